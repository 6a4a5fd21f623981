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


def _check_object(obj) -> None:
    if obj is None:
        raise InputError("No active object. Select a point cloud (a mesh made of vertices, or a "
                         "point cloud object) and try again.")
    if obj.type not in POINT_TYPES:
        raise InputError(f"'{obj.name}' is a {obj.type.lower()} object, not a point cloud. "
                         f"Select a mesh or point cloud object whose points should be meshed.")
    if abs(np.linalg.det(_matrix(obj)[:3, :3])) < 1e-12:
        raise InputError(f"'{obj.name}' has a zero scale on some axis, so its points collapse. "
                         f"Fix its scale (N panel > Item) and try again.")


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


def new_mesh_object(context, mesh: Mesh, name: str, matrix_world, source=None):
    """Add ``mesh`` (world coordinates) as a new object; return it.

    The vertices are stored relative to ``matrix_world`` (the source's world matrix when its
    points were read). With ``source``, the object copies its parent and transform channels, so
    it sits exactly on the source and moves with the same values, and is linked to the source's
    first collection (the scene's when that one is excluded from the view layer); without, it
    gets ``matrix_world`` and the scene's collection. It gets a ``Col`` point colour attribute
    when the mesh has colours, smooth shading, and becomes the only selected, active object.
    """
    inverse = np.linalg.inv(np.array(matrix_world, dtype=np.float64))
    local = np.asarray(mesh.vertices, dtype=np.float64) @ inverse[:3, :3].T + inverse[:3, 3]

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

    obj = bpy.data.objects.new(name, me)
    view_layer = context.view_layer
    collection = source.users_collection[0] if source and source.users_collection else None
    (collection or context.scene.collection).objects.link(obj)
    if collection is not None and obj.name not in view_layer.objects:
        collection.objects.unlink(obj)
        context.scene.collection.objects.link(obj)
    if source is not None:
        _copy_transform(source, obj)
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
