"""The one place where Blender data becomes numpy arrays and back.

Reading: the object as the viewport shows it (modifiers and geometry nodes applied, through the
evaluated depsgraph), positions and colours copied in one ``foreach_get`` each, then moved to
world coordinates, so radii and grid cells are measured on the real shape.

Writing: the engine's mesh (world coordinates) is moved into the source's local frame and the new
object gets the source's world matrix, so it sits exactly on the source and moves with the same
transform values. Vertices, corners and faces are filled in one ``foreach_set`` each.
"""

import bpy
import numpy as np

from ..engine.errors import InputError
from ..engine.geometry import Mesh, PointCloud

POINT_TYPES = {'MESH', 'POINTCLOUD'}
_COLOR_TYPES = {'FLOAT_COLOR', 'BYTE_COLOR'}


def _matrix(obj) -> np.ndarray:
    """The object's world matrix as a (4, 4) float64 array."""
    return np.array(obj.matrix_world, dtype=np.float64)


def _vector_attribute(attributes, name: str, count: int):
    """A point-domain 3-vector attribute as (count, 3) float64, or None when absent."""
    attribute = attributes.get(name)
    if attribute is None or attribute.domain != 'POINT' or attribute.data_type != 'FLOAT_VECTOR':
        return None
    values = np.empty(count * 3, dtype=np.float32)
    attribute.data.foreach_get("vector", values)
    return values.reshape(count, 3).astype(np.float64)


def _color_attribute(geometry, count: int):
    """The point-domain colour attribute (the active one if it qualifies) as (count, 4), or None."""
    candidates = [a for a in geometry.attributes
                  if a.domain == 'POINT' and a.data_type in _COLOR_TYPES
                  and not a.name.startswith(".")]
    if not candidates:
        return None
    active = getattr(getattr(geometry, "color_attributes", None), "active_color", None)
    attribute = next((a for a in candidates if active is not None and a.name == active.name),
                     candidates[0])
    values = np.empty(count * 4, dtype=np.float32)
    attribute.data.foreach_get("color", values)  # linear RGBA, also for byte colours
    return np.clip(values.reshape(count, 4), 0.0, 1.0)


def _read_geometry(geometry, matrix: np.ndarray) -> PointCloud:
    count = len(geometry.attributes["position"].data) if "position" in geometry.attributes else 0
    if count == 0:
        return PointCloud(np.zeros((0, 3)))
    local = _vector_attribute(geometry.attributes, "position", count)
    points = local @ matrix[:3, :3].T + matrix[:3, 3]

    normals = _vector_attribute(geometry.attributes, "normal", count)
    if normals is None and isinstance(geometry, bpy.types.Mesh) and len(geometry.polygons):
        normals = np.empty(count * 3, dtype=np.float32)
        geometry.vertex_normals.foreach_get("vector", normals)
        normals = normals.reshape(count, 3).astype(np.float64)
    if normals is not None:
        # Normals transform with the inverse transpose; a singular matrix is refused earlier.
        normals = normals @ np.linalg.inv(matrix[:3, :3])
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)

    return PointCloud(points, normals, _color_attribute(geometry, count))


def _kind(obj) -> str:
    """'a camera', 'an empty', 'a grease pencil': the object's type as words."""
    words = obj.type.lower().replace("_", " ")
    return f"{'an' if words[0] in 'aeiou' else 'a'} {words}"


def _check_object(obj) -> None:
    if obj is None:
        raise InputError("No active object. Select a point cloud (a mesh made of vertices, or a "
                         "point cloud object) and try again.")
    if obj.type not in POINT_TYPES:
        raise InputError(f"'{obj.name}' is {_kind(obj)}, not a point cloud. Select a mesh or "
                         f"point cloud object whose points should be meshed.")
    if abs(np.linalg.det(_matrix(obj)[:3, :3])) < 1e-12:
        raise InputError(f"'{obj.name}' has a zero scale on some axis, so its points collapse. "
                         f"Fix its scale (N panel > Item) and try again.")


# The custom property that marks an object as a result: the name of the cloud it was made from.
RESULT_KEY = "udf_reconstruction_source"


def result_source_name(obj):
    """The name of the cloud ``obj`` was reconstructed from, or None when it is not a result."""
    if obj is None:
        return None
    name = obj.get(RESULT_KEY)
    return name if isinstance(name, str) and name else None


class Target:
    """What the Reconstruct button would work on, and why not when it cannot.

    ``active``: the active object; ``source``: the cloud to reconstruct (the active object, or
    the cloud a selected result was made from), None when there is none; ``problem``: a sentence
    for the button's tooltip and the error, None when Reconstruct can run; ``short``: the same in
    a few words, for the sidebar.
    """

    def __init__(self, active, source=None, problem=None, count=0, short=None):
        self.active, self.source, self.problem, self.count = active, source, problem, count
        self.short = short or problem

    @property
    def is_result(self) -> bool:
        return self.source is not None and self.source is not self.active


def reconstruct_target(context) -> Target:
    """The cloud the Reconstruct button would reconstruct in ``context`` (see :class:`Target`).

    Nothing selected (the active object deselected, as after Alt+A) means nothing to do; a
    selected result of an earlier run means its cloud again, so the result is replaced rather
    than meshed itself.
    """
    view_layer = context.view_layer
    obj = view_layer.objects.active
    if obj is None:
        return Target(None, problem="Select a point cloud first (a mesh of vertices or a point "
                                    "cloud object)", short="Select a point cloud")
    if context.mode != 'OBJECT':
        return Target(obj, problem="Switch to Object Mode to reconstruct (Tab)",
                      short="Switch to Object Mode")
    if not obj.select_get(view_layer=view_layer):
        return Target(obj, problem="Nothing is selected: select a point cloud first",
                      short="Nothing selected")
    source = obj
    source_name = result_source_name(obj)
    if source_name is not None:
        source = bpy.data.objects.get(source_name)
        if source is None or source.name not in view_layer.objects:
            return Target(obj, problem=f"'{obj.name}' is a reconstructed mesh and its point "
                                       f"cloud '{source_name}' is gone: select a point cloud",
                          short=f"{obj.name}: its cloud is gone")
    if source.type not in POINT_TYPES:
        return Target(obj, problem=f"'{source.name}' is {_kind(source)}, not a point cloud: "
                                   f"select a mesh or point cloud object",
                      short=f"{source.name}: not a point cloud")
    count = point_count(context, source)
    if count == 0:
        return Target(obj, problem=f"'{source.name}' has no points: select an object with "
                                   f"vertices or points", short=f"{source.name}: no points")
    return Target(obj, source, None, count)


def read_point_cloud(context, obj) -> PointCloud:
    """The points of ``obj`` as the viewport shows them, in world coordinates.

    Returns a :class:`PointCloud` with points (N, 3) float64 world units, normals (N, 3) when the
    geometry has a ``normal`` attribute or faces, colours (N, 4) linear RGBA when it has a
    point colour attribute. Raises :class:`InputError` for objects that hold no points.
    """
    _check_object(obj)
    evaluated = obj.evaluated_get(context.evaluated_depsgraph_get())
    matrix = _matrix(obj)
    if obj.type == 'MESH':
        mesh = evaluated.to_mesh()
        try:
            return _read_geometry(mesh, matrix)
        finally:
            evaluated.to_mesh_clear()
    return _read_geometry(evaluated.data, matrix)


def point_count(context, obj) -> int:
    """How many points ``obj`` shows in the viewport (0 for objects that hold no points)."""
    if obj is None or obj.type not in POINT_TYPES:
        return 0
    data = obj.evaluated_get(context.evaluated_depsgraph_get()).data
    position = data.attributes.get("position") if data is not None else None
    return len(position.data) if position is not None else 0


def world_extent(obj) -> float:
    """The longest side of the object's world-space bounding box (the engine's unit length)."""
    matrix = _matrix(obj)
    corners = np.array([tuple(c) for c in obj.bound_box], dtype=np.float64)
    world = corners @ matrix[:3, :3].T + matrix[:3, 3]
    return float(np.max(world.max(axis=0) - world.min(axis=0)))


def _fill_mesh(me, vertices: np.ndarray, faces: np.ndarray) -> None:
    me.vertices.add(len(vertices))
    me.loops.add(faces.size)
    me.polygons.add(len(faces))
    me.attributes["position"].data.foreach_set("vector", vertices.astype(np.float32).ravel())
    corner_verts = faces.astype(np.int32).ravel()
    if ".corner_vert" in me.attributes:
        me.attributes[".corner_vert"].data.foreach_set("value", corner_verts)
    else:
        me.loops.foreach_set("vertex_index", corner_verts)
    me.polygons.foreach_set("loop_start", np.arange(0, faces.size, 3, dtype=np.int32))
    me.update(calc_edges=True)


_TRANSFORM_CHANNELS = ("location", "rotation_euler", "rotation_quaternion", "rotation_axis_angle",
                       "scale", "delta_location", "delta_rotation_euler",
                       "delta_rotation_quaternion", "delta_scale")


def _copy_transform(source, obj) -> None:
    """Give ``obj`` the parent and transform channels of ``source``: the same world matrix, bit
    for bit (setting ``matrix_world`` would round through a decomposition)."""
    obj.parent = source.parent
    obj.parent_type = source.parent_type
    obj.parent_bone = source.parent_bone
    obj.parent_vertices = source.parent_vertices[:]
    obj.matrix_parent_inverse = source.matrix_parent_inverse.copy()
    obj.rotation_mode = source.rotation_mode
    for name in _TRANSFORM_CHANNELS:
        setattr(obj, name, getattr(source, name))


def _layer_collection(layer_collection, collection):
    """The view layer's entry for ``collection`` when it and every collection above it are
    included (not excluded), else None."""
    if layer_collection.exclude:
        return None
    if layer_collection.collection == collection:
        return layer_collection
    for child in layer_collection.children:
        found = _layer_collection(child, collection)
        if found is not None:
            return found
    return None


def _home_collection(context, source):
    """Where a result of ``source`` goes: the source's first collection that the view layer
    includes, else the scene's collection."""
    if source is not None:
        for collection in source.users_collection:
            if collection == context.scene.collection:
                return collection
            if _layer_collection(context.view_layer.layer_collection, collection) is not None:
                return collection
    return context.scene.collection


def _make_mesh(mesh: Mesh, local: np.ndarray, name: str):
    me = bpy.data.meshes.new(name)
    _fill_mesh(me, local, np.asarray(mesh.faces).reshape(-1, 3))
    if mesh.colors is not None and len(mesh.colors) == len(local):
        colors = np.ones((len(local), 4), dtype=np.float32)
        colors[:, :mesh.colors.shape[1]] = mesh.colors
        attribute = me.color_attributes.new("Col", 'FLOAT_COLOR', 'POINT')
        attribute.data.foreach_set("color", colors.ravel())
        me.color_attributes.active_color = attribute
        me.color_attributes.render_color_index = me.color_attributes.active_color_index
    if len(me.polygons) and hasattr(me, "shade_smooth"):
        me.shade_smooth()
    return me


def previous_result(source_name: str, name: str):
    """The object an earlier run made from ``source_name`` under ``name``, if it is still there
    (a result that was renamed is the user's to keep, and is not returned)."""
    obj = bpy.data.objects.get(name)
    if obj is not None and obj.type == 'MESH' and result_source_name(obj) == source_name:
        return obj
    return None


def new_mesh_object(context, mesh: Mesh, name: str, matrix_world, source=None, reuse=None):
    """Add ``mesh`` (world coordinates) as a new object; return it.

    The vertices are stored relative to ``matrix_world`` (the source's world matrix when its
    points were read). With ``source``, the object copies its parent and transform channels, so
    it sits exactly on the source and moves with the same values, is linked to the source's
    first collection that the view layer includes (else the scene's), and is marked as a result
    of the source (:data:`RESULT_KEY`); without, it gets ``matrix_world`` and the scene's
    collection. With ``reuse`` (an earlier result, see :func:`previous_result`) that object gets
    the new mesh instead: its name, collections, modifiers and materials stay, nothing new is
    stacked beside it. The mesh gets a ``Col`` point colour attribute when it has colours,
    smooth shading; the object becomes the only selected, active one.
    """
    inverse = np.linalg.inv(np.array(matrix_world, dtype=np.float64))
    local = np.asarray(mesh.vertices, dtype=np.float64) @ inverse[:3, :3].T + inverse[:3, 3]
    view_layer = context.view_layer
    me = _make_mesh(mesh, local, name)

    if reuse is not None and reuse.name in view_layer.objects:
        obj = reuse
        old = obj.data
        for material in old.materials:
            me.materials.append(material)
        obj.data = me
        if old.users == 0:
            bpy.data.meshes.remove(old)
        me.name = name
    else:
        obj = bpy.data.objects.new(name, me)
        _home_collection(context, source).objects.link(obj)
    if source is not None:
        _copy_transform(source, obj)
        obj[RESULT_KEY] = source.name
    else:
        obj.matrix_world = matrix_world
    for other in view_layer.objects:
        # None: an object deleted from Python that the view layer has not caught up with yet
        if other is not None and other.select_get():
            other.select_set(False)
    obj.select_set(True)
    view_layer.objects.active = obj
    view_layer.update()  # so matrix_world is current for whoever reads it next
    return obj
