"""How far the field's values lie from the true distance, by distance from the nearest point.

For one benchmark shape: the field is computed as a reconstruction computes it
(``engine.field.compute_udf_band``, default settings at ``--resolution``), and at every band node
three distances are compared: the field's value (the network's within
``engine.field.NETWORK_BAND_NODES`` spacings of a point, the nearest-point distance beyond), the
distance to the nearest input point, and the true distance to the ground truth (to a dense
sample of its surface). Prints, per bin of nearest-point distance (voxels), the node count and
the mean (signed) and mean absolute error of each against the truth, in voxels.

Usage (from the repository root)::

    python benchmarks/band_errors.py --domain garments --condition clean [--seed 1000000]
                                     [--resolution 256]
"""

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BINS = ((0, 1), (1, 2), (2, 3), (3, 4), (4, 6))
SURFACE_SAMPLES = 3_000_000


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--domain", default="garments", choices=("cars", "garments", "rooms"))
    parser.add_argument("--condition", default="clean", choices=("clean", "sparse", "noisy"))
    parser.add_argument("--seed", type=int, default=1000000)
    parser.add_argument("--resolution", type=int, default=256)
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from scipy.spatial import cKDTree

    from engine.field import compute_udf_band
    from engine.frame import UnitFrame
    from engine.sampling import sample_surface
    from engine.settings import ReconstructSettings
    from lab.bench import dataset

    truth = dataset.make_shape(args.domain, args.seed)
    points = dataset.make_input(truth, args.domain, args.condition, args.seed).points
    frame = UnitFrame.from_points(points)
    unit = frame.to_unit(points)
    grid = compute_udf_band(unit, ReconstructSettings(resolution=args.resolution,
                                                      fill_gaps=False, radius_mode="fixed")).grid
    nodes, field = grid.band()
    where = grid.index_to_world(nodes)
    nearest, _ = cKDTree(unit).query(where, workers=-1)
    surface, _, _ = sample_surface(frame.to_unit(np.asarray(truth.vertices, np.float64)),
                                   np.asarray(truth.faces), SURFACE_SAMPLES,
                                   np.random.default_rng(0))
    true, _ = cKDTree(surface).query(where, workers=-1)
    h = grid.spacing
    print(f"{args.domain} {args.condition} seed {args.seed} at {args.resolution}: errors against "
          f"the true distance, voxels (mean / mean absolute)")
    print(f"{'nearest point':>16} {'nodes':>9} {'field':>15} {'nearest point':>15}")
    for low, high in BINS:
        inside = (nearest > low * h) & (nearest <= high * h)
        if not inside.any():
            continue
        cells = []
        for values in (field, nearest):
            error = (values[inside] - true[inside]) / h
            cells.append(f"{error.mean():+.3f} / {np.abs(error).mean():.3f}")
        print(f"{f'{low}-{high} voxels':>16} {int(inside.sum()):>9,} {cells[0]:>15} {cells[1]:>15}")


if __name__ == "__main__":
    main()
