"""Exact distances from points to a triangle mesh, with the normal of the closest face.

The closest point on the triangles themselves, so a score built on it does not depend on how
densely a surface was sampled. With Open3D (the benchmark's requirements) its ray-casting scene
(an Embree bounding-volume hierarchy) finds it, in float32 relative to the mesh's lowest corner
(a floor tens of metres across keeps micrometre precision), and the normal is the closest
face's own, in float64 (the scene's float32 normal of a sliver can be nan); without it, a k-d
tree over the face centroids gives candidate faces and the closest point on each is computed
in float64: a face can only be closer than the best candidate found if its centroid lies
within that distance plus the largest centroid-to-corner reach of the mesh's faces, and those
faces are checked too.
"""

from typing import Tuple

import numpy as np

_CHUNK = 1_000_000  # queries per call of the scene: bounds its result buffers
_NUMPY_CHUNK = 65_536  # queries per pass of the numpy path
_CANDIDATES = 8  # nearest centroids checked first by the numpy path


def closest_on_mesh(points: np.ndarray, vertices: np.ndarray,
                    faces: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """For each of ``points`` (N, 3), the distance to the mesh and the unit normal of the face
    the closest point lies on (N, 3). A mesh without faces gives ``inf`` and zero normals; a
    face without area (in float64) a zero normal."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    distances = np.full(len(points), np.inf)
    normals = np.zeros((len(points), 3))
    faces = np.asarray(faces).reshape(-1, 3)
    if len(faces) == 0 or len(points) == 0:
        return distances, normals
    vertices = np.asarray(vertices, dtype=np.float64)
    from engine.sampling import face_areas_and_normals

    try:
        import open3d as o3d
    except ImportError:
        return _closest_numpy(points, vertices, faces.astype(np.int64), distances, normals)
    origin = vertices.min(axis=0)
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
        face = found["primitive_ids"].numpy().astype(np.int64)
        normals[start:start + _CHUNK] = face_areas_and_normals(vertices, faces[face])[1]
    return distances, normals


def _closest_numpy(points, vertices, faces, distances, normals):
    from scipy.spatial import cKDTree

    from engine.sampling import face_areas_and_normals

    corners = vertices[faces]
    centroids = corners.mean(axis=1)
    reach = float(np.linalg.norm(corners - centroids[:, None], axis=2).max())
    face_normals = face_areas_and_normals(vertices, faces)[1]
    tree = cKDTree(centroids)
    k = min(_CANDIDATES, len(faces))
    for start in range(0, len(points), _NUMPY_CHUNK):
        part = points[start:start + _NUMPY_CHUNK]
        near_distance, near = tree.query(part, k=k)
        near_distance, near = near_distance.reshape(len(part), k), near.reshape(len(part), k)
        gaps = _to_triangles(np.repeat(part, k, axis=0), corners[near.reshape(-1)])
        gaps = gaps.reshape(len(part), k)
        best = gaps.argmin(axis=1)
        found = gaps[np.arange(len(part)), best]
        face = near[np.arange(len(part)), best]
        if k < len(faces):  # a face past the k-th centroid may still be closer
            unsure = np.flatnonzero(found > near_distance[:, -1] - reach)
            lists = tree.query_ball_point(part[unsure], found[unsure] + reach)
            counts = np.array([len(items) for items in lists], dtype=np.int64)
            if counts.sum():
                which = np.repeat(unsure, counts)
                candidates = np.concatenate([np.asarray(items, np.int64) for items in lists])
                gaps = _to_triangles(part[which], corners[candidates])
                order = np.lexsort((gaps, which))
                first = np.unique(which[order], return_index=True)[1]
                rows, closer = which[order][first], gaps[order][first]
                better = closer < found[rows]
                found[rows[better]] = closer[better]
                face[rows[better]] = candidates[order][first][better]
        distances[start:start + len(part)] = found
        normals[start:start + len(part)] = face_normals[face]
    return distances, normals


def _to_triangles(p: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Distance from each point of ``p`` (P, 3) to the triangle (P, 3, 3) beside it: the closest
    point by the triangle's Voronoi regions (vertices, edges, interior)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    ab, ac = b - a, c - a
    dot = lambda u, v: np.einsum("ij,ij->i", u, v)  # noqa: E731
    ap, bp, cp = p - a, p - b, p - c
    d1, d2 = dot(ab, ap), dot(ac, ap)
    d3, d4 = dot(ab, bp), dot(ac, bp)
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        on_ab = np.nan_to_num(d1 / (d1 - d3))[:, None]
        on_ac = np.nan_to_num(d2 / (d2 - d6))[:, None]
        on_bc = np.nan_to_num((d4 - d3) / ((d4 - d3) + (d5 - d6)))[:, None]
        total = va + vb + vc
        v = np.nan_to_num(vb / total)[:, None]
        w = np.nan_to_num(vc / total)[:, None]
    regions = [(d1 <= 0) & (d2 <= 0), (d3 >= 0) & (d4 <= d3),
               (vc <= 0) & (d1 >= 0) & (d3 <= 0), (d6 >= 0) & (d5 <= d6),
               (vb <= 0) & (d2 >= 0) & (d6 <= 0), (va <= 0) & (d4 >= d3) & (d5 >= d6)]
    closest = a + ab * v + ac * w
    for region, point in reversed(list(zip(regions, [a, b, a + ab * on_ab, c, a + ac * on_ac,
                                                     b + (c - b) * on_bc]))):
        closest = np.where(region[:, None], point, closest)
    return np.linalg.norm(p - closest, axis=1)
