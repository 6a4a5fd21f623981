"""Surface across the gaps of a sparse scan, where it lies farther from every point than the band.

A sparse scan (the far walls of a room, the lines of a LiDAR sweep) leaves strips of surface
farther than the ball radius from every point. The network sees no point there, the field holds
its truncation value, and the mesh has a hole. A grid node in such a strip lies in the plane of
the points around it and is *surrounded* by them; a node past a true rim (a garment's hem, the
top of a wall) has them all on one side, and keeps its value, so open surfaces stay open.

:func:`fill_gaps` finds the *edge points*: those whose neighbours within ``EDGE_NODES``
spacings (up to ``EDGE_NEIGHBOURS``) leave an angular gap wider than ``EDGE_GAP`` around them in
their tangent plane (a scan line's points, a rim's). The nodes within ``GAP_NODES`` spacings of
an edge point along every axis (a cube: its corners reach farther across a gap than a ball
would, and fill a good part of it), within ``GAP_NODES`` of some point and farther than
``KEEP_NODES`` from every point take the distance to the plane of their ``NEIGHBOURS`` nearest
points when

* those points, taken from the cloud thinned to one per cube of ``THIN_NODES`` spacings (so that
  they come from both sides of a gap between closely sampled scan lines), are flat: the smallest
  eigenvalue of their covariance is under ``FLAT`` of the sum;
* the node lies within ``IN_PLANE`` spacings of their plane; and
* they surround it: seen from the node, in that plane, no angular gap between them is wider
  than ``SURROUND_GAP``.

A node the band already holds takes its plane distance only where that is ``LOWER_NODES``
spacings below its value: between the lines of a scan, where the network and the nearest-point
distance see a line, not the plane, and not over a densely sampled surface, where they agree
with it. Every step is a k-d query or per-node arithmetic, so the field stays the same run after
run.
"""

import math
from typing import Tuple

import numpy as np

from .cpu_threads import query_threads

NEIGHBOURS = 12
EDGE_NEIGHBOURS = 32
GAP_NODES = 12.0  # spacings: the widest strip filled is about twice this
EDGE_GAP = math.radians(120.0)
SURROUND_GAP = math.radians(150.0)
FLAT = 0.05
IN_PLANE = 2.0  # spacings
KEEP_NODES = 1.0  # spacings: nodes this close to a point keep their value
LOWER_NODES = 0.5  # spacings: a band node takes its plane distance when that is this much lower
EDGE_NODES = 6.0  # spacings: the reach of the edge test (twice the network band's)
THIN_NODES = 2.0  # spacings: the cell of the thinned cloud the full test reads
CHUNK = 65536


def fill_gaps(tree, points: np.ndarray, shape: Tuple[int, int, int], origin: np.ndarray,
              spacing: float, indices: np.ndarray, values: np.ndarray,
              lattice_origin: np.ndarray = None) -> Tuple[np.ndarray, np.ndarray, int]:
    """The band with the gaps of a sparse scan filled (see the module docstring).

    Parameters
    ----------
    tree : scipy.spatial.cKDTree over ``points``
    points : (N, 3) float64, the grid's frame
    shape, origin, spacing : the grid
    indices : (M, 3) int64 band nodes; values : (M,) float32 their distances
    lattice_origin : where the thinned cloud's cubes start (default ``origin``): the tiles of
        one reconstruction pass the same point, so that they thin their points alike

    Returns
    -------
    indices, values : the band with the filled nodes (those outside it appended)
    filled : how many nodes took a plane distance
    """
    from scipy.spatial import cKDTree

    from .field import find_band

    if len(points) <= NEIGHBOURS:
        return indices, values, 0
    skip_within = KEEP_NODES * spacing
    normals, spread, edge = _point_planes(tree, points, EDGE_NODES * spacing)
    if not edge.any():
        return indices, values, 0
    reach = GAP_NODES * spacing
    # the nodes near an edge point (find_band dilates from those), their distance to the
    # nearest of all points and that point
    nodes, nearest, owner = find_band(tree, points[edge], shape, origin, spacing, reach,
                                      with_owner=True)
    away = nearest > skip_within
    nodes, owner = nodes[away], owner[away]
    positions = origin + nodes * spacing
    # a quick test before the full one: off the plane of the nearest point, where that plane
    # is known (on a scan line the nearest point's neighbours are collinear: no plane)
    offset = np.einsum("ij,ij->i", positions - points[owner], normals[owner])
    near_plane = ~spread[owner] | (np.abs(offset) < IN_PLANE * spacing)
    nodes, positions = nodes[near_plane], positions[near_plane]
    # the full test reads a thinned cloud, so that the nearest points of a node between two
    # scan lines come from both, not all from the nearer line's closely spaced points
    start = origin if lattice_origin is None else lattice_origin
    thinned = _thinned(points, THIN_NODES * spacing, np.asarray(start, dtype=np.float64))
    if len(thinned) < NEIGHBOURS:  # too few points to fit and surround a plane
        return indices, values, 0
    thin_tree = cKDTree(thinned)
    distance = np.full(len(nodes), np.inf)
    for start in range(0, len(nodes), CHUNK):
        part = slice(start, start + CHUNK)
        distance[part] = _surrounded_plane_distance(thin_tree, thinned, positions[part], spacing)
    take = np.isfinite(distance)
    nodes, distance = nodes[take], distance[take].astype(np.float32)
    if not len(nodes):
        return indices, values, 0
    band = np.ravel_multi_index(indices.T, shape)
    order = np.argsort(band, kind="stable")
    wanted = np.ravel_multi_index(nodes.T, shape)
    at = np.minimum(np.searchsorted(band[order], wanted), len(band) - 1)
    held = band[order][at] == wanted
    values = values.copy()
    rows = order[at[held]]
    lower = distance[held] < values[rows] - LOWER_NODES * spacing
    values[rows[lower]] = distance[held][lower]
    # the nodes outside the band lie farther than the band radius (>= 3 spacings) from every
    # point and hold it: their plane distance, under IN_PLANE spacings, is always lower
    indices = np.concatenate([indices, nodes[~held]])
    values = np.concatenate([values, distance[~held]])
    return indices, values, int(lower.sum() + (~held).sum())


def _thinned(points: np.ndarray, cell: float, start: np.ndarray) -> np.ndarray:
    """The first point (in the points' order) of each occupied cube of side ``cell`` of the
    lattice through ``start``."""
    keys = np.floor((points - start) / cell).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    return points[np.sort(first)]


def _point_planes(tree, points: np.ndarray, reach: float):
    """Each point's unit normal (PCA of its neighbours), whether its neighbours spread in two
    directions (else the normal means nothing), and whether it is an edge point: one whose
    neighbours within ``reach`` (up to ``EDGE_NEIGHBOURS``) leave an angular gap wider than
    ``EDGE_GAP`` around it, or that has fewer than 3 of them."""
    from .compiled import kernels

    compiled = kernels("gap_fill_kernels")
    normals = np.empty_like(points)
    spread = np.empty(len(points), dtype=bool)
    edge = np.empty(len(points), dtype=bool)
    for start in range(0, len(points), CHUNK):
        part = slice(start, start + CHUNK)
        distance, near = tree.query(points[part], k=EDGE_NEIGHBOURS + 1, workers=query_threads())
        # a cloud of fewer points than that: the missing neighbours (index len(points)) lie
        # beyond reach; point them at a real one, which they never count as
        near = np.minimum(near, len(points) - 1)
        around = points[near[:, 1:NEIGHBOURS + 1]]
        normal, tangent_u, tangent_v, _, spread[part] = _planes(around)
        normals[part] = normal
        if compiled is not None:
            edge[part] = compiled.edge_points(points, np.arange(start, start + len(near)), near,
                                              distance, tangent_u, tangent_v, reach, EDGE_GAP)
            continue
        # neighbours past reach repeat the point itself: no direction of their own
        within = distance[:, 1:] <= reach
        offsets = np.where(within[:, :, None], points[near[:, 1:]] - points[part, None], 0.0)
        edge[part] = ((within.sum(axis=1) < 3)
                      | (_widest_gap(offsets, tangent_u, tangent_v, within) > EDGE_GAP))
    return normals, spread, edge


def _surrounded_plane_distance(tree, points, positions, spacing) -> np.ndarray:
    """Distance from each position to the plane of its nearest points where they are flat,
    surround it and it lies within ``IN_PLANE`` spacings of their plane; inf elsewhere."""
    _, near = tree.query(positions, k=NEIGHBOURS, workers=query_threads())
    around = points[near]
    normal, tangent_u, tangent_v, flat, _ = _planes(around)
    centre = around.mean(axis=1)
    distance = np.abs(np.einsum("ij,ij->i", positions - centre, normal))
    surrounded = _widest_gap(around - positions[:, None], tangent_u, tangent_v) < SURROUND_GAP
    keep = flat & surrounded & (distance < IN_PLANE * spacing)
    return np.where(keep, distance, np.inf)


def _planes(around: np.ndarray):
    """Per group of points (G, K, 3): normal, two tangents, whether the group is flat and whether
    it spreads in two directions (not along a line)."""
    centred = around - around.mean(axis=1, keepdims=True)
    covariance = np.einsum("gki,gkj->gij", centred, centred)
    eigenvalues, eigenvectors = np.linalg.eigh(covariance)
    total = np.maximum(eigenvalues.sum(axis=1), 1e-300)
    flat = eigenvalues[:, 0] < FLAT * total
    spread = eigenvalues[:, 1] > FLAT * total
    return eigenvectors[:, :, 0], eigenvectors[:, :, 2], eigenvectors[:, :, 1], flat, spread


def _widest_gap(offsets: np.ndarray, tangent_u: np.ndarray, tangent_v: np.ndarray,
                valid: np.ndarray = None) -> np.ndarray:
    """The widest angle between consecutive directions of ``offsets`` (G, K, 3) in the plane of
    ``tangent_u`` and ``tangent_v`` (radians); with ``valid`` (G, K), only those offsets count
    (the others repeat a valid one's angle)."""
    angles = np.arctan2(np.einsum("gki,gi->gk", offsets, tangent_v),
                        np.einsum("gki,gi->gk", offsets, tangent_u))
    if valid is not None:
        first = np.take_along_axis(angles, np.argmax(valid, axis=1)[:, None], axis=1)
        angles = np.where(valid, angles, first)
    angles = np.sort(angles, axis=1)
    wrapped = np.concatenate([angles, angles[:, :1] + 2.0 * np.pi], axis=1)
    return np.diff(wrapped, axis=1).max(axis=1)
