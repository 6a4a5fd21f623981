"""Tidy the one-layer mesh: degenerate faces, non-manifold vertices, specks, small pieces."""

import numpy as np

from ..cpu_threads import query_threads
from . import mesh_ops

SPECK_AREA = 20.0  # voxels^2: a piece smaller than this (about 4.5 x 4.5 voxels) may be a speck
CRUMB_AREA = 1.0  # voxels^2: a piece smaller than one voxel's face is below what the grid resolves
ON_SHEET = 2.0  # voxels: a small piece this close to a larger one lies on it (a fragment of
#                the other layer, left stalled up to 2 voxels off the kept sheet)
ON_SHEET_SHARE = 0.5  # ... with this share of its area
SMALL_NEIGHBOURS = 32


def find_specks(vertices: np.ndarray, faces: np.ndarray, spacing: float) -> np.ndarray:
    """The faces of specks: pieces left over from a noisy double cover, not parts of the surface.

    A piece (faces joined by vertices) smaller than ``SPECK_AREA`` voxels^2 is a speck when it
    is smaller than ``CRUMB_AREA`` (a crumb under one voxel's face, which no part the grid
    resolves is) or when ``ON_SHEET_SHARE`` of its area lies within ``ON_SHEET`` voxels of a
    larger piece (a fragment of a layer lying on a kept sheet). A small part on its own, a few
    voxels across, stays.

    Parameters
    ----------
    vertices : (n, 3) float64, world units; faces : (m, 3) int64.
    spacing : float, the voxel size (world units).

    Returns
    -------
    (m,) bool, True for the faces of specks.
    """
    from scipy.spatial import cKDTree

    if len(faces) == 0:
        return np.zeros(0, bool)
    count, label = mesh_ops.vertex_components(len(vertices), faces)
    _, area = mesh_ops.face_normals(vertices / spacing, faces)
    piece_area = np.bincount(label, weights=area, minlength=count)
    small = piece_area[label] < SPECK_AREA
    speck = small & (piece_area[label] < CRUMB_AREA)
    rest = np.nonzero(small & ~speck)[0]
    if len(rest):
        cents = vertices[faces[rest]].mean(axis=1) / spacing
        tree = cKDTree(cents)
        near = np.zeros(len(rest), bool)
        large = np.flatnonzero(~small)
        for start in range(0, len(large), mesh_ops.NORMALS_CHUNK):  # the large pieces' faces
            part = faces[large[start:start + mesh_ops.NORMALS_CHUNK]]
            found = tree.query_ball_point(vertices[part].mean(axis=1) / spacing,
                                          np.nextafter(ON_SHEET, 0), workers=query_threads())
            near[np.concatenate([np.zeros(0, np.int64)]
                                + [np.asarray(f, np.int64) for f in found if f])] = True
        # small pieces lying on a larger small piece
        k = min(SMALL_NEIGHBOURS, len(rest))
        dist, idx = tree.query(cents, k=k, distance_upper_bound=ON_SHEET,
                               workers=query_threads())
        found = np.isfinite(dist)
        other = rest[np.where(found, idx, 0)]
        larger = piece_area[label[other]] > piece_area[label[rest]][:, None]
        near |= (found & larger).any(axis=1)
        on_sheet = np.bincount(label[rest], weights=area[rest] * near, minlength=count)
        speck[rest] |= (on_sheet >= ON_SHEET_SHARE * piece_area)[label[rest]]
    return speck


def clean_mesh(vertices: np.ndarray, faces: np.ndarray, spacing: float,
               min_component_faces: int = 0):
    """Remove what a user would call broken, keep everything else.

    Parameters
    ----------
    vertices : (n, 3) float64, world units; faces : (m, 3) int64.
    spacing : float
        Voxel size: faces with area below ``1e-8 spacing^2`` count as degenerate; specks are
        measured against it (:func:`find_specks`).
    min_component_faces : int
        Drop edge-connected pieces with fewer faces (0 keeps all).

    Returns
    -------
    vertices (n', 3), faces (m', 3), counts (dict: degenerate, split_vertices, specks,
    small_pieces).
    """
    counts = {"degenerate": 0, "split_vertices": 0, "specks": 0, "small_pieces": 0}
    empty = np.zeros((0, 3)), np.zeros((0, 3), np.int64), counts
    if len(faces) == 0:
        return empty
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
        return empty
    vertices, faces, _ = mesh_ops.remove_unreferenced(vertices, faces)
    before = len(vertices)
    vertices, faces = mesh_ops.split_nonmanifold_vertices(vertices, faces)
    counts["split_vertices"] = len(vertices) - before
    speck = find_specks(vertices, faces, spacing)
    if speck.any():
        counts["specks"] = int(mesh_ops.vertex_components(len(vertices), faces[speck])[0])
        faces = faces[~speck]
        if len(faces) == 0:
            return empty
        vertices, faces, _ = mesh_ops.remove_unreferenced(vertices, faces)
    return vertices, faces, counts
