"""Training data for the radius selector: per-query parent-patch features and the frozen
backbone's UDF error at each candidate radius (the errors cached on disk one file per shape,
resumable).

Shapes come from the benchmark's *training* seeds (disjoint from its test seeds by
construction). Each shape is scanned under one of the clean / sparse / noisy conditions (chosen
by its seed), so the selector sees the densities and noise where the radius matters most; a few
more are scanned densely (``dense_conditions``), clean or noisy, because a virtual room scan
is that dense near its scanner and a selector that never saw a dense noisy patch reads one as
clean (engine/weights/SELECTOR_CARD.md).
Queries are drawn uniformly within ``QUERY_BAND`` of random input points: the grid nodes where
the field calls the network (``NETWORK_BAND_NODES`` spacings at the default resolution 256).
Farther nodes keep the nearest-point distance whatever the radius, so they teach nothing.
"""

import hashlib
from dataclasses import replace
from pathlib import Path
from typing import Callable, Dict, Optional

import numpy as np

from engine.field import NETWORK_BAND_NODES, predict_trimmed
from engine.frame import UnitFrame
from engine.patches import MAX_POINTS, gather_patches
from engine.selector import parent_features
from engine.settings import ReconstructSettings
from ..bench.dataset import CONDITIONS, ScanCondition, make_input, make_shape
from .mesh_distance import point_mesh_distance

TRAINING_CONDITIONS = ("clean", "sparse", "noisy")
DENSE_POINTS = 150_000  # 3x the benchmark's clean and noisy scans
QUERY_BAND = NETWORK_BAND_NODES / ReconstructSettings().resolution
Predictor = Callable[[np.ndarray, np.ndarray], np.ndarray]


def band_queries(points: np.ndarray, count: int, radius: float,
                 rng: np.random.Generator) -> np.ndarray:
    """``count`` points uniform in volume within ``radius`` of random input points; (count, 3)."""
    centres = points[rng.integers(0, len(points), count)]
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return centres + direction * (radius * rng.random(count) ** (1 / 3))[:, None]


def backbone_udf(predict: Predictor, tree, points: np.ndarray, queries: np.ndarray,
                 radii: np.ndarray) -> np.ndarray:
    """The field's UDF at ``queries`` with per-query ``radii``: backbone where the ball holds
    points, the nearest-point distance where it is empty (as :mod:`engine.field` does)."""
    radii = np.broadcast_to(np.asarray(radii, dtype=np.float64), (len(queries),))
    values = tree.query(queries, workers=-1)[0]
    rel, mask, counts = gather_patches(tree, points, queries, radii, MAX_POINTS)
    filled = np.flatnonzero(counts > 0)
    values[filled] = predict_trimmed(predict, rel[filled], mask[filled], counts[filled],
                                     1024) * radii[filled]
    return values


def dense_conditions(points: int = DENSE_POINTS) -> Dict[str, ScanCondition]:
    """The clean and the noisy scan condition, by name, with ``points`` points instead of 50 000."""
    return {name: replace(CONDITIONS[name], name=f"dense-{name}", count=points)
            for name in ("clean", "noisy")}


def condition_of(seed: int) -> int:
    """Index in TRAINING_CONDITIONS of the condition a training shape is scanned under."""
    return seed % len(TRAINING_CONDITIONS)


def shape_scene(domain: str, seed: int, queries: int, query_seed: int,
                condition: Optional[ScanCondition] = None) -> Dict[str, np.ndarray]:
    """One training shape scanned and framed as at inference, with queries and exact UDF.

    Scanned under ``condition``, or by default the training condition its seed picks."""
    from scipy.spatial import cKDTree

    gt = make_shape(domain, seed)
    condition = condition or CONDITIONS[TRAINING_CONDITIONS[condition_of(seed)]]
    cloud = make_input(gt, domain, condition, seed)
    frame = UnitFrame.from_points(cloud.points)
    points = frame.to_unit(cloud.points)
    rng = np.random.default_rng([query_seed, seed, 11])
    q = band_queries(points, queries, QUERY_BAND, rng)
    udf = point_mesh_distance(frame.to_unit(gt.vertices), gt.faces, q, rng)
    return {"points": points, "queries": q, "udf": udf, "tree": cKDTree(points),
            "condition": condition.name}


def shape_cache(domain: str, seed: int, predict: Predictor, queries: int, parent_radius: float,
                radii: np.ndarray, cache_dir: Path, query_seed: int = 0,
                condition: Optional[ScanCondition] = None) -> Dict[str, np.ndarray]:
    """Selector inputs and error curves at the candidate ``radii`` for one shape (scanned as
    :func:`shape_scene` says).

    The error curves (the backbone run once per radius: the costly part) are read from
    ``cache_dir`` when present and written there otherwise; the selector's inputs are computed
    afresh from the regenerated scene, so a change of features needs no new error curves.

    Returns ``rel``, ``mask``, ``extra`` (:func:`engine.selector.parent_features`), ``errors``
    (Q, K), ``udf`` (Q,) and ``queries`` (Q, 3, unit frame).
    """
    scene = shape_scene(domain, seed, queries, query_seed, condition)
    scan = "" if condition is None else f"_{condition.name}{condition.count}"
    radii = np.asarray(radii, dtype=np.float64)
    grid = (f"_r{radii[0]:.4f}-{radii[-1]:.4f}x{len(radii)}_"
            f"{hashlib.sha256(np.round(radii, 9).tobytes()).hexdigest()[:6]}")
    path = (Path(cache_dir)
            / f"{domain}_{seed}_{queries}_{query_seed}_band{QUERY_BAND:.4f}{scan}{grid}.npz")
    if path.exists():
        with np.load(path) as data:
            errors = data["errors"]
    else:
        errors = np.stack([np.abs(backbone_udf(predict, scene["tree"], scene["points"],
                                               scene["queries"], r) - scene["udf"])
                           for r in radii], axis=1).astype(np.float32)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.stem + ".tmp.npz")
        np.savez(tmp, errors=errors, udf=scene["udf"].astype(np.float32))
        tmp.replace(path)
    rel, mask, extra = parent_features(scene["tree"], scene["points"], scene["queries"],
                                       parent_radius)
    return {"rel": rel, "mask": mask, "extra": extra, "errors": errors,
            "udf": scene["udf"].astype(np.float32), "queries": scene["queries"]}
