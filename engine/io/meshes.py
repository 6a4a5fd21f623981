"""STL, GLB and glTF, read and written through trimesh.

STL holds float32 triangles and no per-vertex data: equal corners are merged into shared
vertices on reading. GLB and glTF keep per-vertex normals and colours; their positions are
float32 (the glTF standard) and are read and written as stored, without turning glTF's +Y up
into +Z up. A glTF scene's meshes and point clouds are placed by their node transforms and
joined into one mesh. trimesh is imported only when one of these formats is used.
"""

import io

import numpy as np

from ..geometry import Mesh
from .common import BadFile, scaled_colors

_STL_TRIANGLE_BYTES = 50


def read_stl(path: str) -> Mesh:
    """Binary or ASCII STL -> a mesh whose equal corners are merged into shared vertices."""
    from trimesh.exchange.stl import load_stl

    with open(path, "rb") as file:
        data = file.read()
    if not data:
        raise BadFile("the file is empty")
    count = int(np.frombuffer(data, "<u4", 1, 80)[0]) if len(data) >= 84 else 0
    binary = len(data) >= 84 and 84 + count * _STL_TRIANGLE_BYTES == len(data)
    if not binary and not data.lstrip().startswith(b"solid"):
        if len(data) >= 84:
            raise BadFile(f"a binary STL of {count:,} triangles needs "
                          f"{84 + count * _STL_TRIANGLE_BYTES:,} bytes, but the file has "
                          f"{len(data):,}")
        raise BadFile("not an STL file (too short for binary STL, no 'solid' line)")
    loaded = _parsed(load_stl, io.BytesIO(data))
    corners = np.asarray(loaded["vertices"], np.float64)[np.asarray(loaded["faces"])]
    if len(corners) == 0:
        raise BadFile("the file contains no triangles")
    vertices, faces = np.unique(corners.reshape(-1, 3), axis=0, return_inverse=True)
    return Mesh(vertices, faces.reshape(-1, 3).astype(np.int64), None, None)


def write_stl(file, vertices, faces, normals, colors) -> None:
    """Binary STL; each facet's normal comes from its corners' order (zero when degenerate)."""
    from trimesh.exchange.stl import export_stl

    file.write(export_stl(_trimesh(vertices, faces, None, None)))


def read_gltf(path: str) -> Mesh:
    """GLB, or glTF with embedded or neighbouring buffers -> every mesh and point cloud of the
    scene, placed by its node transform, joined into one mesh."""
    import trimesh

    scene = _parsed(trimesh.load_scene, path, process=False, maintain_order=True)
    parts = []
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        parts.append(_placed(scene.geometry[name], np.asarray(transform, np.float64)))
    if not parts:
        raise BadFile("the scene contains no meshes or points")
    offsets = np.cumsum([0] + [len(part.vertices) for part in parts[:-1]])
    faces = np.concatenate([part.faces + offset for part, offset in zip(parts, offsets)])
    normals = colors = None
    if all(part.normals is not None for part in parts):
        normals = np.concatenate([part.normals for part in parts])
    if all(part.colors is not None for part in parts):
        channels = min(part.colors.shape[1] for part in parts)
        colors = np.concatenate([part.colors[:, :channels] for part in parts])
    return Mesh(np.concatenate([part.vertices for part in parts]), faces, normals, colors)


def _placed(geometry, transform: np.ndarray) -> Mesh:
    """One trimesh geometry of a scene in the scene's frame, with its own normals and colours."""
    vertices = np.asarray(geometry.vertices, np.float64) @ transform[:3, :3].T + transform[:3, 3]
    faces = np.asarray(getattr(geometry, "faces", np.zeros((0, 3))), np.int64).reshape(-1, 3)
    normals = None
    # Only normals stored in the file: trimesh would otherwise compute them from the faces.
    if "vertex_normals" in geometry._cache:
        normals = geometry.vertex_normals @ np.linalg.inv(transform[:3, :3])
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
    colors = None
    if hasattr(geometry, "faces"):
        if geometry.visual.kind == "vertex":
            colors = geometry.visual.vertex_colors
    elif geometry.colors is not None and len(geometry.colors) == len(vertices):
        colors = geometry.colors
    if colors is not None:
        colors = scaled_colors(colors, 255)
        if np.all(colors[:, 3] == 1.0):
            colors = colors[:, :3]
    return Mesh(vertices, faces, normals, colors)


def _parsed(parse, *args, **kwargs):
    """``parse(*args, **kwargs)``, its errors (of many kinds in trimesh) as one BadFile."""
    try:
        return parse(*args, **kwargs)
    except MemoryError:
        raise BadFile("its counts do not fit in memory: the file is corrupt") from None
    except Exception as error:
        detail = (str(error).splitlines() or [""])[0][:160] or type(error).__name__
        raise BadFile(f"not a readable file of this format ({detail})") from None


def write_glb(file, vertices, faces, normals, colors) -> None:
    """Binary glTF: one mesh (or one point cloud when there are no faces)."""
    file.write(_trimesh(vertices, faces, normals, colors).export(
        file_type="glb", **_normal_option(faces, normals)))


def write_gltf(file, vertices, faces, normals, colors) -> None:
    """glTF as one JSON file, its buffers embedded as base64."""
    exported = _trimesh(vertices, faces, normals, colors).export(
        file_type="gltf", embed_buffers=True, **_normal_option(faces, normals))
    (data,) = exported.values()
    file.write(data)


def _normal_option(faces, normals) -> dict:
    return {"include_normals": normals is not None} if len(faces) else {}


def _trimesh(vertices, faces, normals, colors):
    """A trimesh object holding exactly these arrays (nothing merged, reordered or fixed)."""
    import trimesh

    rgba = None
    if colors is not None:
        rgba = np.round(np.clip(colors, 0.0, 1.0) * 255.0).astype(np.uint8)
    if len(faces) == 0:
        return trimesh.PointCloud(vertices, colors=rgba)
    return trimesh.Trimesh(vertices, faces, vertex_normals=normals, vertex_colors=rgba,
                           process=False, validate=False)
