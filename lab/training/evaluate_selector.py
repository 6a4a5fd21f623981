"""Held-out UDF error of a radius selector file against every single radius of its range.

    python -m lab.training.evaluate_selector [engine/weights/selector.npz] [--first-seed 100]
        [--count 15] [--out result.json]

Runs :func:`.train_selector.evaluate` on ``--count`` held-out training shapes of every domain
from ``--first-seed`` (by default :data:`.train_selector.BALANCED_SEEDS`: 5 clean, 5 sparse, 5
noisy; rooms are never trained on), at the product's learned range
(``engine.settings.MODE_RANGES``) and the candidate radii the selector was trained with (read
from the training record ``train_selector`` writes beside it, ``<selector>.json``), and prints per domain and condition: the learned error, the best single fixed radius of
the range on these very queries, fixed 0.018 and curvature (mean |UDF error| x 10^4, unit
frame).
"""

import argparse
import json
import types
from pathlib import Path

from engine.field import backbone_predictor
from engine.selector import DEFAULT_WEIGHTS, load_selector_numpy
from engine.settings import MODE_RANGES
from .train_selector import BALANCED_SEEDS, evaluate



def training_grid(selector: str) -> tuple[int, str]:
    """The candidate count and spacing ``selector`` was trained with, from its training record."""
    record = Path(selector).with_suffix(".json")
    try:
        args = json.loads(record.read_text())["args"]
        return int(args["candidates"]), str(args["spacing"])
    except (OSError, ValueError, KeyError) as error:
        raise SystemExit(f"cannot read the training record {record} of {selector} "
                         f"({error}); it names the candidate radii to compare against") from None


def table(results: dict) -> str:
    """Markdown rows: per domain, then per condition, the policies' errors x 10^4."""
    lines = ["| domain | condition | fixed 0.018 | best fixed (radius) | curvature | learned "
             "(mean radius) | learned against best fixed |", "|---|---|---:|---:|---:|---:|---:|"]
    for domain, result in results.items():
        for condition in ("all", "clean", "sparse", "noisy"):
            means = result if condition == "all" else result.get(condition)
            if means is None:
                continue
            lines.append(
                f"| {domain} | {condition} | {1e4 * means['fixed 0.0180']:.2f} | "
                f"{1e4 * means['best fixed']:.2f} ({means['best fixed radius']:.3f}) | "
                f"{1e4 * means['curvature']:.2f} | {1e4 * means['learned']:.2f} "
                f"({means['learned radius']:.3f}) | "
                f"{100 * (means['learned'] / means['best fixed'] - 1):+.1f} % |")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("selector", nargs="?", default=str(DEFAULT_WEIGHTS))
    parser.add_argument("--first-seed", type=int, default=BALANCED_SEEDS[0])
    parser.add_argument("--count", type=int, default=len(BALANCED_SEEDS))
    parser.add_argument("--queries", type=int, default=3000, help="queries per shape")
    parser.add_argument("--out", help="write the means as JSON here too")
    args = parser.parse_args(argv)
    parent, rho_min, rho_max = MODE_RANGES["learned"]
    candidates, spacing = training_grid(args.selector)
    grid = types.SimpleNamespace(parent_radius=parent, rho_min=rho_min, rho_max=rho_max,
                                 candidates=candidates, spacing=spacing, queries=args.queries)
    seeds = list(range(args.first_seed, args.first_seed + args.count))
    results = evaluate(grid, backbone_predictor("cpu"), load_selector_numpy(args.selector),
                       seeds)
    if args.out:
        with open(args.out, "w") as handle:
            json.dump(results, handle, indent=2)
    print(table(results))


if __name__ == "__main__":
    main()
