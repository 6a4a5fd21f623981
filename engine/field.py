"""The unsigned distance field on a grid band near the input points.

The grid covers the points' bounding box plus a margin, with spacing ``h = 1 / resolution`` and
the exact index-to-position map ``x = origin + i * h`` (``indexing='ij'``). Only the *band* is
evaluated: the nodes within distance R of some input point, with R the largest ball radius of
the radius policy, at most ``BAND_RADIUS_CAP`` (widened to ``MIN_BAND_NODES`` spacings on coarse
grids). They are found
without a k-d tree query per grid node: the points are voxelised onto the grid, the occupancy is
dilated by a cube of half-width ``ceil(R / h + 1/2)`` nodes (a superset of the band) and only
those candidates are checked against the exact nearest-point distance.

Band nodes get ``prediction * r`` from the backbone on their patch of radius r (the radius
policy's choice). A ball that holds fewer than ``MIN_PATCH_POINTS`` points is widened (by
``SPARSE_WIDENING``) until it holds enough: one or two points cannot tell the network where the
surface runs, and on a sparse scan their nearest-point distance would dent the field between
the samples. A ball still short at the widest (an isolated outlier) gets its node's
nearest-point distance (LoSF-UDF skips balls with fewer than 6 points), an upper bound of the
UDF when the points lie on the surface. Band nodes farther than ``NETWORK_BAND_NODES``
spacings from every input point also keep their nearest-point distance: the mesher's iso-level
is at most 2 spacings and its vertices end on the zero level, so only the nodes near the
surface need the network's accuracy (at resolution 256 this skips about a third
of the band). Where the cloud is sparse, points farther apart than those spacings (the far walls
of a room scan at 256), nodes up to ``SPARSE_BAND_NODES`` spacings away get the network too, as
far out as their nearest point's 4th neighbour: a nearest-point distance there rises above the
iso-level between the samples and left holes in the mesh. Every other node is farther than R
from all input points and holds R: the field is the UDF truncated at R, which is all the mesher
needs. With ``fill_gaps``, nodes in the plane of a sparse scan's points and surrounded by them,
up to ``gap_fill.GAP_NODES`` spacings from the nearest, take the distance to that plane
(:mod:`.gap_fill`): the surface runs on across gaps wider than the band.

``udf_source="nearest"`` replaces the network by the distance to the nearest input point: the
non-learned baseline, exact on the band up to the sampling gaps of the cloud.
"""

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Optional, Tuple

import numpy as np

from .cpu_threads import cpu_threads, map_in_threads, query_threads, run_in_threads
from .devices import resolve_device
from .errors import InputError
from .gap_fill import fill_gaps
from .udf_grid import UDFGrid
from .patches import (MAX_POINTS, QUERY_CHUNK, gather_patches, groups_by_count,
                      patches_from_neighbours)
from .progress import CancelFn, ProgressFn, check_cancel, no_progress
from .radius import (max_radius, parent_ball, radii_for_queries, reads_parent_ball,
                     require_policy)
from .radius_lattice import lattice_radii, lattice_step, ridge_nodes
from .settings import UDF_SOURCES, ReconstructSettings, radius_range

# Balls with fewer points use the nearest-point distance (see the module docstring).
MIN_PATCH_POINTS = 3
# Balls with fewer points are widened by these factors in turn until one holds enough
# (see widen_sparse_balls); past the last, the nearest-point distance stays.
SPARSE_WIDENING = (1.5, 2.0, 3.0)
# Band nodes farther than this many spacings from every input point keep the nearest-point
# distance (an upper bound) instead of the network's value: above the mesher's iso-level (<= 2).
NETWORK_BAND_NODES = 3.0
# ... unless the cloud is sparse there: a node up to this many spacings from its nearest point
# still gets the network's value when that point's 4th-nearest neighbour is at least as far
# (between the lines of a sparse scan the surface runs farther from every point than 3 spacings).
SPARSE_BAND_NODES = 5.0
SPARSE_NEIGHBOUR = 4
# Margin beyond the band radius on each side of the grid, in nodes.
MARGIN_NODES = 3
# The band reaches at most this far from the points (working frame) whatever the largest ball:
# the network's nodes lie within SPARSE_BAND_NODES spacings of a point and the rest only have
# to stand above the mesher's iso-level, so a wider band (the learned mode's balls reach 0.072)
# would cost time and memory for nodes that hold nearest-point distances.
BAND_RADIUS_CAP = 0.024
# The band is at least this many spacings wide, so that the mesher sees a few nodes of true
# distance on each side of the surface even when the ball radius is below one spacing.
MIN_BAND_NODES = 3
# Queries per backbone call: about 8k x 64 x 3 float32 = 6 MB of patches on CPU.
CPU_BATCH = 8192
CUDA_BATCH = 65536
# Patches are cut to their group's largest point count before the backbone (see
# predict_trimmed); no narrower than MIN_WIDTH columns (the backbone reads its 8 nearest).
TRIM_GROUP = 1024
MIN_WIDTH = 16

Predictor = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass
class BandField:
    """A UDF grid and how it was made.

    grid : UDFGrid
        The field as a sparse band, unit frame; ``far_value`` (= band radius) elsewhere.
    stats : dict
        ``grid_shape``, ``spacing``, ``band_radius``, ``band_nodes``, ``network_queries`` (band
        nodes within ``NETWORK_BAND_NODES`` spacings of a point), ``widened_balls`` (balls widened
        to reach ``MIN_PATCH_POINTS`` points), ``sparse_balls`` (such nodes whose ball held
        fewer points even widened: not sent to the network),
        ``mean_patch_points`` (over the balls the network saw),
        ``udf_source``, ``device`` (``cpu``, ``cuda``, ``custom`` predictor or ``none``),
        ``seconds_band``, ``seconds_udf``, ``seconds_radius`` (the part of ``seconds_udf``
        spent choosing radii, the selector or the curvature estimate with the parent ball's
        neighbour search: ``seconds_udf`` times the radius policy's share of the batches'
        time, as the batches run on several threads at once), ``seconds_parent_ball`` (the
        part of ``seconds_radius`` spent on the parent ball's neighbour search, whose lists
        also give the backbone its patches), ``gap_nodes`` and ``seconds_gap_fill`` (the nodes
        the gap fill set and its part of ``seconds_udf``; the gaps are looked for with the fill
        off too), ``open_gap_nodes`` (with the fill off, the nodes it would have set).
    """

    grid: UDFGrid
    stats: dict = field(default_factory=dict)


def grid_layout(points: np.ndarray, resolution: int, band_radius: float,
                anchor: Optional[np.ndarray] = None, bounds=None,
                ) -> Tuple[Tuple[int, int, int], np.ndarray, float]:
    """The grid that holds the band of ``points``.

    Parameters
    ----------
    points : (N, 3) float array, unit frame
    resolution : grid cells along the longest side of the unit frame (spacing 1 / resolution)
    band_radius : R, the largest ball radius (unit frame)
    anchor : (3,) float, optional
        A node of a larger grid (a tiled reconstruction's): the grid's nodes are that grid's
        nodes. Without, the grid is centred on the points' bounding box.
    bounds : ``(low, high)`` (3,) float arrays, optional, with ``anchor``
        Clip the grid to this box (a tile's core and halo).

    Returns
    -------
    shape : (nx, ny, nz) node counts
    origin : (3,) float64, position of node (0, 0, 0)
    spacing : float, h
    """
    spacing = 1.0 / resolution
    low, high = points.min(axis=0), points.max(axis=0)
    margin = math.ceil(band_radius / spacing) + MARGIN_NODES
    if anchor is not None:
        low, high = low - margin * spacing, high + margin * spacing
        if bounds is not None:
            low, high = np.maximum(low, bounds[0]), np.minimum(high, bounds[1])
        start = np.floor((low - anchor) / spacing).astype(np.int64)
        stop = np.ceil((high - anchor) / spacing).astype(np.int64)
        shape = tuple(int(n) for n in np.maximum(stop - start + 1, 2))
        return shape, anchor + start * spacing, spacing
    cells = np.ceil((high - low) / spacing - 1e-9).astype(np.int64)
    shape = tuple(int(c) + 1 + 2 * margin for c in cells)
    centre = 0.5 * (low + high)
    origin = centre - 0.5 * (np.asarray(shape, dtype=np.float64) - 1.0) * spacing
    return shape, origin, spacing


def find_band(tree, points: np.ndarray, shape: Tuple[int, int, int], origin: np.ndarray,
              spacing: float, band_radius: float, cancel: Optional[CancelFn] = None,
              with_owner: bool = False):
    """Every grid node within ``band_radius`` of an input point, and its nearest-point distance.

    Parameters
    ----------
    tree : scipy.spatial.cKDTree over the cloud
    points : (N, 3) float array, unit frame: the cloud, or some of its points (then the nodes
        within ``band_radius`` of those along every axis, a cube, whose nearest point of the
        whole cloud lies within ``band_radius``); points outside the grid are passed over (a
        tile's grid: nodes near its edge may then miss the band, which its halo allows for)
    shape, origin, spacing : the grid (see :func:`grid_layout`)
    band_radius : R, unit frame
    cancel : optional cancel check, called between chunks
    with_owner : also return the index of each node's nearest point in ``tree``

    Returns
    -------
    indices : (M, 3) int64 node indices, in C order of the grid
    nearest : (M,) float64 distance from each node to the nearest point of the cloud, <= R
    owner : (M,) int64, that point's index in ``tree``, with ``with_owner`` only
    """
    from scipy import ndimage

    voxels = np.rint((points - origin) / spacing).astype(np.int64)
    voxels = voxels[np.all((voxels >= 0) & (voxels < np.asarray(shape)), axis=1)]
    occupied = np.zeros(shape, dtype=np.uint8)
    occupied[voxels[:, 0], voxels[:, 1], voxels[:, 2]] = 1
    # a node within R of p is within R/h + 1/2 nodes of p's nearest node along every axis
    width = 2 * math.ceil(band_radius / spacing + 0.5) + 1
    for axis in range(3):
        occupied = ndimage.maximum_filter1d(occupied, width, axis=axis, mode="constant")
    check_cancel(cancel)
    candidates = np.argwhere(occupied)
    del occupied
    bound = float(np.nextafter(band_radius, np.inf))
    keep = np.zeros(len(candidates), dtype=bool)
    nearest = np.empty(len(candidates), dtype=np.float64)
    owner = np.empty(len(candidates), dtype=np.int64)
    for start in range(0, len(candidates), 4 * QUERY_CHUNK):
        stop = min(start + 4 * QUERY_CHUNK, len(candidates))
        positions = origin + candidates[start:stop] * spacing
        distance, owner[start:stop] = tree.query(positions, k=1, distance_upper_bound=bound,
                                                 workers=query_threads())
        keep[start:stop] = distance <= band_radius
        nearest[start:stop] = distance
        check_cancel(cancel)
    if with_owner:
        return candidates[keep], nearest[keep], owner[keep]
    return candidates[keep], nearest[keep]


def backbone_predictor(device: str) -> Predictor:
    """The backbone as ``predict(rel (B, 64, 3) float32, mask (B, 64) bool) -> (B,) UDF / r``.

    numpy on ``cpu`` (what Blender ships), torch on ``cuda``.
    """
    from . import backbone

    if not backbone.DEFAULT_WEIGHTS.exists():
        raise InputError(f"the backbone weights ({backbone.DEFAULT_WEIGHTS.name}) are missing "
                         f"from {backbone.DEFAULT_WEIGHTS.parent}; reinstall the extension, or "
                         f"use the 'nearest' UDF source")
    if device == "cpu":
        return backbone.load_backbone_numpy().predict
    import torch

    model = backbone.load_backbone_torch(device=device)

    def predict(rel: np.ndarray, mask: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            out = model(torch.from_numpy(rel).to(device), torch.from_numpy(mask).to(device))
        return out.float().cpu().numpy()

    return predict


def compute_udf_band(points_unit: np.ndarray, settings: Optional[ReconstructSettings] = None,
                     progress: Optional[ProgressFn] = None, cancel: Optional[CancelFn] = None,
                     udf_source: str = "network", tree=None,
                     predictor: Optional[Predictor] = None, anchor: Optional[np.ndarray] = None,
                     bounds=None) -> BandField:
    """Evaluate the unsigned distance field on the band of grid nodes near the points.

    Parameters
    ----------
    points_unit : (N, 3) float array
        Input points in the unit frame (bounding box longest side 1).
    settings : ReconstructSettings, optional
        ``resolution`` (grid spacing 1 / resolution), the radius policy and its radii, ``device``.
    progress : callable ``(fraction, message)``, optional
    cancel : callable ``() -> bool``, optional
        Checked between batches; raises :class:`Cancelled` when it returns True.
    udf_source : ``"network"`` or ``"nearest"``
        The backbone, or the distance to the nearest input point (no network).
    tree : scipy.spatial.cKDTree over ``points_unit``, optional (built when missing)
    predictor : callable, optional
        Replaces the backbone (same signature as :func:`backbone_predictor`'s result).
    anchor, bounds : optional
        Put the grid's nodes on a larger grid's and clip it to a box (a tile; see
        :func:`grid_layout`).

    Returns
    -------
    BandField
        The grid (float32 UDF, unit frame) and statistics.
    """
    from scipy.spatial import cKDTree

    settings = (settings or ReconstructSettings()).validate()
    if udf_source not in UDF_SOURCES:
        raise InputError(f"udf source must be one of {', '.join(UDF_SOURCES)}, not {udf_source!r}")
    progress = progress or no_progress
    points = np.asarray(points_unit, dtype=np.float64).reshape(-1, 3)
    use_network = udf_source == "network"
    if use_network:
        require_policy(settings)  # refuse an unavailable radius mode before any work
    tree = tree if tree is not None else cKDTree(points)

    started = time.perf_counter()
    progress(0.0, "finding the query band")
    spacing = 1.0 / settings.resolution
    band_radius = max(min(max_radius(settings), BAND_RADIUS_CAP), MIN_BAND_NODES * spacing)
    shape, origin, spacing = grid_layout(points, settings.resolution, band_radius, anchor,
                                         bounds)
    indices, nearest, owner = find_band(tree, points, shape, origin, spacing, band_radius,
                                        cancel, with_owner=True)
    seconds_band = time.perf_counter() - started
    stats = {"grid_shape": shape, "spacing": spacing, "band_radius": band_radius,
             "band_nodes": int(len(indices)), "udf_source": udf_source, "device": "none",
             "sparse_balls": 0, "widened_balls": 0, "mean_patch_points": 0.0,
             "seconds_band": seconds_band}
    progress(0.1, f"query band: {len(indices):,} grid nodes")

    started = time.perf_counter()
    if use_network:
        near = _network_nodes(tree, points, nearest, owner, spacing)
        stats["network_queries"] = int(near.sum())
        values = nearest.astype(np.float32)
        # the radius lattice is anchored where the tiles of one reconstruction share a node
        lattice_origin = origin if anchor is None else np.asarray(anchor, dtype=np.float64)
        nodes = indices[near] + np.rint((origin - lattice_origin) / spacing).astype(np.int64)
        queries = origin + indices[near] * spacing
        values[near] = _network_values(points, tree, queries, nearest[near], settings,
                                       predictor, progress, cancel, stats,
                                       (nodes, lattice_origin, spacing, owner[near]))
    else:
        values = nearest.astype(np.float32)
    del owner
    # the gaps are looked for either way: with the fill off, how many nodes it would have set
    # tells the user whether to turn it on, whatever the radius mode
    progress(0.9, "looking for gaps between the scan's points")
    filling = time.perf_counter()
    filled_indices, filled_values, gap_nodes = fill_gaps(
        tree, points, shape, origin, spacing, indices, values,
        origin if anchor is None else np.asarray(anchor, dtype=np.float64))
    if settings.fill_gaps:
        indices, values = filled_indices, filled_values
        stats["gap_nodes"], stats["open_gap_nodes"] = gap_nodes, 0
    else:
        stats["gap_nodes"], stats["open_gap_nodes"] = 0, gap_nodes
    del filled_indices, filled_values
    stats["seconds_gap_fill"] = time.perf_counter() - filling
    stats["seconds_udf"] = time.perf_counter() - started
    # the radius lattice's time, then the policy's share of the batches' time
    lattice_seconds = stats.pop("lattice_seconds", 0.0)
    batches = stats["seconds_udf"] - lattice_seconds
    stats["seconds_radius"] = lattice_seconds + stats.pop("radius_share", 0.0) * batches
    stats["seconds_parent_ball"] = stats.pop("parent_share", 0.0) * batches
    grid = UDFGrid.from_band(indices, values, shape, origin, spacing, far_value=band_radius)
    progress(1.0, "field done")
    return BandField(grid, stats)


def _network_nodes(tree, points: np.ndarray, nearest: np.ndarray, owner: np.ndarray,
                   spacing: float) -> np.ndarray:
    """The band nodes that get the network's value (see ``NETWORK_BAND_NODES``): ``nearest``
    and ``owner``, each node's nearest-point distance and that point (:func:`find_band`)."""
    near = nearest <= NETWORK_BAND_NODES * spacing
    gap = np.flatnonzero(~near & (nearest <= SPARSE_BAND_NODES * spacing))
    if len(gap) and len(points) > SPARSE_NEIGHBOUR:
        owners, which = np.unique(owner[gap], return_inverse=True)
        local, _ = tree.query(points[owners], k=[SPARSE_NEIGHBOUR + 1])
        near[gap] = nearest[gap] <= local[which.ravel(), 0]
    return near


def _network_values(points: np.ndarray, tree, queries: np.ndarray, nearest: np.ndarray,
                    settings: ReconstructSettings, predictor: Optional[Predictor],
                    progress: ProgressFn, cancel: Optional[CancelFn], stats: dict,
                    lattice=None) -> np.ndarray:
    """Backbone UDF (unit frame) at each band query: (M,) float32.

    The queries go in batches; on the CPU the batches run on one thread per core
    (:mod:`engine.cpu_threads`), each batch whole: its neighbour search, radius policy and
    backbone. A batch is cut and computed the same way on any number of threads.

    ``lattice``: ``(nodes, lattice_origin, spacing, owner)``, the queries' grid nodes and the
    index of each one's nearest point. Where the policy's parent ball spans many spacings its
    radii come from a coarser lattice (:mod:`engine.radius_lattice`), before the batches;
    on the ridges of the nearest-point distance a node keeps its own radius where wider.
    """
    if predictor is None:
        device = resolve_device(settings.device)
        predictor = backbone_predictor(device)
        stats["device"] = device
    else:
        stats["device"] = "custom"
    on_gpu = stats["device"] == "cuda"
    batch = CUDA_BATCH if on_gpu else CPU_BATCH
    group = batch if on_gpu else TRIM_GROUP  # a GPU prefers few large calls
    threads = 1 if on_gpu else cpu_threads()
    values = np.empty(len(queries), dtype=np.float32)
    step = 1
    if lattice is not None and reads_parent_ball(settings):
        step = lattice_step(radius_range(settings)[0], lattice[2])
    stats["lattice_step"] = step
    lattice_seconds, on_lattice = 0.0, None
    if step > 1:
        lattice_seconds = time.perf_counter()
        nodes, lattice_origin, spacing, owner = lattice
        ridge = ridge_nodes(nodes, queries - points[owner], spacing)
        on_lattice, found = lattice_radii(
            lambda positions: radii_for_queries(settings, tree, points, positions,
                                                parent_ball(settings, tree, positions)),
            nodes, lattice_origin, spacing, step, threads, cancel, own=ridge)
        stats["lattice_positions"] = found["lattice_positions"]
        stats["lattice_own_nodes"] = found["lattice_own_nodes"]
        lattice_seconds = time.perf_counter() - lattice_seconds

    def one_batch(start: int) -> dict:
        check_cancel(cancel)
        stop = min(start + batch, len(queries))
        mark = time.perf_counter()
        batch_queries = queries[start:stop]
        # the parent ball's lists also hold the backbone's patch: one k-d query serves both
        parent = None
        if reads_parent_ball(settings) and on_lattice is None:
            parent = parent_ball(settings, tree, batch_queries)
        seconds_parent = time.perf_counter() - mark
        if on_lattice is None:
            radii = radii_for_queries(settings, tree, points, batch_queries, parent)
        else:
            radii = on_lattice[start:stop].copy()
        seconds_radius = time.perf_counter() - mark
        if parent is None:
            rel, mask, counts = gather_patches(tree, points, batch_queries, radii, MAX_POINTS)
        else:
            rel, mask, counts = patches_from_neighbours(points, batch_queries, parent, radii,
                                                        MAX_POINTS)
        widened = 0
        few = np.flatnonzero(counts < MIN_PATCH_POINTS)
        if len(few):
            grown = widen_sparse_balls(tree, points, batch_queries[few], radii[few])
            rel[few], mask[few], counts[few], radii[few], widened = grown
        chunk = nearest[start:stop].astype(np.float32)
        seen = np.flatnonzero(counts >= MIN_PATCH_POINTS)
        chunk[seen] = predict_trimmed(predictor, rel[seen], mask[seen], counts[seen],
                                       group, cancel) * radii[seen]
        values[start:stop] = chunk
        return {"count": stop - start, "sparse": len(counts) - len(seen), "widened": widened,
                "points": int(counts[seen].sum()), "seconds_radius": seconds_radius,
                "seconds_parent": seconds_parent, "seconds": time.perf_counter() - mark}

    totals = {"sparse": 0, "widened": 0, "points": 0, "seconds_radius": 0.0,
              "seconds_parent": 0.0, "seconds": 0.0}
    done = 0
    results = map_in_threads(one_batch, range(0, len(queries), batch), threads)
    try:
        for result in results:
            for key in totals:
                totals[key] += result[key]
            done += result["count"]
            progress(0.1 + 0.8 * done / len(queries),  # the gap fill follows, up to 1
                     f"network UDF: {done:,} / {len(queries):,} queries")
    finally:
        results.close()  # on a cancel from the progress report too: start no other batch
    stats["sparse_balls"] = totals["sparse"]
    stats["widened_balls"] = totals["widened"]
    # the radius policy's share of the batches' time (on several threads their times overlap)
    stats["radius_share"] = totals["seconds_radius"] / max(totals["seconds"], 1e-12)
    stats["parent_share"] = totals["seconds_parent"] / max(totals["seconds"], 1e-12)
    stats["lattice_seconds"] = lattice_seconds
    stats["mean_patch_points"] = totals["points"] / max(len(queries) - totals["sparse"], 1)
    return values


def widen_sparse_balls(tree, points: np.ndarray, queries: np.ndarray, radii: np.ndarray):
    """Patches for balls that hold too few points, from balls widened by ``SPARSE_WIDENING``.

    On a sparsely sampled surface (10 000 points over a room) a ball of the chosen radius can
    hold one or two points. Their nearest-point distance (the fallback) has its zeros at the
    samples themselves and rises between them, so the surface between the samples is lost
    (the first sparse test room: CD-L1 x100 0.999 without widening, 0.628 with it). A wider
    ball holds the neighbours that show where the surface runs; the backbone reads any radius
    (its input is scaled by r, its output multiplied by r) and was trained on patches of a
    handful of points upwards. Each ball takes the first factor that gives it
    ``MIN_PATCH_POINTS`` points; a ball still short at the last factor (an isolated outlier)
    keeps the fallback.

    Returns
    -------
    rel, mask, counts, radii : as the inputs of the backbone, for every query
    widened : int, how many balls found enough points
    """
    rel = np.zeros((len(queries), MAX_POINTS, 3), dtype=np.float32)
    mask = np.zeros((len(queries), MAX_POINTS), dtype=bool)
    counts = np.zeros(len(queries), dtype=np.int64)
    radii = np.array(radii, dtype=np.float64)
    todo = np.arange(len(queries))
    for factor in SPARSE_WIDENING:
        if not len(todo):
            break
        wider = radii[todo] * factor
        part_rel, part_mask, part_counts = gather_patches(tree, points, queries[todo], wider,
                                                          MAX_POINTS)
        enough = part_counts >= MIN_PATCH_POINTS
        rows = todo[enough]
        rel[rows], mask[rows] = part_rel[enough], part_mask[enough]
        counts[rows], radii[rows] = part_counts[enough], wider[enough]
        todo = todo[~enough]
    return rel, mask, counts, radii, len(queries) - len(todo)


def predict_trimmed(predictor: Predictor, rel: np.ndarray, mask: np.ndarray,
                     counts: np.ndarray, group_size: int,
                     cancel: Optional[CancelFn] = None, threads: int = 1) -> np.ndarray:
    """UDF / r of patches with points, (B,) float64, computed on as few padding rows as possible.

    Padding rows never change the backbone's output, but they cost as much as real points. The
    patches are taken in order of point count, in groups of ``group_size``, each cut to its
    largest count (at least ``MIN_WIDTH`` columns); ``cancel`` is checked before each group.
    With ``threads`` > 1 the groups run on that many threads (:mod:`engine.cpu_threads`); each
    group's answer is the same either way.
    """
    out = np.empty(len(counts), dtype=np.float64)

    def predict_group(item) -> None:
        group, width = item
        check_cancel(cancel)
        out[group] = np.asarray(predictor(rel[group, :width], mask[group, :width]),
                                dtype=np.float64).reshape(-1)

    run_in_threads(predict_group, groups_by_count(counts, group_size, MIN_WIDTH), threads)
    return out
