"""Table I's learned rows against another row, shape by shape.

    python -m lab.bench.paired --count 30 [--out bench_results/table1]

For every domain and condition: learned minus the other row (best fixed, fixed 0.018, Poisson)
in CD-L1 ×10² and F1@0.005 over the first ``count`` test shapes, the mean difference, its
standard error, and on how many shapes learned is the better one. A mean difference within two
standard errors of zero is a tie on these shapes.
"""

import argparse
import math
from pathlib import Path

from .command import BEST_FIXED_RADII, DOMAIN_NAMES
from .harness import read_json
from .methods import ours_name

OTHERS = ("best fixed", "fixed 0.018", "poisson")
TABLE_CONDITIONS = ("clean", "sparse", "noisy")
KEYS = (("cd_l1_x100", "CD", -1), ("f1_0.005", "F1@0.005", 1))  # sign: +1 where higher is better


def _rows(folder: Path, name: str, domain: str, condition: str, count: int) -> dict:
    """The first ``count`` shapes of one JSON result, by shape seed."""
    result = read_json(folder / f"{name}_{domain}_{condition}.json")
    shapes = {row["shape_seed"]: row for row in result["shapes"]}
    seeds = sorted(shapes)[:count]
    if len(seeds) < count:
        raise SystemExit(f"{name}_{domain}_{condition}: {len(seeds)} shapes, not {count}")
    return {seed: shapes[seed] for seed in seeds}


def other_name(other: str, domain: str) -> str:
    if other == "best fixed":
        return ours_name("fixed", BEST_FIXED_RADII[domain])
    return "ours" if other == "fixed 0.018" else other


def paired(folder: Path, count: int, other: str, domain: str, condition: str) -> dict:
    """``{key: (mean difference, standard error, shapes where learned is better)}``."""
    learned = _rows(folder, ours_name("learned"), domain, condition, count)
    rows = _rows(folder, other_name(other, domain), domain, condition, count)
    if sorted(rows) != sorted(learned):
        raise SystemExit(f"{other} and learned hold other shapes ({domain}, {condition})")
    out = {}
    for key, _, sign in KEYS:
        diffs = [learned[seed][key] - rows[seed][key] for seed in learned]
        mean = sum(diffs) / count
        spread = sum((d - mean) ** 2 for d in diffs) / max(count - 1, 1)
        out[key] = (mean, math.sqrt(spread / count), sum(sign * d > 0 for d in diffs))
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, required=True)
    parser.add_argument("--out", default="bench_results/table1")
    args = parser.parse_args(argv)
    folder = Path(args.out)
    for other in OTHERS:
        print(f"\nlearned minus {other}, first {args.count} shapes (mean ± standard error; "
              f"shapes where learned is better)\n")
        print("| condition | domain | " + " | ".join(label for _, label, _ in KEYS) + " |")
        print("|---|---|" + "---:|" * len(KEYS))
        for condition in TABLE_CONDITIONS:
            for domain in DOMAIN_NAMES:
                found = paired(folder, args.count, other, domain, condition)
                cells = [f"{mean:+.4f} ± {error:.4f} ({better}/{args.count})"
                         for mean, error, better in (found[key] for key, _, _ in KEYS)]
                print(f"| {condition} | {domain} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
