"""Area-weighted random samples on a triangle mesh's surface."""

from typing import Tuple

import numpy as np


def face_areas_and_normals(vertices: np.ndarray, faces: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Per-face area (F,) and unit normal (F, 3); degenerate faces get area 0 and normal 0."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    norm = np.linalg.norm(cross, axis=1)
    normals = np.divide(cross, norm[:, None], out=np.zeros_like(cross), where=norm[:, None] > 0)
    return 0.5 * norm, normals


def sample_surface(vertices: np.ndarray, faces: np.ndarray, count: int,
                   rng: np.random.Generator) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Draw ``count`` points uniformly by area on the mesh.

    Parameters
    ----------
    vertices : (V, 3) float array
    faces : (F, 3) int array, at least one face of non-zero area
    count : number of samples
    rng : the random generator to draw from (the caller owns the seed)

    Returns
    -------
    points : (count, 3) float64
    normals : (count, 3) float64, the unit normal of the face each point lies on
    face_index : (count,) int64
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    areas, normals = face_areas_and_normals(v, f)
    total = areas.sum()
    if f.shape[0] == 0 or not np.isfinite(total) or total <= 0:
        raise ValueError("cannot sample a mesh without faces of non-zero area")
    cumulative = np.cumsum(areas)
    face_index = np.searchsorted(cumulative, rng.random(count) * cumulative[-1], side="right")
    face_index = np.minimum(face_index, f.shape[0] - 1)
    u, w = rng.random(count), rng.random(count)
    flip = u + w > 1.0
    u[flip], w[flip] = 1.0 - u[flip], 1.0 - w[flip]
    a, b, c = v[f[face_index, 0]], v[f[face_index, 1]], v[f[face_index, 2]]
    points = a + u[:, None] * (b - a) + w[:, None] * (c - a)
    return points, normals[face_index], face_index
