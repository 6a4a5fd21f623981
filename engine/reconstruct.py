"""The one entry point of a reconstruction: points in, mesh out.

The CLI, the Blender operator, the batch script and the benchmark all call :func:`reconstruct`;
none of them re-implements a stage. The stages (DESIGN.md, "Data flow"):

1. validate the settings; refuse clouds no surface can be built from; drop isolated points
   when there are many or they stretch the bounding box (:mod:`.outliers`); choose the cell
   size and put the points in the working frame (:mod:`.detail`);
2. evaluate the UDF on the grid band near the points (:mod:`.field`);
3. extract a single-layer mesh with DCUDF (:mod:`.meshing`);
4. map the mesh back to the input's coordinates (the same similarity transform, inverted) and
   carry the input colours to its vertices (nearest input point).
"""

import time
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Union

import numpy as np

from .cpu_threads import core_budget, query_threads
from .errors import InputError
from .field import UDF_SOURCES, compute_udf_band
from .detail import AUTO_MAX_CELLS, choose_detail
from .frame import validate_points
from .geometry import Mesh, PointCloud
from .outliers import AUTO_SHARE, AUTO_SHRINK, box_shrink, find_outliers
from .progress import CancelFn, ProgressFn, check_cancel, no_progress, sub_progress
from .settings import ReconstructSettings

_NO_FACES = np.zeros((0, 3), np.int64)
# Share of the progress bar per stage (the field and the mesher take most of the time).
_OUTLIERS_END = 0.01
_FIELD_END = 0.6
_MESH_END = 0.97
# Below this mean number of points per ball the backbone sees too little of the surface.
SPARSE_PATCH_POINTS = 6.0
# From this share of the band's nodes in gaps the gap fill (switched off) would have filled, the
# scan has gaps wider than the ball: at 128 a line scan reaches 0.9, the benchmark's sparse rooms
# 0.05-0.06, its clean rooms about 0.01, its objects under 0.01 (every radius mode).
GAPPY_SHARE = 0.02


@dataclass
class ReconstructResult:
    """What a reconstruction produced.

    mesh : Mesh or None
        In the input's own coordinates; colours when the input had colours. None when
        :func:`.reconstruct_to_file.reconstruct_to_file` wrote it to the file tile by tile.
    messages : list of str
        Notes for the user (warnings from the mesher, too sparse a cloud, ...).
    timings : dict of str to float
        Seconds per stage: ``outliers``, ``frame``, ``band``, ``udf``, ``meshing``, ``finish``,
        ``total``, and the mesher's own stages as ``meshing_<stage>``.
    stats : dict
        ``points`` (used), ``outliers`` (dropped), ``outliers_found`` (flagged: ``auto`` keeps
        them when they are few and do not stretch the bounding box), ``grid_shape``,
        ``spacing``, ``band_radius``, ``band_nodes``,
        ``queries`` (backbone evaluations), ``sparse_balls``, ``mean_patch_points``,
        ``udf_source``, ``device``, ``iso`` (working frame), ``voxel_size`` (cell length, input units), ``cells`` (along the
        longest side), ``components`` (pieces of the output),
        ``vertices``, ``faces``, ``meshing`` (the mesher's own numbers). Made in tiles
        (:mod:`.tiles`): ``tiles``, ``tile_cells`` and ``workers`` too, the field's numbers summed
        over the tiles, the stitching's in ``meshing``, ``timings["tiles"]`` for field and mesh.
    """

    mesh: Optional[Mesh]
    messages: List[str] = field(default_factory=list)
    timings: Dict[str, float] = field(default_factory=dict)
    stats: dict = field(default_factory=dict)


def reconstruct(cloud: Union[PointCloud, np.ndarray],
                settings: Optional[ReconstructSettings] = None,
                progress: Optional[ProgressFn] = None, cancel: Optional[CancelFn] = None,
                udf_source: Optional[str] = None) -> ReconstructResult:
    """Reconstruct a mesh from a point cloud.

    Parameters
    ----------
    cloud : PointCloud or (N, 3) float array
        The points in any units; ``colors`` (N, 3|4) in [0, 1] are carried to the mesh.
    settings : ReconstructSettings or dict, optional
        Defaults to ``ReconstructSettings()``; a dict names settings to change from the
        defaults. Radii are in the working frame (:mod:`.detail`).
    progress : callable ``(fraction, message)``, optional
        Called with fractions rising from 0 to 1 over the whole reconstruction.
    cancel : callable ``() -> bool``, optional
        Polled between batches; when it returns True, :class:`Cancelled` is raised.
    udf_source : ``"network"`` or ``"nearest"``, optional
        The backbone, or the non-learned distance to the nearest input point; overrides the
        settings' ``udf_source``.

    Returns
    -------
    ReconstructResult

    Raises
    ------
    InputError
        Bad settings or a cloud no surface can be built from (NaN, too few points, a line ...).
    Cancelled
        ``cancel()`` returned True.
    """
    settings = ReconstructSettings.coerce(settings)
    with core_budget(settings.workers):  # --workers 1: one core, in every stage
        return _reconstruct(cloud, settings, progress, cancel, udf_source)


def _reconstruct(cloud, settings: ReconstructSettings, progress, cancel,
                 udf_source: Optional[str], write_tiled=None) -> ReconstructResult:
    """:func:`reconstruct`; ``write_tiled(stitched, frame, colors, tree, progress)``, given,
    takes a mesh made in tiles as it is stitched (a :class:`.tiles.StitchedMesh`, working
    frame) and returns ``(pieces, faces of the largest piece)``: the result then has no mesh
    (:func:`.reconstruct_to_file.reconstruct_to_file`)."""
    from scipy.spatial import cKDTree

    from .meshing import MeshingResult, extract_surface
    from .tiles import mesh_in_tiles, tile_size

    started = time.perf_counter()
    progress = progress or no_progress
    udf_source = udf_source or settings.udf_source
    if udf_source not in UDF_SOURCES:
        raise InputError(f"udf source must be one of {', '.join(UDF_SOURCES)}, not {udf_source!r}")
    if isinstance(cloud, PointCloud):
        points, colors = cloud.points, cloud.colors
    else:
        points, colors = cloud, None
    timings: Dict[str, float] = {}

    progress(0.0, "preparing the points")
    points = validate_points(points)
    if colors is not None and len(colors) != len(points):
        raise InputError(f"the cloud has {len(colors)} colours for {len(points)} points; "
                         f"give one colour per point or none")
    progress(0.0, "finding outliers")
    mark = time.perf_counter()
    given = len(points)
    points, colors, outliers_found, outliers, shrink = _drop_outliers(
        points, colors, settings, sub_progress(progress, 0.0, _OUTLIERS_END), cancel)
    timings["outliers"] = time.perf_counter() - mark
    check_cancel(cancel)
    detail = choose_detail(points, settings)
    frame = detail.frame
    tile_cells = tile_size(detail, settings)
    # tiles map their own points to the working frame: no copy of the cloud there is held,
    # except for the k-d tree that serves the untiled field and the colours
    points_unit = None
    if not tile_cells or colors is not None:
        points_unit = frame.to_unit(points)
    tree = None if points_unit is None else cKDTree(points_unit)
    count = len(points)
    if not tile_cells:
        del points  # the working frame's copy is all that is read from here on
    timings["frame"] = time.perf_counter() - started - timings["outliers"]
    check_cancel(cancel)

    written = None
    if tile_cells:
        mark = time.perf_counter()
        def write_counted(stitched, write_progress):
            counts = (stitched.vertex_count, stitched.face_count)
            return counts + write_tiled(stitched, frame, colors, tree, write_progress)
        consume = None if write_tiled is None else write_counted
        output, field_stats, mesh_stats = mesh_in_tiles(
            points, settings, meshing_settings(settings), tile_cells, udf_source,
            sub_progress(progress, 0.01, _MESH_END), cancel, consume, frame.to_unit)
        timings["tiles"] = time.perf_counter() - mark
        written = output if consume is not None else None
        mesh = Mesh(*output) if written is None else Mesh(np.zeros((0, 3)), _NO_FACES)
        meshed = MeshingResult(mesh, mesh_stats.pop("iso"), {}, [], mesh_stats)
    else:
        band = compute_udf_band(points_unit, settings, sub_progress(progress, 0.01, _FIELD_END),
                                cancel, udf_source=udf_source, tree=tree)
        timings["band"] = band.stats.pop("seconds_band")
        timings["udf"] = band.stats.pop("seconds_udf")
        field_stats = band.stats
        check_cancel(cancel)

        mark = time.perf_counter()
        meshed = extract_surface(band.grid, meshing_settings(settings),
                                 sub_progress(progress, _FIELD_END, _MESH_END), cancel)
        timings["meshing"] = time.perf_counter() - mark
    check_cancel(cancel)

    mark = time.perf_counter()
    result_mesh = None
    if written is None:
        progress(_MESH_END, "mapping the mesh back to the input's coordinates")
        result_mesh = _in_input_frame(meshed.mesh, frame, colors, tree, bool(tile_cells))
        counts = (len(result_mesh.vertices), len(result_mesh.faces),
                  _piece_count(result_mesh))
    else:
        counts = written[:3]
    timings["finish"] = time.perf_counter() - mark
    timings["total"] = time.perf_counter() - started

    stats = {"points": int(count), "outliers": outliers,
             "voxel_size": detail.voxel_size, "cells": detail.cells,
             "outliers_found": outliers_found, **field_stats,
             "queries": (field_stats["network_queries"] - field_stats["sparse_balls"]
                         if udf_source == "network" else 0),
             "iso": float(meshed.iso), "components": int(counts[2]),
             "vertices": int(counts[0]), "faces": int(counts[1]),
             "meshing": dict(meshed.stats), "meshing_notes": list(meshed.details)}
    timings.update({f"meshing_{stage}": seconds for stage, seconds in meshed.timings.items()})
    messages = list(meshed.messages)
    if outliers:
        why = (f": they stretched the bounding box {shrink:,.0f} times"
               if settings.outliers == "auto" and outliers < AUTO_SHARE * given else "")
        messages.insert(0, f"dropped {outliers:,} isolated points ({_share(outliers, given, 1)}) "
                           f"as outliers"
                           f"{why}; set outliers to 'keep' to use every point")
    elif outliers_found:
        points = "point" if outliers_found == 1 else "points"
        messages.insert(0, f"kept {outliers_found:,} isolated {points} "
                           f"({_share(outliers_found, given, 2)}): too "
                           f"few to be outliers; set outliers to 'drop' to remove them")
    if detail.capped:
        messages.append(f"auto detail stops at {AUTO_MAX_CELLS} cells along the longest side "
                        f"({detail.voxel_size:.3g} units per cell); set Detail to Voxel Size for "
                        f"finer cells")
    if udf_source == "network" and 0 < field_stats["mean_patch_points"] < SPARSE_PATCH_POINTS:
        messages.insert(0, f"the balls hold only {field_stats['mean_patch_points']:.1f} points on "
                           f"average; for a cloud this sparse, raise the radius")
    open_gaps = field_stats.get("open_gap_nodes", 0) / max(field_stats["band_nodes"], 1)
    if open_gaps >= GAPPY_SHARE:
        messages.append(f"the scan has gaps wider than the ball in places "
                        f"({100 * open_gaps:.0f} % of the field's nodes lie in them); turn on "
                        f"Fill Gaps (--fill-gaps) to carry flat surfaces across them")
    if stats["faces"] == 0:
        messages.append("the mesh is empty: try a larger radius or a lower resolution")
    progress(1.0, f"done: {stats['vertices']:,} vertices, {stats['faces']:,} faces")
    return ReconstructResult(result_mesh, messages, timings, stats)


def _in_input_frame(mesh: Mesh, frame, colors, tree, own: bool) -> Mesh:
    """The mesh (working frame) in the input's coordinates, with the colour of the nearest
    input point at each vertex when the input has colours; ``own``: its vertices are this
    function's to map in place."""
    vertices_unit = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    out_colors = None
    if colors is not None and len(vertices_unit):
        out_colors = nearest_colors(vertices_unit, colors, tree)
    # a similarity transform leaves unit normals unchanged
    return Mesh(frame.from_unit(vertices_unit, in_place=own),
                np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3),
                None if mesh.normals is None else np.asarray(mesh.normals, np.float64),
                out_colors)


def nearest_colors(vertices_unit: np.ndarray, colors, tree) -> np.ndarray:
    """The colour (float32) of the input point nearest each vertex (working frame; ``tree``:
    the k-d tree of the input points there)."""
    _, nearest = tree.query(vertices_unit, k=1, workers=query_threads())
    return np.asarray(colors, dtype=np.float32)[nearest]


def _drop_outliers(points: np.ndarray, colors, settings: ReconstructSettings,
                   progress: Optional[ProgressFn] = None, cancel: Optional[CancelFn] = None):
    """The points (and colours) without the outliers, as ``settings.outliers`` says.

    Returns ``(points, colors, found, dropped, shrink)``: how many points the test flagged, how
    many of them were dropped (all or none), and how many times dropping them shrinks the
    bounding box's longest side. ``auto`` drops them when they are at least :data:`AUTO_SHARE`
    of the cloud or shrink the box more than :data:`AUTO_SHRINK` times. Refuses, saying why,
    when too few points would be left. ``progress`` and ``cancel`` go to :func:`find_outliers`.
    """
    if settings.outliers == "keep":
        return points, colors, 0, 0, 1.0
    outlier = find_outliers(points, settings.outlier_ratio, progress, cancel)
    found = int(outlier.sum())
    shrink = box_shrink(points, outlier)
    if not found or (settings.outliers == "auto" and found < AUTO_SHARE * len(points)
                     and not shrink > AUTO_SHRINK):
        return points, colors, found, 0, shrink
    kept = points[~outlier]
    try:
        validate_points(kept)
    except InputError as error:
        raise InputError(f"{error} (after dropping {found:,} of {len(points):,} points as "
                         f"outliers; set outliers to 'keep' to use every point)") from None
    return kept, None if colors is None else np.asarray(colors)[~outlier], found, found, shrink


def meshing_settings(settings: ReconstructSettings):
    """The mesher's settings derived from a reconstruction's: seed, small-piece filter, device."""
    from .meshing import MeshingSettings

    return MeshingSettings(seed=settings.seed, min_component_faces=settings.min_component_faces,
                           device=settings.device)


def _share(count: int, total: int, digits: int) -> str:
    """``count`` as a percentage of ``total`` to ``digits`` decimals; a share that would round
    to zero reads "under 0.01 %" (for two digits), never "0.00 %"."""
    share = 100.0 * count / total
    smallest = 10.0 ** -digits
    return f"under {smallest:.{digits}f} %" if share < smallest else f"{share:.{digits}f} %"


def _piece_count(mesh: Mesh) -> int:
    """Connected pieces of a mesh (faces sharing a vertex), 0 for a mesh without faces."""
    from .meshing.mesh_ops import component_count

    return component_count(len(mesh.vertices), mesh.faces)
