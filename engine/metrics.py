"""Surface metrics between a predicted and a ground-truth mesh.

Protocol (``research/evaluation.md`` §1.1, CAP-UDF / LoSF-UDF convention): both meshes are put in
the ground truth's unit frame (bbox centre at 0, longest side 1), each is sampled by area with
face normals, and nearest neighbours are found in both directions with a k-d tree.

* ``cd_l1_x100``: Chamfer L1 = ½(mean pred→gt distance + mean gt→pred distance), times 100.
* ``cd_l2``: ½(mean squared pred→gt distance + mean squared gt→pred distance), unscaled.
* ``f1_<t>``: F-score 2PR/(P+R) at threshold t, with P the share of pred samples within t of a
  gt sample and R the share of gt samples within t of a pred sample (0 when P + R = 0).
* ``nc``: normal consistency, the mean |dot| of each sample's normal with its nearest neighbour's
  normal, averaged over both directions (orientation-agnostic).
* ``double_layer`` / ``gt_double_layer``: the double-layered share of the prediction's (ground
  truth's) area, see :func:`double_layer_share`. CD, F1 and NC cannot see a second sheet lying on
  the first; this can. The ground truth's own share comes from its thin parts.
* ``double_layer_wide`` / ``gt_double_layer_wide``: the same within ``WIDE_LAYERS`` layer
  distances (:func:`wide_double_layer_share`): two layers of one sheet that stalled a few grid
  spacings apart instead of meeting, which the one-spacing measure cannot see.
* ``area_ratio``: prediction area / ground-truth area (a double layer doubles it, holes and
  retracted rims shrink it).
* ``gt_close_sheets``: the share of the ground truth's area with another of its sheets within
  the layer distance, facing either way (:func:`close_sheet_share`): a thin part's two sides, a
  pocket on its cloth.
* ``area_ratio_thin_once``: the area ratio against the ground truth with those close sheets
  counted once, ``gt_area * (1 - gt_close_sheets / 2)``: two sheets closer than the layer
  distance (a car's 8 mm floor pan at 1.7 cm cells, a pocket 3 mm off a shirt) can only come out
  as one from a field sampled that coarsely, and then this is the ratio that reads 1.

The sample count sets a floor: a mesh scored against itself does not get 0 (at 100k samples the
CGAL bunny gives CD-L1 ×10² ≈ 0.24), so always state the count.
"""

from typing import Dict, Sequence

import numpy as np

from .errors import InputError
from .frame import UnitFrame
from .geometry import Mesh
from .sampling import face_areas_and_normals, sample_surface

DEFAULT_THRESHOLDS = (0.005, 0.01)
LAYER_DISTANCE = 1.0 / 256  # unit frame: one grid spacing at the Table I resolution
OPPOSITE_COS = -0.5  # normals more than 120 degrees apart face opposite ways
# Two sheets lie one above the other where normals within 14 degrees (cos > 0.97) are more than
# a quarter of the layer distance apart along them: no crease passes (across a crease that
# gentle a neighbour within the distance lies under sin(14 deg) < 1/4 of it off the plane).
PARALLEL_COS = 0.97
CLOSE_OFFSET = 0.25
_LAYER_DENSITY = 4.0  # samples per layer_distance^2 of area
_LAYER_MAX_SAMPLES = 3_000_000
_LAYER_NEIGHBOURS = 16
WIDE_LAYERS = 4  # the wide double-layer measure looks this many layer distances off each point
_WIDE_NEIGHBOURS = 4
_WIDE_DENSITY = 2.0  # samples per layer_distance^2: about 6 within a layer distance of a probe
_WIDE_PROBES = 100_000  # samples that probe (the share's standard error stays under 0.2 %)


def f1_key(threshold: float) -> str:
    """The result key of the F-score at ``threshold``: ``0.005 -> "f1_0.005"``."""
    return f"f1_{threshold:g}"


def chamfer_f_nc(pred_pts: np.ndarray, pred_normals: np.ndarray,
                 gt_pts: np.ndarray, gt_normals: np.ndarray,
                 thresholds: Sequence[float] = DEFAULT_THRESHOLDS) -> Dict[str, float]:
    """Chamfer distances, F-scores and normal consistency between two point samples.

    Parameters
    ----------
    pred_pts : (N, 3) float array, points on the prediction (N >= 1)
    pred_normals : (N, 3) float array, unit normals of ``pred_pts`` (sign ignored)
    gt_pts : (M, 3) float array, points on the ground truth (M >= 1)
    gt_normals : (M, 3) float array, unit normals of ``gt_pts`` (sign ignored)
    thresholds : distances for the F-scores, in the units of the points

    Returns
    -------
    dict
        ``cd_l1_x100``, ``cd_l2``, one ``f1_<t>`` per threshold (see :func:`f1_key`) and ``nc``,
        all Python floats. Distances are in the units of the points (``cd_l1_x100`` ×100).
    """
    from scipy.spatial import cKDTree

    pred_pts = np.asarray(pred_pts, dtype=np.float64)
    gt_pts = np.asarray(gt_pts, dtype=np.float64)
    pred_normals = np.asarray(pred_normals, dtype=np.float64)
    gt_normals = np.asarray(gt_normals, dtype=np.float64)

    # accuracy: each pred sample to its nearest gt sample; completeness: the other way round
    acc, pred_to_gt = cKDTree(gt_pts).query(pred_pts, k=1, workers=-1)
    comp, gt_to_pred = cKDTree(pred_pts).query(gt_pts, k=1, workers=-1)

    result = {
        "cd_l1_x100": float(0.5 * (acc.mean() + comp.mean()) * 100.0),
        "cd_l2": float(0.5 * (np.mean(acc ** 2) + np.mean(comp ** 2))),
    }
    for t in thresholds:
        precision = float(np.mean(acc <= t))
        recall = float(np.mean(comp <= t))
        total = precision + recall
        result[f1_key(t)] = 2.0 * precision * recall / total if total > 0 else 0.0

    nc_pred = np.abs(np.sum(pred_normals * gt_normals[pred_to_gt], axis=1)).mean()
    nc_gt = np.abs(np.sum(gt_normals * pred_normals[gt_to_pred], axis=1)).mean()
    result["nc"] = float(0.5 * (nc_pred + nc_gt))
    return result


def _surface_area(mesh: Mesh) -> float:
    """Total face area of ``mesh`` (0 for a mesh without faces)."""
    faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    if faces.shape[0] == 0:
        return 0.0
    areas, _ = face_areas_and_normals(mesh.vertices, faces)
    return float(areas.sum())


def double_layer_share(vertices: np.ndarray, faces: np.ndarray,
                       distance: float = LAYER_DISTANCE, seed: int = 0,
                       max_samples: int = _LAYER_MAX_SAMPLES) -> float:
    """The share of a mesh's area that has an opposite-facing sheet within ``distance``.

    A surface point counts as double-layered when the mesh has a point within ``distance`` of it
    whose face normal is more than 120 degrees from its own (``cos < -0.5``): a second,
    opposite-facing layer on top of the first, as DCUDF's two covers are, or the two sides of a
    part thinner than ``distance``. Creases (90 degrees) and curvature do not count.

    The mesh is sampled by area at about 4 points per ``distance^2`` (at most ``max_samples``),
    and each sample looks at its 16 nearest neighbours within ``distance``; the share of the
    samples that find an opposite-facing neighbour is the share of the area. It relies on the
    faces' winding: a mesh with randomly flipped faces reads as double-layered.

    Parameters
    ----------
    vertices : (V, 3) float; faces : (F, 3) int
    distance : the layer distance, in the vertices' units
    seed : seeds the sampling
    max_samples : cap on the sample count (large meshes get a coarser, still unbiased, estimate)

    Returns
    -------
    float in [0, 1] (0 for a mesh without area).
    """
    return _sheet_shares(vertices, faces, distance, seed, max_samples)[0]


def close_sheet_share(vertices: np.ndarray, faces: np.ndarray,
                      distance: float = LAYER_DISTANCE, seed: int = 0,
                      max_samples: int = _LAYER_MAX_SAMPLES) -> float:
    """The share of a mesh's area that has another sheet of it within ``distance``, facing
    either way: double-layered (:func:`double_layer_share`), or with a neighbour whose normal
    is within 14 degrees of its own (``cos > 0.97``) lying more than ``distance / 4`` off its
    tangent plane (a pocket or a hem band on its cloth). Creases and curvature do not count.
    Sampled as :func:`double_layer_share` is, with the same samples for the same seed."""
    return _sheet_shares(vertices, faces, distance, seed, max_samples)[1]


def _layer_samples(vertices, faces, distance, seed, max_samples, density=_LAYER_DENSITY):
    """Area-weighted samples (points, normals, count), ``density`` per ``distance^2``; count 0
    for a mesh without area."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0 or not distance > 0:
        return None, None, 0
    areas, _ = face_areas_and_normals(vertices, faces)
    total = float(areas.sum())
    if not np.isfinite(total) or total <= 0:
        return None, None, 0
    count = int(min(max_samples, max(1000, density * total / distance ** 2)))
    points, normals, _ = sample_surface(vertices, faces, count, np.random.default_rng([seed, 2]))
    return points, normals, count


def _sheet_shares(vertices, faces, distance, seed, max_samples):
    """(double-layered share, close-sheet share) of a mesh's area."""
    from scipy.spatial import cKDTree

    points, normals, count = _layer_samples(vertices, faces, distance, seed, max_samples)
    if count == 0:
        return 0.0, 0.0
    tree = cKDTree(points)
    k = min(_LAYER_NEIGHBOURS, count)
    double = np.zeros(count, bool)
    close = np.zeros(count, bool)
    for start in range(0, count, 200_000):
        stop = min(start + 200_000, count)
        _, idx = tree.query(points[start:stop], k=k, distance_upper_bound=distance, workers=-1)
        idx = idx.reshape(stop - start, k)
        valid = idx < count
        safe = np.where(valid, idx, 0)
        cos = np.einsum("qkc,qc->qk", normals[safe], normals[start:stop])
        off = np.abs(np.einsum("qkc,qc->qk", points[safe] - points[start:stop, None],
                               normals[start:stop]))
        double[start:stop] = (valid & (cos < OPPOSITE_COS)).any(axis=1)
        parallel = valid & (cos > PARALLEL_COS) & (off > CLOSE_OFFSET * distance)
        close[start:stop] = double[start:stop] | parallel.any(axis=1)
    return float(double.mean()), float(close.mean())


def wide_double_layer_share(vertices: np.ndarray, faces: np.ndarray,
                            distance: float = LAYER_DISTANCE, layers: int = WIDE_LAYERS,
                            seed: int = 0, max_samples: int = _LAYER_MAX_SAMPLES) -> float:
    """The share of a mesh's area with an opposite-facing sheet along its normal line within
    ``layers * distance``, either side.

    :func:`double_layer_share` looks ``distance`` (one grid spacing) around each point: two
    layers of one sheet that stalled 2-4 spacings apart, on either side of the surface, pass it
    unseen. Here the mesh is sampled by area (2 per ``distance^2``), and up to 100 000 of the
    samples probe their normal lines at every multiple of ``distance`` up to ``layers`` of them,
    both ways; a sample counts as double-layered when a sample within ``distance`` of one of its
    probes faces the other way (``cos < -0.5``). The two sides of a part thinner than
    ``layers * distance`` count too: the ground truth's share says how much.

    Returns a float in [0, 1] (0 for a mesh without area).
    """
    from scipy.spatial import cKDTree

    points, normals, count = _layer_samples(vertices, faces, distance, seed, max_samples,
                                            _WIDE_DENSITY)
    if count == 0:
        return 0.0
    tree = cKDTree(points)
    k = min(_WIDE_NEIGHBOURS, count)
    probes = min(count, _WIDE_PROBES)  # the samples are drawn independently: a prefix will do
    p, n = points[:probes], normals[:probes]
    double = np.zeros(probes, bool)
    steps = distance * np.arange(1, layers + 1)
    for step in np.concatenate([steps, -steps]):
        _, idx = tree.query(p + step * n, k=k, distance_upper_bound=distance, workers=-1)
        idx = idx.reshape(probes, k)
        valid = idx < count
        cos = np.einsum("qkc,qc->qk", normals[np.where(valid, idx, 0)], n)
        double |= (valid & (cos < OPPOSITE_COS)).any(axis=1)
    return float(double.mean())


def layer_scores(pred_vertices: np.ndarray, pred_faces: np.ndarray, gt_vertices: np.ndarray,
                 gt_faces: np.ndarray, distance: float = LAYER_DISTANCE,
                 seed: int = 0) -> Dict[str, float]:
    """``double_layer``, ``gt_double_layer``, ``double_layer_wide``, ``gt_double_layer_wide``,
    ``gt_close_sheets``, ``area_ratio`` and ``area_ratio_thin_once`` of a prediction (same
    units; see the module docstring)."""
    pred_area = _surface_area(Mesh(pred_vertices, pred_faces))
    truth = _truth_terms(gt_vertices, gt_faces, distance, seed)
    gt_area = truth["gt_area"]
    thin_once = gt_area * (1.0 - truth["gt_close_sheets"] / 2)
    return {"double_layer": double_layer_share(pred_vertices, pred_faces, distance, seed),
            "gt_double_layer": truth["gt_double_layer"],
            "gt_close_sheets": truth["gt_close_sheets"],
            "double_layer_wide": wide_double_layer_share(pred_vertices, pred_faces, distance,
                                                         seed=seed),
            "gt_double_layer_wide": truth["gt_double_layer_wide"],
            "area_ratio": pred_area / gt_area if gt_area > 0 else float("nan"),
            "area_ratio_thin_once": pred_area / thin_once if thin_once > 0 else float("nan")}


_TRUTH_TERMS: Dict[tuple, Dict[str, float]] = {}  # the last few truths' terms, by content


def _truth_terms(gt_vertices: np.ndarray, gt_faces: np.ndarray, distance: float,
                 seed: int) -> Dict[str, float]:
    """The ground truth's own terms of :func:`layer_scores` (its area, double-layered, close-sheet
    and wide double-layered shares), computed once per truth: a benchmark scores several
    methods against the same one."""
    import hashlib

    vertices = np.ascontiguousarray(gt_vertices, dtype=np.float64)
    faces = np.ascontiguousarray(gt_faces, dtype=np.int64).reshape(-1, 3)
    digest = hashlib.blake2b(vertices.tobytes(), digest_size=20)
    digest.update(faces.tobytes())
    key = (digest.hexdigest(), len(vertices), float(distance), int(seed))
    if key not in _TRUTH_TERMS:
        while len(_TRUTH_TERMS) >= 8:
            del _TRUTH_TERMS[next(iter(_TRUTH_TERMS))]
        gt_double, gt_close = _sheet_shares(vertices, faces, distance, seed, _LAYER_MAX_SAMPLES)
        _TRUTH_TERMS[key] = {
            "gt_area": _surface_area(Mesh(vertices, faces)), "gt_double_layer": gt_double,
            "gt_close_sheets": gt_close,
            "gt_double_layer_wide": wide_double_layer_share(vertices, faces, distance,
                                                            seed=seed)}
    return _TRUTH_TERMS[key]


def evaluate(pred: Mesh, gt: Mesh, samples: int = 100_000, seed: int = 0,
             frame=None, layer_distance: float = LAYER_DISTANCE) -> Dict[str, object]:
    """Score a predicted mesh against a ground-truth mesh.

    Parameters
    ----------
    pred : Mesh, the reconstruction (may have no faces: scored as the worst result)
    gt : Mesh, the ground truth, with at least one face of non-zero area
    samples : number of area-weighted surface samples drawn on each mesh
    seed : seed of the sampling; pred and gt draw from separate streams
        ``default_rng([seed, 0])`` and ``default_rng([seed, 1])``
    frame : UnitFrame or None
        Frame both meshes are scored in; None uses the ground truth's vertices' frame
        (bbox centred at 0, longest side 1).
    layer_distance : distance (unit frame) within which an opposite-facing sheet makes a point
        double-layered (:func:`double_layer_share`); default one grid spacing at 256.

    Returns
    -------
    dict
        ``cd_l1_x100``, ``cd_l2``, ``f1_0.005``, ``f1_0.01``, ``nc`` (floats, distances in the unit
        frame), ``double_layer``, ``gt_double_layer``, ``double_layer_wide``,
        ``gt_double_layer_wide``, ``gt_close_sheets``, ``area_ratio`` and
        ``area_ratio_thin_once`` (:func:`layer_scores`),
        ``empty`` (bool, True when the prediction has no surface to sample; then the
        Chamfer distances are inf and F-scores and NC 0), ``samples`` (int, the count per mesh)
        and ``pred_faces`` (int).

    Raises
    ------
    InputError
        If the ground truth has no face of non-zero area or ``samples`` < 1.
    """
    if samples < 1:
        raise InputError(f"the sample count must be at least 1, got {samples}")
    if _surface_area(gt) <= 0:
        raise InputError("the ground-truth mesh has no faces with area; cannot score against it")
    if frame is None:  # 3 distinct points: a single triangle is a valid ground truth
        frame = UnitFrame.from_points(np.asarray(gt.vertices, dtype=np.float64), min_points=3)

    pred_faces = int(np.asarray(pred.faces).reshape(-1, 3).shape[0])
    info = {"empty": False, "samples": int(samples), "pred_faces": pred_faces}
    if _surface_area(pred) <= 0:
        worst = {"cd_l1_x100": float("inf"), "cd_l2": float("inf")}
        worst.update({f1_key(t): 0.0 for t in DEFAULT_THRESHOLDS})
        worst["nc"] = 0.0
        gt_unit = frame.to_unit(np.asarray(gt.vertices, dtype=np.float64))
        truth = _truth_terms(gt_unit, gt.faces, layer_distance, seed)
        worst.update({"double_layer": 0.0, "area_ratio": 0.0, "area_ratio_thin_once": 0.0,
                      "gt_double_layer": truth["gt_double_layer"],
                      "gt_close_sheets": truth["gt_close_sheets"], "double_layer_wide": 0.0,
                      "gt_double_layer_wide": truth["gt_double_layer_wide"]})
        return {**worst, **info, "empty": True}

    gt_vertices = frame.to_unit(np.asarray(gt.vertices, dtype=np.float64))
    pred_vertices = frame.to_unit(np.asarray(pred.vertices, dtype=np.float64))
    gt_pts, gt_normals, _ = sample_surface(gt_vertices, gt.faces, samples,
                                           np.random.default_rng([seed, 1]))
    pred_pts, pred_normals, _ = sample_surface(pred_vertices, pred.faces, samples,
                                               np.random.default_rng([seed, 0]))
    scores = chamfer_f_nc(pred_pts, pred_normals, gt_pts, gt_normals, DEFAULT_THRESHOLDS)
    scores.update(layer_scores(pred_vertices, pred.faces, gt_vertices, gt.faces, layer_distance,
                               seed))
    return {**scores, **info}
