"""Tidy the one-layer mesh: degenerate faces, non-manifold vertices, small pieces."""

import numpy as np

from . import mesh_ops


def clean_mesh(vertices: np.ndarray, faces: np.ndarray, spacing: float,
               min_component_faces: int = 0):
    """Remove what a user would call broken, keep everything else.

    Parameters
    ----------
    vertices : (n, 3) float64, world units; faces : (m, 3) int64.
    spacing : float
        Voxel size: faces with area below ``1e-8 spacing^2`` count as degenerate.
    min_component_faces : int
        Drop edge-connected pieces with fewer faces (0 keeps all).

    Returns
    -------
    vertices (n', 3), faces (m', 3), counts (dict: degenerate, split_vertices, small_pieces).
    """
    counts = {"degenerate": 0, "split_vertices": 0, "small_pieces": 0}
    if len(faces) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), counts
    repeated = ((faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2])
                | (faces[:, 0] == faces[:, 2]))
    _, area = mesh_ops.face_normals(vertices, faces)
    bad = repeated | (area < 1e-8 * spacing ** 2)
    counts["degenerate"] = int(bad.sum())
    faces = faces[~bad]
    if min_component_faces > 0 and len(faces):
        pairs, _ = mesh_ops.dual_edges(faces)
        n, labels = mesh_ops.face_components(len(faces), pairs)
        sizes = np.bincount(labels, minlength=n)
        small = sizes < min_component_faces
        counts["small_pieces"] = int(small.sum())
        faces = faces[~small[labels]]
    if len(faces) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), counts
    vertices, faces, _ = mesh_ops.remove_unreferenced(vertices, faces)
    before = len(vertices)
    vertices, faces = mesh_ops.split_nonmanifold_vertices(vertices, faces)
    counts["split_vertices"] = len(vertices) - before
    return vertices, faces, counts
