"""Tiles on one core and in worker processes: wall seconds, the speed-ups, and whether the
meshes are the same.

    python benchmarks/bench_workers.py [--cloud examples/owl_50k.ply] [--resolution 256]
        [--tile-cells 96] [--workers 1 2] [--repeats 2] [--radius-mode fixed]

``--workers 1`` makes the tiles in this process on one core (one thread for the field, the
mesher and the k-d queries); ``--workers N`` in N worker processes of one thread each, and 0 on
every core. Each repeat runs every worker count once, in turn, so that other jobs on the machine
weigh on all of them alike; speed-ups are ratios of the medians, over the first count given.
The mesh of every run is compared with the first one's, vertex for vertex.
"""

import argparse
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402

from engine.io import read_point_cloud  # noqa: E402
from engine.reconstruct import reconstruct  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cloud", default="examples/owl_50k.ply")
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--tile-cells", type=int, default=96)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--radius-mode", default="fixed")
    args = parser.parse_args()
    cloud = read_point_cloud(args.cloud)
    runs = list(args.workers)
    seconds = {run: [] for run in runs}
    first = None
    for repeat in range(args.repeats):
        for run in runs:
            settings = {"resolution": args.resolution, "tile_cells": args.tile_cells,
                        "workers": run, "radius_mode": args.radius_mode}
            start = time.perf_counter()
            result = reconstruct(cloud, settings)
            wall = time.perf_counter() - start
            seconds[run].append(wall)
            mesh = (np.asarray(result.mesh.vertices), np.asarray(result.mesh.faces))
            if first is None:
                first = mesh
            same = (mesh[0].shape == first[0].shape and np.array_equal(mesh[0], first[0])
                    and np.array_equal(mesh[1], first[1]))
            print(f"repeat {repeat + 1}  workers {run}  {wall:7.1f} s  "
                  f"tiles {result.stats.get('tiles')}  faces {len(mesh[1]):,}  "
                  f"same mesh as the first run: {same}", flush=True)
    base = statistics.median(seconds[runs[0]])
    for run in runs:
        median = statistics.median(seconds[run])
        print(f"workers {run}: median {median:.1f} s; speed-up over workers {runs[0]} "
              f"{base / median:.2f}x")


if __name__ == "__main__":
    main()
