"""What filling the gaps of a sparse scan costs (engine/gap_fill.py), beside the field it adds to.

    python benchmarks/bench_gap_fill.py [--resolution 256] [--count 1]

For the first ``--count`` sparse and clean test shapes of each domain and the bundled owl, it
builds the band (nearest-point distances: the band's nodes do not depend on the network), then
fills the gaps, and prints the points, band nodes, edge points and the fill's wall and process
seconds on this machine (the work does not depend on the band's values, only which nodes take
a plane distance does).
"""

import argparse
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from engine import gap_fill
from engine.field import compute_udf_band
from engine.frame import UnitFrame
from engine.io import read_point_cloud
from engine.settings import ReconstructSettings
from lab.bench import dataset

OWL = Path(__file__).resolve().parents[1] / "examples" / "owl_50k.ply"


def clouds(count: int):
    for condition in ("sparse", "clean"):
        for domain in dataset.DOMAINS:
            for seed in dataset.test_seeds(domain, count)[:count]:
                gt = dataset.make_shape(domain, seed)
                points = np.asarray(dataset.make_input(gt, domain, condition, seed).points)
                yield f"{domain} {condition} {seed}", points
    points = read_point_cloud(str(OWL)).points
    yield "owl", points


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--count", type=int, default=1)
    args = parser.parse_args()
    print("| cloud | points | band nodes | edge points | fill s (wall) | fill s (process) |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, points in clouds(args.count):
        points = UnitFrame.from_points(points).to_unit(points)
        band = compute_udf_band(points, ReconstructSettings(resolution=args.resolution,
                                                            fill_gaps=False, radius_mode="fixed"),
                                udf_source="nearest")
        grid = band.grid
        indices, values = grid.band()
        tree = cKDTree(points)
        wall, process = time.perf_counter(), time.process_time()
        gap_fill.fill_gaps(tree, points, grid.shape, grid.origin, grid.spacing,
                                          indices, values)
        wall, process = time.perf_counter() - wall, time.process_time() - process
        _, _, edge = gap_fill._point_planes(tree, points, gap_fill.EDGE_NODES * grid.spacing)
        print(f"| {name} | {len(points):,} | {len(indices):,} | {int(edge.sum()):,} | "
              f"{wall:.2f} | {process:.2f} |", flush=True)


if __name__ == "__main__":
    main()
