"""How much of the radius headroom the selector's parent-patch features carry: a lookup table.

    python -m lab.training.radius_lookup --fit out/radius_curves/heldout_raw.npz \
        --score out/radius_curves/test_raw.npz --out bench_results/radius_curves/lookup.json

Both inputs are ``--raw`` files of :mod:`.radius_curves` (per-query error curves over the same
radii). For every query the selector's three scalar parent-patch features at the parent radius
``--parent-radius`` are recomputed (:func:`engine.selector.parent_features`: the point count,
the thickness and the quadric residual; the scenes are regenerated from their seeds, as
``radius_curves`` made them). The features are cut into quantile bins on the fitting queries
(``--bins`` per feature), each cell gets the radius with the lowest mean error there (cells with
fewer than ``--min-cell`` fitting queries the overall best), and the table is scored on the other
file's queries. Fitted on cars and garments only (``--fit-domains``), as the selector is trained,
so rooms stay unseen. The score is out of sample: a floor on what a selector reading these
features can do, where the oracles of ``radius_curves`` are ceilings.
"""

import argparse
import json
import time
from pathlib import Path
from typing import Dict, Sequence

import numpy as np

from .radius_curves import SCALE

FEATURES = ("count", "thickness", "residual")


def scene_features(domain: str, condition: str, seeds: Sequence[int], queries: np.ndarray,
                   per_shape: int, query_seed: int, parent_radius: float) -> np.ndarray:
    """(Q, 3) count, thickness, residual of each query's parent patch, shape by shape."""
    from scipy.spatial import cKDTree

    from engine.frame import UnitFrame
    from engine.selector import parent_features
    from ..bench.dataset import CONDITIONS, make_input, make_shape
    from .selector_data import QUERY_BAND, band_queries

    out = []
    for i, seed in enumerate(seeds):
        gt = make_shape(domain, int(seed))
        cloud = make_input(gt, domain, CONDITIONS[condition], int(seed))
        points = UnitFrame.from_points(cloud.points).to_unit(cloud.points)
        rng = np.random.default_rng([query_seed, int(seed), 21])
        q = band_queries(points, per_shape, QUERY_BAND, rng)
        if not np.array_equal(q, queries[i * per_shape:(i + 1) * per_shape]):
            raise ValueError(f"{domain} {condition} {seed}: regenerated queries differ")
        _, _, extra = parent_features(cKDTree(points), points, q, parent_radius)
        out.append(extra[:, [0, -2, -1]])
    return np.concatenate(out)


def load(path: str, domains, conditions, query_seed: int, parent_radius: float
         ) -> Dict[str, Dict[str, np.ndarray]]:
    with np.load(path) as data:
        raw = {k: data[k] for k in data.files}
    cells = {}
    for domain in domains:
        for condition in conditions:
            key = f"{domain}/{condition}/"
            seeds = raw[key + "seeds"]
            errors = raw[key + "errors"]
            features = scene_features(domain, condition, seeds, raw[key + "queries"],
                                      len(errors) // len(seeds), query_seed, parent_radius)
            cells[f"{domain}/{condition}"] = {"errors": errors, "features": features}
    return {"radii": raw["radii"], "cells": cells}


def cell_index(features: np.ndarray, edges) -> np.ndarray:
    index = np.zeros(len(features), dtype=np.int64)
    for j, e in enumerate(edges):
        index = index * (len(e) + 1) + np.searchsorted(e, features[:, j], side="right")
    return index


def fit_table(errors: np.ndarray, features: np.ndarray, bins: int, min_cell: int):
    """Quantile edges per feature and the best grid index per cell (fallback: overall best)."""
    edges = [np.unique(np.quantile(features[:, j], np.linspace(0, 1, bins + 1)[1:-1]))
             for j in range(features.shape[1])]
    index = cell_index(features, edges)
    overall = int(np.argmin(errors.mean(axis=0)))
    size = int(np.prod([len(e) + 1 for e in edges]))
    choice = np.full(size, overall)
    for c in np.unique(index):
        rows = index == c
        if rows.sum() >= min_cell:
            choice[c] = int(np.argmin(errors[rows].mean(axis=0)))
    return edges, choice


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fit", required=True, help="radius_curves --raw file to fit on")
    parser.add_argument("--score", required=True, help="radius_curves --raw file to score on")
    parser.add_argument("--out", default="bench_results/radius_curves/lookup.json")
    parser.add_argument("--fit-domains", nargs="+", default=["cars", "garments"])
    parser.add_argument("--domains", nargs="+", default=["cars", "garments", "rooms"])
    parser.add_argument("--conditions", nargs="+", default=["clean", "sparse", "noisy"])
    parser.add_argument("--parent-radius", type=float, default=0.024)
    parser.add_argument("--bins", type=int, default=4, help="quantile bins per feature")
    parser.add_argument("--min-cell", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0, help="the query seed of both files")
    args = parser.parse_args(argv)
    from threadpoolctl import threadpool_limits

    started = time.time()
    with threadpool_limits(1):
        fit = load(args.fit, args.fit_domains, args.conditions, args.seed, args.parent_radius)
        score = load(args.score, args.domains, args.conditions, args.seed, args.parent_radius)
    radii = [float(r) for r in score["radii"]]
    if not np.allclose(fit["radii"], radii):
        raise ValueError("the two files hold different radii")
    errors = np.concatenate([c["errors"] for c in fit["cells"].values()])
    features = np.concatenate([c["features"] for c in fit["cells"].values()])
    edges, choice = fit_table(errors, features, args.bins, args.min_cell)
    results = {"args": vars(args), "radii": radii, "features": list(FEATURES),
               "edges": [e.tolist() for e in edges],
               "table_radii": [radii[i] for i in choice], "scores": {}}
    for domain in args.domains:
        parts = {c: score["cells"][f"{domain}/{c}"] for c in args.conditions}
        rows = {}
        for name, cells in [(c, [parts[c]]) for c in args.conditions] + \
                [("all conditions", list(parts.values()))]:
            e = np.concatenate([c["errors"] for c in cells])
            picked = choice[cell_index(np.concatenate([c["features"] for c in cells]), edges)]
            mean = e.mean(axis=0) * SCALE
            best = int(np.argmin(mean))
            lookup = float(e[np.arange(len(e)), picked].mean() * SCALE)
            rows[name] = {"best_fixed_radius": radii[best],
                          "best_fixed": round(float(mean[best]), 4),
                          "lookup": round(lookup, 4),
                          "lookup_gain": round(1.0 - lookup / float(mean[best]), 4),
                          "lookup_mean_radius": round(float(np.mean(np.asarray(radii)[picked])),
                                                      5)}
            print(domain, name, json.dumps(rows[name]), flush=True)
        results["scores"][domain] = rows
    results["seconds"] = round(time.time() - started, 1)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(results, indent=1))
    print(f"wrote {args.out} in {results['seconds']} s")


if __name__ == "__main__":
    main()
