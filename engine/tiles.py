"""Large clouds in tiles: each tile's field and mesh on its own, stitched into one mesh.

The field at a grid node depends only on the input points within reach of it (the widest ball,
:data:`engine.field.SPARSE_WIDENING` times the largest radius), so a tile is computed from the
points within its *core* (a cube of ``tile_cells`` cells) widened by a halo of
:data:`HALO_CELLS` cells, where the mesher sees the surface run on, and by that reach. Each tile
is meshed on its own; only the faces whose centroid lies in its core are kept (the cores tile
the space without overlap, so no face is kept twice).

Every tile's grid lies on one lattice shared by all tiles, so two neighbours compute the same
field, cover and, mostly, the same faces along their common border.

Stitching. Boundary vertices of different tiles within :data:`SAME_CELLS` of each other are one
vertex meshed by both and are merged; the others that are each other's nearest across tiles
within :data:`WELD_CELLS` cells are welded (to their mean). The two sides of an open sheet are
equally good layers, and a tile may keep the other side than its neighbours: such a tile is made
again keeping the side they kept (:func:`tiles_to_turn`), since the two sides share no vertices
along the border; a piece still facing the other way is turned over. A face both tiles kept
is kept once, faces left hanging on a weld are dropped and the holes left along the seam (up to
:data:`SEAM_HOLE_EDGES` edges) are closed.

Tiles are made one after the other in this process, in worker processes or on a Dask cluster
(:mod:`.tile_runners`), with the same result.

Memory is bounded by the tile size, not the scene; time grows with the number of tiles that
hold points.
"""

import dataclasses
from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np

from .progress import CancelFn, ProgressFn, no_progress, sub_progress

AUTO_TILE_CELLS = 192
"""With ``tile_cells`` 0, tiles of this many cells per side (a worker's memory follows it)."""
AUTO_TILE_ABOVE = 512
"""With ``tile_cells`` 0, a grid of more than this many cells along its longest side is tiled."""
HALO_CELLS = 8
"""Cells beyond a tile's core that it meshes too, so its core's faces see the surface go on."""
SAME_CELLS = 0.1
"""Boundary vertices of different tiles this close (cells) are one vertex meshed by both."""
SEAM_HOLE_EDGES = 16
"""Holes of up to this many edges left along a welded seam are closed."""
NORMAL_RINGS = 3
"""Rings of faces around a welded vertex whose normals vote on the orientation."""
WELD_CELLS = 0.9
"""Other boundary vertices of neighbouring tiles that are each other's nearest within this
many cells are welded too."""


@dataclass(frozen=True)
class Tile:
    """A cube of the grid: ``low <= x < high`` (working frame), numbered ``index`` per axis."""

    index: Tuple[int, int, int]
    low: np.ndarray
    high: np.ndarray


def plan_tiles(points: np.ndarray, spacing: float, tile_cells: int) -> List[Tile]:
    """The tiles of ``tile_cells`` cells per side that hold at least one point, in C order.

    The outermost tiles reach to infinity on their outer sides, so every point is in exactly
    one core.
    """
    low = points.min(axis=0)
    size = tile_cells * spacing
    counts = np.maximum(np.ceil((points.max(axis=0) - low) / size - 1e-9).astype(np.int64), 1)
    which = np.minimum(np.floor((points - low) / size).astype(np.int64), counts - 1)
    used = np.unique(np.ravel_multi_index(which.T, counts))
    tiles = []
    for flat in used:
        index = np.array(np.unravel_index(flat, counts))
        tile_low = np.where(index == 0, -np.inf, low + index * size)
        tile_high = np.where(index == counts - 1, np.inf, low + (index + 1) * size)
        tiles.append(Tile(tuple(int(i) for i in index), tile_low, tile_high))
    return tiles


def tile_points(points: np.ndarray, tile: Tile, reach: float) -> np.ndarray:
    """Indices of the points within ``reach`` of the tile's core box (per axis)."""
    inside = np.all((points >= tile.low - reach) & (points < tile.high + reach), axis=1)
    return np.flatnonzero(inside)


def keep_core(vertices: np.ndarray, faces: np.ndarray, tile: Tile):
    """The faces whose centroid lies in the tile's core, with only the vertices they use."""
    if not len(faces):
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    centroids = vertices[faces].mean(axis=1)
    faces = faces[np.all((centroids >= tile.low) & (centroids < tile.high), axis=1)]
    used, faces = np.unique(faces, return_inverse=True)
    return vertices[used], faces.reshape(-1, 3)


def stitch(pieces, spacing: float):
    """One mesh from the tiles' kept faces: ``pieces`` is a list of ``(vertices, faces)``.

    Returns
    -------
    vertices : (n, 3) float64; faces : (m, 3) int64
    stats : dict with ``welded`` vertices, ``flipped`` pieces, ``ears_dropped`` faces and
        ``holes_closed``
    """
    from .meshing.layers import close_pinholes
    from .meshing.mesh_ops import vertex_components

    vertices, faces, _, a, b = _joined(pieces, spacing)
    stats = {"welded": 0, "flipped": 0, "ears_dropped": 0, "holes_closed": 0}
    if len(a):
        count, face_piece = vertex_components(len(vertices), faces)
        faces, stats["flipped"] = _agree_orientation(vertices, faces, face_piece, count, a, b)
        vertices, merged = _weld(vertices, a, b)
        faces = merged[faces]
        faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2])
                      & (faces[:, 0] != faces[:, 2])]
        # a face both tiles kept once its corners are welded: keep it once
        faces = faces[np.sort(np.unique(np.sort(faces, axis=1), axis=0, return_index=True)[1])]
        stats["welded"] = int(len(vertices) - len(np.unique(merged)))
        faces, stats["ears_dropped"] = _drop_ears(faces)
        faces, stats["holes_closed"] = close_pinholes(faces, SEAM_HOLE_EDGES)
    return vertices, faces, stats


def tiles_to_turn(pieces, spacing: float) -> np.ndarray:
    """Indices of the tiles whose kept layer faces against their neighbours' across the
    borders (by the votes of :func:`_agree_orientation`): the smaller side, by area."""
    from .meshing.mesh_ops import face_normals, vertex_components

    vertices, faces, tile_of, a, b = _joined(pieces, spacing)
    if not len(a):
        return np.zeros(0, np.int64)
    count, face_piece = vertex_components(len(vertices), faces)
    turned = _agree_orientation(vertices, faces, face_piece, count, a, b)[0]
    flipped = turned[:, 0] != faces[:, 0]
    area = face_normals(vertices, faces)[1]
    if area[flipped].sum() > area[~flipped].sum():
        flipped = ~flipped  # an open sheet's orientation is free: turn the smaller side
    face_tile = tile_of[faces[:, 0]]
    share = np.bincount(face_tile, weights=area * flipped, minlength=len(pieces))
    total = np.bincount(face_tile, weights=area, minlength=len(pieces))
    return np.flatnonzero(share > 0.5 * np.maximum(total, 1e-300))


def _joined(pieces, spacing: float):
    """The pieces as one unwelded mesh, and the boundary vertices to weld across tiles.

    Returns ``vertices``, ``faces``, ``tile_of`` (the tile of each vertex) and the pairs
    ``(a, b)`` of vertex indices to weld (see :func:`_pairs_across`).
    """
    from .meshing.mesh_ops import edge_topology

    vertices = np.concatenate([v for v, _ in pieces] + [np.zeros((0, 3))])
    offsets = np.cumsum([0] + [len(v) for v, _ in pieces])
    faces = np.concatenate([f + o for (_, f), o in zip(pieces, offsets)]
                           + [np.zeros((0, 3), np.int64)]).astype(np.int64)
    tile_of = np.repeat(np.arange(len(pieces)), np.diff(offsets))
    if not len(faces):
        empty = np.zeros(0, np.int64)
        return vertices, faces, tile_of, empty, empty
    topo = edge_topology(faces)
    rim = np.unique(topo.edges[topo.counts == 1])
    a, b = _pairs_across(vertices[rim], tile_of[rim], spacing)
    return vertices, faces, tile_of, rim[a], rim[b]


def _drop_ears(faces: np.ndarray, passes: int = 3):
    """Drop the faces left hanging on a weld: a face with a third face on one of its edges and
    nothing on the other two (one tile's face over the other tile's, sharing an edge).
    Returns the faces and how many were dropped."""
    from .meshing.mesh_ops import edge_topology

    dropped = 0
    for _ in range(passes):
        if not len(faces):
            break
        topo = edge_topology(faces)
        uses = topo.counts[topo.face_edges]
        ear = ((uses == 1).sum(axis=1) == 2) & ((uses > 2).sum(axis=1) == 1)
        if not ear.any():
            break
        faces = faces[~ear]
        dropped += int(ear.sum())
    return faces, dropped


def _pairs_across(points: np.ndarray, tile_of: np.ndarray, spacing: float):
    """Pairs ``(i, j)`` of boundary vertices of different tiles to weld: every pair closer
    than :data:`SAME_CELLS` cells (the same vertex, meshed by both tiles), then, among the
    vertices left, each other's nearest of another tile within :data:`WELD_CELLS` cells."""
    from scipy.spatial import cKDTree

    if len(points) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    same = cKDTree(points).query_pairs(SAME_CELLS * spacing, output_type="ndarray")
    same = same[tile_of[same[:, 0]] != tile_of[same[:, 1]]]
    left = np.setdiff1d(np.arange(len(points)), same.reshape(-1))
    i, j = _mutual_nearest_across(points[left], tile_of[left], WELD_CELLS * spacing)
    return (np.concatenate([same[:, 0], left[i]]).astype(np.int64),
            np.concatenate([same[:, 1], left[j]]).astype(np.int64))


def _weld(vertices: np.ndarray, a: np.ndarray, b: np.ndarray):
    """Merge the vertices joined by pairs ``(a, b)``, each group at its mean position.

    Returns the new vertices and, per old vertex, the index of the vertex it became (the
    group's smallest index; unused vertices are left in place).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(vertices)
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    _, group = connected_components(graph, directed=False)
    first = np.full(group.max() + 1, n, dtype=np.int64)
    np.minimum.at(first, group, np.arange(n))
    merged = first[group]
    sums = np.zeros_like(vertices)
    np.add.at(sums, merged, vertices)
    size = np.bincount(merged, minlength=n)
    welded = vertices.copy()
    grouped = size > 1
    welded[grouped] = sums[grouped] / size[grouped, None]
    return welded, merged


def _mutual_nearest_across(points: np.ndarray, tile_of: np.ndarray, reach: float):
    """Pairs ``(i, j)``, ``i < j``, of points of different tiles that are each other's nearest
    point of another tile, closer than ``reach``."""
    from scipy.spatial import cKDTree

    if len(points) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    tree = cKDTree(points)
    k = min(8, len(points))
    distance, near = tree.query(points, k=k, distance_upper_bound=reach)
    distance = np.atleast_2d(distance)
    near = np.atleast_2d(near)
    valid = np.isfinite(distance)
    other = valid & (tile_of[np.minimum(near, len(points) - 1)] != tile_of[:, None])
    first = np.where(other.any(axis=1), np.argmax(other, axis=1), -1)
    has = first >= 0
    best = np.full(len(points), -1)
    best[has] = near[np.flatnonzero(has), first[has]]
    i = np.flatnonzero(has)
    j = best[i]
    mutual = best[j] == i
    i, j = i[mutual], j[mutual]
    keep = i < j
    return i[keep], j[keep]


def _agree_orientation(vertices, faces, face_piece, count, a, b):
    """Turn over the pieces whose faces at welded pairs face against their neighbours'.

    Each welded pair votes (the normals of the few rings around its two vertices agree or not)
    between the two pieces it joins; a spanning forest over the pieces, strongest votes first,
    fixes each piece's parity. ``face_piece`` (m,) numbers the pieces (``count`` of them) per face.
    Returns the faces (some rows reversed) and how many pieces were turned.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import minimum_spanning_tree

    from .meshing.mesh_ops import face_normals

    from .meshing.mesh_ops import incidence_matrix

    normals, areas = face_normals(vertices, faces)
    # the normal of the few rings around each vertex: the faces at a tile's cut are slivers
    incidence = incidence_matrix(len(vertices), faces)  # vertices x faces
    vertex_normal = incidence @ (normals * areas[:, None])
    for _ in range(NORMAL_RINGS):
        vertex_normal = incidence @ (incidence.T @ vertex_normal)
    vertex_normal /= np.maximum(np.linalg.norm(vertex_normal, axis=1), 1e-300)[:, None]
    agree = np.einsum("ij,ij->i", vertex_normal[a], vertex_normal[b])
    piece = np.zeros(len(vertices), np.int64)
    for k in range(3):
        piece[faces[:, k]] = face_piece
    pa, pb = piece[a], piece[b]
    between = pa != pb
    pa, pb, agree = pa[between], pb[between], agree[between]
    if not len(pa):
        return faces, 0
    lo, hi = np.minimum(pa, pb), np.maximum(pa, pb)
    key = lo * count + hi
    keys, inverse = np.unique(key, return_inverse=True)
    vote = np.bincount(inverse, weights=np.sign(agree), minlength=len(keys))
    strength = np.bincount(inverse, weights=np.abs(agree), minlength=len(keys))
    u, v = keys // count, keys % count
    # strongest evidence first: a minimum spanning forest over negative strengths
    graph = coo_matrix((-(strength + 1e-12), (u, v)), shape=(count, count)).tocsr()
    forest = minimum_spanning_tree(graph).tocoo()
    sign = dict(zip(zip(u.tolist(), v.tolist()), np.sign(vote).tolist()))
    adjacency = {}
    for x, y in zip(forest.row.tolist(), forest.col.tolist()):
        s = sign.get((min(x, y), max(x, y)), 1.0)
        adjacency.setdefault(x, []).append((y, s))
        adjacency.setdefault(y, []).append((x, s))
    flip = np.zeros(count, bool)
    seen = np.zeros(count, bool)
    for root in sorted(adjacency):
        if seen[root]:
            continue
        seen[root] = True
        stack = [root]
        while stack:
            node = stack.pop()
            for other, s in adjacency[node]:
                if not seen[other]:
                    seen[other] = True
                    flip[other] = flip[node] ^ (s < 0)
                    stack.append(other)
    turned = flip[face_piece]
    faces = faces.copy()
    faces[turned] = faces[turned][:, ::-1]
    return faces, int(flip.sum())


def tile_size(detail, settings) -> int:
    """Cells per tile side for a reconstruction, 0 for one grid without tiles."""
    if settings.tile_cells:
        return int(settings.tile_cells)
    return AUTO_TILE_CELLS if detail.cells > AUTO_TILE_ABOVE else 0


def tile_reach(settings, spacing: float) -> float:
    """How far beyond a tile's core its points must reach: the mesher's halo plus the widest
    ball any node of the halo may read (a sparse ball widened to its last factor)."""
    from .field import MIN_BAND_NODES, SPARSE_WIDENING
    from .radius import max_radius

    ball = max(max_radius(settings), MIN_BAND_NODES * spacing)
    return HALO_CELLS * spacing + SPARSE_WIDENING[-1] * ball + spacing


def mesh_tile(points: np.ndarray, tile: Tile, anchor: np.ndarray, settings, meshing,
              udf_source: str, progress: Optional[ProgressFn] = None,
              cancel: Optional[CancelFn] = None):
    """The field and mesh of one tile from its points (working frame); the faces of its core.

    Returns ``(vertices, faces, stats)``: the kept faces and the field's and mesher's numbers.
    """
    from .field import compute_udf_band
    from .meshing import extract_surface

    progress = progress or no_progress
    halo = HALO_CELLS / settings.resolution
    band = compute_udf_band(points, settings, sub_progress(progress, 0.0, 0.6), cancel,
                            udf_source=udf_source, anchor=anchor,
                            bounds=(tile.low - halo, tile.high + halo))
    meshed = extract_surface(band.grid, meshing, sub_progress(progress, 0.6, 1.0), cancel)
    vertices, faces = keep_core(np.asarray(meshed.mesh.vertices, np.float64),
                                np.asarray(meshed.mesh.faces, np.int64), tile)
    return vertices, faces, {**band.stats, "iso": float(meshed.iso)}


def mesh_in_tiles(points: np.ndarray, settings, meshing, tile_cells: int,
                  udf_source: str = "network", progress: Optional[ProgressFn] = None,
                  cancel: Optional[CancelFn] = None):
    """One mesh of a cloud (working frame) made tile by tile (see the module docstring).

    Returns
    -------
    vertices : (n, 3) float64; faces : (m, 3) int64
    field_stats : dict, the tiles' field numbers summed (``band_nodes``, ``network_queries``,
        ``sparse_balls``, ``widened_balls``), ``mean_patch_points`` over all, ``tiles``
    mesh_stats : dict, the stitching's numbers (``welded``, ``flipped``, ``ears_dropped``,
        ``holes_closed``), the clean-up's and ``iso`` (the tiles' median iso-level)
    """
    from .meshing.cleanup import clean_mesh
    from .tile_runners import available_cores

    from .tile_runners import run_tiles

    progress = progress or no_progress
    spacing = 1.0 / settings.resolution
    tiles = plan_tiles(points, spacing, tile_cells)
    anchor = points.min(axis=0)
    reach = tile_reach(settings, spacing)

    def job(number: int) -> tuple:
        tile = tiles[number]
        return (points[tile_points(points, tile, reach)], tile, anchor, settings, meshing,
                udf_source)

    # a tile's work follows the points it reads: workers take the largest tiles first
    costs = [len(tile_points(points, tile, reach)) for tile in tiles]
    results = run_tiles(mesh_tile, len(tiles), job, settings.workers, settings.scheduler,
                        sub_progress(progress, 0.0, 0.85), cancel, costs)
    # where a tile kept the other side of an open sheet than its neighbours, make it again
    # keeping the side they kept: the two sides share no vertices along the border
    turn = tiles_to_turn([(v, f) for v, f, _ in results], spacing)
    if len(turn):
        other = dataclasses.replace(meshing, other_side=not meshing.other_side)

        def again(number: int) -> tuple:
            return job(int(turn[number]))[:4] + (other, udf_source)

        redone = run_tiles(mesh_tile, len(turn), again, settings.workers, settings.scheduler,
                           sub_progress(progress, 0.85, 0.95), cancel,
                           [costs[int(number)] for number in turn])
        for number, result in zip(turn, redone):
            results[number] = result
    pieces = []
    sums = {"band_nodes": 0, "network_queries": 0, "sparse_balls": 0, "widened_balls": 0}
    patch_points = 0.0
    device = "none"
    isos = []
    for vertices, faces, band in results:
        isos.append(band["iso"])
        pieces.append((vertices, faces))
        for key in sums:
            sums[key] += int(band.get(key, 0))
        seen = band.get("network_queries", 0) - band["sparse_balls"]
        patch_points += band["mean_patch_points"] * seen
        device = band["device"]
    progress(0.95, f"stitching {len(tiles)} tiles")
    vertices, faces, stitched = stitch(pieces, spacing)
    vertices, faces, counts = clean_mesh(vertices, faces, spacing, meshing.min_component_faces)
    seen = sums["network_queries"] - sums["sparse_balls"]
    field_stats = {**sums, "tiles": len(tiles), "tile_cells": tile_cells, "spacing": spacing,
                   "workers": settings.workers or available_cores(),
                   "mean_patch_points": patch_points / max(seen, 1), "device": device,
                   "udf_source": udf_source}
    mesh_stats = {**stitched, "tiles_turned": int(len(turn)), **{f"cleanup_{k}": v for k, v in counts.items()},
                  "iso": float(np.median(isos)) if isos else 0.0}
    progress(1.0, "tiles stitched")
    return vertices, faces.astype(np.int64), field_stats, mesh_stats
