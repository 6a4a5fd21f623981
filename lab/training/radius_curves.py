"""The frozen backbone's UDF error against the ball radius, per domain, condition and patch type.

    python -m lab.training.radius_curves --out bench_results/radius_curves/curves.json
        [--shapes 10] [--queries 3000] [--seed 0] [--split test] [--threads 1]
    python -m lab.training.radius_curves --tables bench_results/radius_curves/curves.json

For ``--shapes`` shapes of each domain (cars, garments, rooms), each scanned under each of the
clean, sparse and noisy conditions (``lab.bench.dataset.CONDITIONS``), ``--queries`` queries
uniform within ``QUERY_BAND`` (3 grid spacings at resolution 256) of random input points: the
grid nodes where the field calls the network, as the selector's training data has them
(:mod:`.selector_data`). At every radius of ``--radii`` the field's UDF is taken as the
selector's data takes it (:func:`.selector_data.backbone_udf`: the backbone on the up to 64
nearest points in the ball, the nearest-point distance where the ball is empty; no widening of
sparse balls) and compared with the exact distance to the ground-truth mesh
(:func:`.mesh_distance.point_mesh_distance`).

Each query also gets a patch type from the ground-truth mesh (:func:`patch_types`): a second
sheet near it (another part of the surface, facing the same or the opposite way, within 0.012,
0.012-0.024 or 0.024-0.048 of the query), a crease or strongly curved spot, a ball of few input
points, or none of these ("smooth"). The noisy patches are the noisy condition's.

Reported per domain x condition (and per patch type within it, and per domain over all three
conditions): the mean absolute UDF error at each radius; the best fixed radius (lowest mean) and
its error; the error at 0.018 (LoSF-UDF's radius) and 0.024 (today's parent radius); the oracle
(each query at its own best grid radius); the *local* oracle (each query at the best radius of
the mean curve of its 64 nearest other queries on the same shape: what a selector that reads the
neighbourhood could at best know, since one query's own best radius is mostly the luck of how
its points fall); the *type* oracle (each patch type at its own best fixed radius); over all
three conditions of a domain also the *condition* oracle (each condition at its own best fixed
radius) and the *density* oracle (each of 8 bins of the 64th nearest point's distance at its
own best radius); and the distance to the 64th nearest input point (beyond it a larger ball
adds no point to the backbone's patch; it only shrinks the patch inside the unit ball).

``--split test`` evaluates on the benchmark's test seeds (never trained on); ``--split heldout``
on training seeds 40, 41, ... (the selector's held-out shapes, never trained on either).
"""

import argparse
import json
import platform
import time
from pathlib import Path
from typing import Dict, Optional, Sequence

import numpy as np

RADII = (0.008, 0.010, 0.012, 0.015, 0.018, 0.021, 0.024, 0.030, 0.036, 0.042, 0.048, 0.060,
         0.072, 0.096)
DOMAINS = ("cars", "garments", "rooms")
EVAL_CONDITIONS = ("clean", "sparse", "noisy")
PATCH_TYPES = ("sheet < 0.012", "sheet 0.012-0.024", "sheet 0.024-0.048", "crease",
               "few points", "smooth")
SHEET_BINS = (0.012, 0.024, 0.048)  # a second sheet within these distances of the query
CREASE_REACH = 0.012  # surface within this of the query's foot point ...
CREASE_COS = np.cos(np.radians(30.0))  # ... turning by more than 30 degrees: a crease
FEW_POINTS = 10  # at most this many input points within FEW_RADIUS: a "few points" ball
FEW_RADIUS = 0.024
LOCAL_NEIGHBOURS = 64
DENSITY_BINS = 8
SCALE = 1e4  # errors are reported x 10^4 (unit frame)


def patch_types(vertices: np.ndarray, faces: np.ndarray, queries: np.ndarray,
                point_tree, rng: np.random.Generator, samples: int = 200_000) -> Dict:
    """Each query's patch type (index into PATCH_TYPES), from the ground-truth mesh.

    With dense area-uniform samples of the mesh (each with its face's normal): the query's foot
    is its nearest sample, with normal n. A sample belongs to a *second sheet* when its normal is
    within 37 degrees of +-n and it lies off the foot's tangent plane by more than half its
    distance along it plus 0.002 (a smooth sheet curving away with its normal still that close
    to n stays below that); the second-sheet distance is the nearest such sample's distance
    from the query. A *crease* is a foot with surface within ``CREASE_REACH`` whose normal turns
    by more than 30 degrees (a crease, a corner, or a radius of curvature below about 0.023).
    The first that applies wins: second sheet (by distance bin), crease, few input points
    (at most ``FEW_POINTS`` within ``FEW_RADIUS``), smooth.

    Returns ``type`` (Q,) int, ``sheet_distance`` (Q,) float (inf where none within 0.048),
    ``crease`` (Q,) bool, ``points_in_ball`` (Q,) int (input points within ``FEW_RADIUS``).
    """
    from scipy.spatial import cKDTree

    from engine.sampling import sample_surface

    dense, normals, _ = sample_surface(vertices, faces, samples, rng)
    tree = cKDTree(dense)
    _, foot_index = tree.query(queries)
    foot, n0 = dense[foot_index], normals[foot_index]
    lists = tree.query_ball_point(queries, SHEET_BINS[-1])
    lengths = np.fromiter((len(x) for x in lists), dtype=np.int64, count=len(lists))
    which = np.repeat(np.arange(len(queries)), lengths)
    flat = np.fromiter((i for x in lists for i in x), dtype=np.int64, count=int(lengths.sum()))
    d = dense[flat] - foot[which]
    off = np.abs(np.einsum("ij,ij->i", d, n0[which]))
    along = np.sqrt(np.maximum(np.einsum("ij,ij->i", d, d) - off ** 2, 0.0))
    parallel = np.abs(np.einsum("ij,ij->i", normals[flat], n0[which]))
    second = (parallel > 0.8) & (off > 0.5 * along + 0.002)
    sheet_distance = np.full(len(queries), np.inf)
    np.minimum.at(sheet_distance, which[second],
                  np.linalg.norm(dense[flat[second]] - queries[which[second]], axis=1))
    turns = (~second) & (np.sqrt(off ** 2 + along ** 2) < CREASE_REACH) & (parallel < CREASE_COS)
    crease = np.bincount(which[turns], minlength=len(queries)) > 0
    in_ball = point_tree.query_ball_point(queries, FEW_RADIUS, return_length=True)
    kind = np.full(len(queries), PATCH_TYPES.index("smooth"))
    kind[in_ball <= FEW_POINTS] = PATCH_TYPES.index("few points")
    kind[crease] = PATCH_TYPES.index("crease")
    for i in reversed(range(len(SHEET_BINS))):  # nearest bin last: it wins
        kind[sheet_distance < SHEET_BINS[i]] = i
    return {"type": kind, "sheet_distance": sheet_distance, "crease": crease,
            "points_in_ball": np.asarray(in_ball)}


def error_curves(predict, tree, points: np.ndarray, queries: np.ndarray, udf: np.ndarray,
                 radii: Sequence[float]) -> np.ndarray:
    """|field UDF - exact UDF| of each query at each radius; (Q, K) float64."""
    from .selector_data import backbone_udf

    return np.stack([np.abs(backbone_udf(predict, tree, points, queries, r) - udf)
                     for r in radii], axis=1)


def local_choice(errors: np.ndarray, queries: np.ndarray,
                 neighbours: int = LOCAL_NEIGHBOURS) -> np.ndarray:
    """Per query, the grid index of the lowest mean error over its ``neighbours`` nearest
    *other* queries (one shape's queries only): the query's own error does not vote, so the
    choice is not fitted to the luck of its own points."""
    from scipy.spatial import cKDTree

    errors = np.asarray(errors, dtype=np.float64)
    k = min(int(neighbours) + 1, len(errors))
    if k < 2:
        return np.argmin(errors, axis=1)
    _, nearest = cKDTree(queries).query(queries, k=k)
    others = np.where(nearest[:, :1] == np.arange(len(errors))[:, None], nearest[:, 1:],
                      nearest[:, :-1])  # drop the query itself (first, bar exact ties)
    return np.argmin(errors[others].mean(axis=1), axis=1)


def summarise(errors: np.ndarray, radii: Sequence[float], local: Optional[np.ndarray] = None,
              groups: Optional[np.ndarray] = None) -> Dict:
    """Mean error per radius (x 10^4), best fixed radius, errors at 0.018 and 0.024, the oracles.

    ``errors`` (Q, K) per query and radius; ``local`` (Q,) grid index each query's local
    oracle picks (optional); ``groups`` (Q,) int, e.g. the patch type: the *type oracle* gives
    each group its own best fixed radius (chosen on the same queries; optional)."""
    radii = [float(r) for r in radii]
    mean = errors.mean(axis=0) * SCALE
    best = int(np.argmin(mean))
    out = {"queries": int(len(errors)),
           "curve": [round(float(m), 4) for m in mean],
           "best_fixed_radius": radii[best],
           "best_fixed": round(float(mean[best]), 4),
           "oracle": round(float(errors.min(axis=1).mean() * SCALE), 4)}
    for r in (0.018, 0.024):
        if r in radii:
            out[f"at_{r:.3f}"] = round(float(mean[radii.index(r)]), 4)
    old = [i for i, r in enumerate(radii) if 0.012 - 1e-9 <= r <= 0.024 + 1e-9]
    if old:
        out["oracle_0.012_0.024"] = round(float(errors[:, old].min(axis=1).mean() * SCALE), 4)
    if local is not None:
        out["local_oracle"] = round(float(errors[np.arange(len(errors)), local].mean() * SCALE), 4)
    if groups is not None:
        total = sum(errors[groups == g].mean(axis=0).min() * np.sum(groups == g)
                    for g in np.unique(groups))
        out["type_oracle"] = round(float(total / len(errors) * SCALE), 4)
        out["type_oracle_gain"] = round(1.0 - out["type_oracle"] / out["best_fixed"], 4)
    out["oracle_gain"] = round(1.0 - out["oracle"] / out["best_fixed"], 4)
    if local is not None:
        out["local_oracle_gain"] = round(1.0 - out["local_oracle"] / out["best_fixed"], 4)
    return out


def measure_shape(domain: str, seed: int, condition: str, queries: int, query_seed: int,
                  predict, radii: Sequence[float]) -> Dict[str, np.ndarray]:
    """One shape under one condition: queries, error curves, patch types, 64th-point distance."""
    from scipy.spatial import cKDTree

    from engine.frame import UnitFrame
    from ..bench.dataset import CONDITIONS, make_input, make_shape
    from .mesh_distance import point_mesh_distance
    from .selector_data import QUERY_BAND, band_queries

    gt = make_shape(domain, seed)
    cloud = make_input(gt, domain, CONDITIONS[condition], seed)
    frame = UnitFrame.from_points(cloud.points)
    points = frame.to_unit(cloud.points)
    vertices = frame.to_unit(gt.vertices)
    tree = cKDTree(points)
    rng = np.random.default_rng([query_seed, seed, 21])
    q = band_queries(points, queries, QUERY_BAND, rng)
    udf = point_mesh_distance(vertices, gt.faces, q, rng)
    errors = error_curves(predict, tree, points, q, udf, radii)
    types = patch_types(vertices, gt.faces, q, tree, rng)
    d64 = tree.query(q, k=64)[0][:, -1]
    return {"queries": q, "udf": udf, "errors": errors, "local": local_choice(errors, q),
            "d64": d64, **types}


def seeds_for(split: str, domain: str, count: int):
    from ..bench.dataset import test_seeds, train_seeds

    if split == "test":
        return test_seeds(domain, count)
    first = 40  # past the selector's 40 training shapes per domain
    return train_seeds(domain, first + count)[first:]


def run(domains, conditions, shapes: int, queries: int, seed: int, split: str,
        radii: Sequence[float], log=print, raw: Optional[Dict] = None) -> Dict:
    """Measure every domain x condition; returns the JSON-ready results (and fills ``raw``, if
    given, with the per-query arrays under "domain/condition/name")."""
    from engine.field import backbone_predictor

    predict = backbone_predictor("cpu")
    radii = [float(r) for r in radii]
    raw = {} if raw is None else raw
    for domain in domains:
        for condition in conditions:
            parts = []
            seeds = seeds_for(split, domain, shapes)
            for s in seeds:
                started = time.time()
                parts.append(measure_shape(domain, s, condition, queries, seed, predict, radii))
                log(f"{domain} {condition} seed {s}: {time.time() - started:.1f} s", flush=True)
            raw.update({f"{domain}/{condition}/{k}": np.concatenate([p[k] for p in parts])
                        for k in parts[0]})
            raw[f"{domain}/{condition}/seeds"] = np.asarray(seeds)
    raw["radii"] = np.asarray(radii)
    return summarise_raw(raw, domains, conditions)


def summarise_raw(raw: Dict[str, np.ndarray], domains, conditions) -> Dict:
    """The results file's numbers from the per-query arrays of :func:`run`."""
    radii = [float(r) for r in raw["radii"]]
    results = {"radii": radii, "patch_types": list(PATCH_TYPES), "domains": {}}
    pooled_types = {c: [] for c in conditions}
    for domain in domains:
        per_domain = {}
        shapes_all = []
        for condition in conditions:
            prefix = f"{domain}/{condition}/"
            data = {k[len(prefix):]: v for k, v in raw.items() if k.startswith(prefix)}
            shapes_all.append(data)
            pooled_types[condition].append(data)
            entry = summarise(data["errors"], radii, data["local"], groups=data["type"])
            entry["seeds"] = [int(s) for s in data["seeds"]]
            entry["median_64th_point_distance"] = round(float(np.median(data["d64"])), 5)
            entry["share_few_points"] = round(float(np.mean(data["points_in_ball"]
                                                            <= FEW_POINTS)), 4)
            entry["by_patch_type"] = by_type(data, radii)
            per_domain[condition] = entry
        keys = ("errors", "local", "type", "d64")
        data = {k: np.concatenate([p[k] for p in shapes_all]) for k in keys}
        condition_index = np.concatenate([np.full(len(p["errors"]), i)
                                          for i, p in enumerate(shapes_all)])
        pooled = summarise(data["errors"], radii, data["local"],
                           groups=condition_index * len(PATCH_TYPES) + data["type"])
        # the best fixed radius of each condition, each on its own queries: a selector that
        # knew the scan condition and nothing else
        pooled["condition_oracle"] = round(float(np.mean(np.concatenate(
            [d["errors"][:, radii.index(per_domain[c]["best_fixed_radius"])]
             for c, d in zip(conditions, shapes_all)])) * SCALE), 4)
        pooled["condition_oracle_gain"] = round(
            1.0 - pooled["condition_oracle"] / pooled["best_fixed"], 4)
        # a radius per density bin (the 64th nearest point's distance, which the parent patch
        # shows), blind to noise and to the condition
        edges = np.quantile(data["d64"], np.linspace(0, 1, DENSITY_BINS + 1)[1:-1])
        density = summarise(data["errors"], radii, groups=np.searchsorted(edges, data["d64"]))
        pooled["density_oracle"] = density["type_oracle"]
        pooled["density_oracle_gain"] = density["type_oracle_gain"]
        per_domain["all conditions"] = pooled
        results["domains"][domain] = per_domain
    results["by_patch_type_all_domains"] = {
        c: by_type({k: np.concatenate([d[k] for d in parts]) for k in ("errors", "local", "type")},
                   radii)
        for c, parts in pooled_types.items()}
    return results


def by_type(data: Dict[str, np.ndarray], radii) -> Dict:
    out = {}
    for i, name in enumerate(PATCH_TYPES):
        rows = data["type"] == i
        if rows.any():
            out[name] = summarise(data["errors"][rows], radii, data["local"][rows])
    return out


def format_tables(results: Dict) -> str:
    """Markdown tables of a results file: the curves per domain x condition (x 10^4), then the
    curves per patch type over all domains, per condition."""
    radii = results["radii"]
    head = "| " + " | ".join(f"{r:.3f}" for r in radii) + " |"
    rule = "|---:" * len(radii) + "|"
    lines = ["| domain | condition " + head + " best fixed | at 0.018 | at 0.024 | local oracle"
             " | oracle |", "|---|---" + rule + "---|---:|---:|---:|---:|"]
    for domain, entries in results["domains"].items():
        for condition, e in entries.items():
            best = e["curve"].index(e["best_fixed"])
            cells = [f"**{c:.2f}**" if i == best else f"{c:.2f}" for i, c in enumerate(e["curve"])]
            lines.append(
                f"| {domain} | {condition} | " + " | ".join(cells)
                + f" | {e['best_fixed_radius']:.3f}: {e['best_fixed']:.2f} | {e['at_0.018']:.2f}"
                f" | {e['at_0.024']:.2f} | {e['local_oracle']:.2f}"
                f" ({-100 * e['local_oracle_gain']:+.1f} %)"
                f" | {e['oracle']:.2f} ({-100 * e['oracle_gain']:+.1f} %) |")
    lines += ["", "| condition | patch type | queries " + head + " best fixed | local oracle |",
              "|---|---|---:" + rule + "---|---:|"]
    for condition, types in results["by_patch_type_all_domains"].items():
        for name, e in types.items():
            best = e["curve"].index(e["best_fixed"])
            cells = [f"**{c:.2f}**" if i == best else f"{c:.2f}" for i, c in enumerate(e["curve"])]
            lines.append(f"| {condition} | {name} | {e['queries']} | " + " | ".join(cells)
                         + f" | {e['best_fixed_radius']:.3f} | {e['local_oracle']:.2f} "
                         f"({-100 * e['local_oracle_gain']:+.1f} %) |")
    lines += ["", "| domain, all conditions | best fixed | density oracle | condition oracle | "
              "type oracle (condition x patch type) | local oracle | oracle |",
              "|---|---|---:|---:|---:|---:|---:|"]
    for domain, entries in results["domains"].items():
        e = entries["all conditions"]
        cells = [f"{e[k]:.2f} ({-100 * e[k + '_gain']:+.1f} %)" for k in
                 ("density_oracle", "condition_oracle", "type_oracle", "local_oracle", "oracle")]
        lines.append(f"| {domain} | {e['best_fixed_radius']:.3f}: {e['best_fixed']:.2f} | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tables", metavar="JSON",
                        help="print the markdown tables of an existing results file and exit")
    parser.add_argument("--out", default="bench_results/radius_curves/curves.json")
    parser.add_argument("--shapes", type=int, default=10, help="shapes per domain and condition")
    parser.add_argument("--queries", type=int, default=3000, help="queries per shape")
    parser.add_argument("--seed", type=int, default=0, help="query seed")
    parser.add_argument("--split", choices=("test", "heldout"), default="test")
    parser.add_argument("--domains", nargs="+", default=list(DOMAINS))
    parser.add_argument("--conditions", nargs="+", default=list(EVAL_CONDITIONS))
    parser.add_argument("--radii", type=float, nargs="+", default=list(RADII))
    parser.add_argument("--threads", type=int, default=1, help="BLAS threads")
    parser.add_argument("--raw", help="also write the per-query arrays to this .npz")
    parser.add_argument("--from-raw", metavar="NPZ",
                        help="recompute the results from a --raw file instead of measuring")
    args = parser.parse_args(argv)
    if args.tables:
        print(format_tables(json.loads(Path(args.tables).read_text())))
        return
    from threadpoolctl import threadpool_limits

    started = time.time()
    raw = {}
    if args.from_raw:
        with np.load(args.from_raw) as data:
            raw = {k: data[k] for k in data.files}
        results = summarise_raw(raw, args.domains, args.conditions)
    else:
        with threadpool_limits(args.threads):
            results = run(args.domains, args.conditions, args.shapes, args.queries, args.seed,
                          args.split, sorted(args.radii), raw=raw)
    if args.raw and not args.from_raw:
        Path(args.raw).parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(args.raw, **raw)
    results["args"] = vars(args)
    results["seconds"] = round(time.time() - started, 1)
    results["machine"] = f"{platform.machine()}, {platform.processor() or 'cpu'}, " \
                         f"{args.threads} BLAS thread(s)"
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=1))
    print(f"wrote {out} in {results['seconds']} s")


if __name__ == "__main__":
    main()
