"""Time and peak memory of the outlier test on a large cloud: slab by slab against one k-d tree.

    python benchmarks/bench_outliers.py CLOUD [--slab-points 1000000]

CLOUD: a ``.npy`` array of points (N, 3) or a point-cloud file the engine reads. Each way runs
in a fresh process, one after the other: the neighbour searches slab by slab of
``--slab-points`` candidates (the engine's default, ``engine.outliers.SLAB_POINTS``), and with
every candidate in one tree. Prints the points, seconds, the process's peak resident memory
(``VmHWM``, the cloud included), its resident memory once the cloud is loaded, how many points
were flagged, and whether both ways flag the same points.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def run(cloud_path: str, slab_points: int, flags_path: str) -> dict:
    """One way, in this process: the figures as a dict; the flags saved to ``flags_path``."""
    import numpy as np

    import engine.outliers as outliers
    from engine.tile_runners import process_peak_bytes, process_resident_bytes

    if cloud_path.endswith(".npy"):
        points = np.load(cloud_path)
    else:
        from engine.io import read_point_cloud

        points = read_point_cloud(cloud_path).points
    loaded = process_resident_bytes()
    outliers.SLAB_POINTS = slab_points
    started = time.perf_counter()
    flagged = outliers.find_outliers(points)
    seconds = time.perf_counter() - started
    np.save(flags_path, flagged)
    return {"points": len(points), "seconds": seconds, "peak_gib": process_peak_bytes() / 2 ** 30,
            "loaded_gib": loaded / 2 ** 30, "flagged": int(flagged.sum())}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cloud")
    parser.add_argument("--slab-points", type=int, default=None)
    parser.add_argument("--child", nargs=2, metavar=("SLAB_POINTS", "FLAGS"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(run(args.cloud, int(args.child[0]), args.child[1])))
        return
    import numpy as np

    from engine.outliers import SLAB_POINTS

    slab = args.slab_points or SLAB_POINTS
    print("search | points | seconds | peak GiB | GiB with the cloud loaded | flagged")
    with tempfile.TemporaryDirectory() as folder:
        flags = []
        for name, points in ((f"slabs of {slab:,}", slab), ("one tree", 2 ** 62)):
            flags.append(os.path.join(folder, f"{points}.npy"))
            child = subprocess.run([sys.executable, __file__, args.cloud, "--child",
                                    str(points), flags[-1]], check=True, capture_output=True,
                                   text=True)
            figures = json.loads(child.stdout.strip().splitlines()[-1])
            print(f"{name} | {figures['points']:,} | {figures['seconds']:.1f} | "
                  f"{figures['peak_gib']:.2f} | {figures['loaded_gib']:.2f} | "
                  f"{figures['flagged']:,}", flush=True)
        same = np.array_equal(np.load(flags[0]), np.load(flags[1]))
    print(f"the same points flagged both ways: {same}")


if __name__ == "__main__":
    main()
