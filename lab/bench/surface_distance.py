"""Exact distances from points to a triangle mesh, with the normal of the closest face.

Open3D's ray-casting scene (an Embree bounding-volume hierarchy) finds the closest point on the
triangles themselves, so a score built on it does not depend on how densely a surface was
sampled. The scene works in float32: coordinates are taken relative to the mesh's lowest corner
first, so a floor tens of metres across keeps micrometre precision.
"""

from typing import Tuple

import numpy as np

_CHUNK = 1_000_000  # queries per call: bounds the scene's result buffers


def closest_on_mesh(points: np.ndarray, vertices: np.ndarray,
                    faces: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """For each of ``points`` (N, 3), the distance to the mesh and the unit normal of the face
    the closest point lies on (N, 3). A mesh without faces gives ``inf`` and zero normals."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    distances = np.full(len(points), np.inf)
    normals = np.zeros((len(points), 3))
    faces = np.asarray(faces).reshape(-1, 3)
    if len(faces) == 0 or len(points) == 0:
        return distances, normals
    import open3d as o3d

    origin = np.asarray(vertices, dtype=np.float64).min(axis=0)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.ascontiguousarray(vertices - origin, dtype=np.float32)),
        o3d.core.Tensor(np.ascontiguousarray(faces, dtype=np.uint32)))
    for start in range(0, len(points), _CHUNK):
        queries = points[start:start + _CHUNK] - origin
        found = scene.compute_closest_points(
            o3d.core.Tensor(np.ascontiguousarray(queries, dtype=np.float32)))
        closest = found["points"].numpy().astype(np.float64)
        distances[start:start + _CHUNK] = np.linalg.norm(queries - closest, axis=1)
        normals[start:start + _CHUNK] = found["primitive_normals"].numpy()
    return distances, normals
