"""Memory and time of stitching the tiles of one reconstruction into one mesh.

    python benchmarks/bench_stitch.py [--cloud examples/owl_50k.ply] [--resolution 256]
        [--tile-cells 64 128] [--workers 2]

For each tile size: reconstructs the cloud in tiles, keeps the tiles' pieces as the stitcher
received them, then stitches them again under tracemalloc and prints the faces, the seam's share
of them (the faces stitching may change, with the faces around them: ``engine.tiles._seam``),
the seconds, and the peak of numpy's allocations above the pieces it is handed (which it frees
as it reads them), in MB and per face.
"""

import argparse
import os
import sys
import time
import tracemalloc

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from engine import tiles  # noqa: E402
from engine.io import read_point_cloud  # noqa: E402
from engine.reconstruct import reconstruct  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cloud", default="examples/owl_50k.ply")
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--tile-cells", type=int, nargs="+", default=[64, 128])
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    cloud = read_point_cloud(args.cloud)
    stitch = tiles.stitch
    print("tile cells | tiles | faces | seam share | stitch s | peak MB | bytes / face")
    for cells in args.tile_cells:
        captured = []

        def capture(pieces, tile_list, spacing, min_component_faces=0):
            captured.append((list(pieces), tile_list, spacing))
            return stitch(pieces, tile_list, spacing, min_component_faces)

        tiles.stitch = capture
        try:
            reconstruct(cloud, {"resolution": args.resolution, "tile_cells": cells,
                                "workers": args.workers})
        finally:
            tiles.stitch = stitch
        pieces, tile_list, spacing = captured[-1]
        faces = sum(len(f) for _, f in pieces)
        seam = len(tiles._seam(pieces, tile_list, spacing).faces)
        tracemalloc.start()
        # copies made under tracemalloc, handed over: the stitcher frees each tile's arrays
        # once read, and the peak counts that
        given = [(v.copy(), f.copy()) for v, f in pieces]
        base = tracemalloc.get_traced_memory()[0]
        start = time.perf_counter()
        stitch(given, tile_list, spacing)
        seconds = time.perf_counter() - start
        peak = tracemalloc.get_traced_memory()[1] - base
        tracemalloc.stop()
        print(f"{cells} | {len(pieces)} | {faces:,} | {100 * seam / faces:.0f} % | "
              f"{seconds:.1f} | {peak / 2 ** 20:.0f} | {peak / faces:.0f}", flush=True)


if __name__ == "__main__":
    main()
