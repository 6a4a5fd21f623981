"""Memory and time of stitching the tiles of one reconstruction into one mesh.

    python benchmarks/bench_stitch.py [--cloud examples/owl_50k.ply] [--resolution 256]
        [--tile-cells 64 128] [--workers 2]

For each tile size: reconstructs the cloud in tiles, keeps the tiles' pieces as the stitcher
received them (each tile in a file, its seam's rim in memory: ``engine.tiles.TilePiece``), then
stitches them again under tracemalloc and prints the faces, the seam's share of them (the faces
stitching may change, with the faces around them), the seconds, and the peak of numpy's
allocations above the rims it is handed, in MB and per face: choosing the tiles to turn
(``engine.tiles.tiles_to_turn``), gathered into one mesh in memory (``engine.tiles.stitch``, as
``reconstruct()`` returns it, the output included), and read block by block as a file writer
reads it (``StitchedMesh.vertex_blocks``/``face_blocks``, as the CLI writes a PLY).
"""

import argparse
import dataclasses
import os
import shutil
import sys
import tempfile
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
    stitched_in_blocks = tiles.stitched_in_blocks
    print("tile cells | tiles | faces | seam share | stitch s | turn peak MB | bytes / face | "
          "peak MB | bytes / face | streamed peak MB | bytes / face")
    for cells in args.tile_cells:
        with tempfile.TemporaryDirectory() as folder:
            captured = []

            def capture(pieces, tile_list, spacing, min_component_faces=0, into=None):
                # the tiles' files go with the reconstruction's folder: keep copies
                kept = []
                for number, piece in enumerate(pieces):
                    path = os.path.join(folder, f"tile{number}.npz")
                    shutil.copy(piece.rest.stored, path)
                    kept.append(dataclasses.replace(
                        piece, rest=tiles.TileRest(piece.rest.piece_rest, path)))
                captured.append((kept, tile_list, spacing))
                return stitched_in_blocks(pieces, tile_list, spacing, min_component_faces,
                                          into)

            tiles.stitched_in_blocks = capture
            try:
                reconstruct(cloud, {"resolution": args.resolution, "tile_cells": cells,
                                    "workers": args.workers})
            finally:
                tiles.stitched_in_blocks = stitched_in_blocks
            pieces, tile_list, spacing = captured[-1]
            faces = sum(int(piece.piece_faces.sum()) for piece in pieces)
            seam = len(tiles._seam([piece.held() for piece in pieces], spacing).faces)
            tracemalloc.start()
            base = tracemalloc.get_traced_memory()[0]
            tiles.tiles_to_turn(list(pieces), tile_list, spacing)
            turn = tracemalloc.get_traced_memory()[1] - base
            tracemalloc.reset_peak()
            base = tracemalloc.get_traced_memory()[0]
            start = time.perf_counter()
            tiles.stitch(list(pieces), tile_list, spacing)
            seconds = time.perf_counter() - start
            peak = tracemalloc.get_traced_memory()[1] - base
            tracemalloc.reset_peak()
            base = tracemalloc.get_traced_memory()[0]
            stitched, _ = tiles.stitched_in_blocks(list(pieces), tile_list, spacing, 0, folder)
            for _ in stitched.vertex_blocks():
                pass
            for _ in stitched.face_blocks():
                pass
            del stitched
            streamed = tracemalloc.get_traced_memory()[1] - base
            tracemalloc.stop()
        print(f"{cells} | {len(tile_list)} | {faces:,} | {100 * seam / faces:.0f} % | "
              f"{seconds:.1f} | {turn / 2 ** 20:.0f} | {turn / faces:.0f} | "
              f"{peak / 2 ** 20:.0f} | {peak / faces:.0f} | "
              f"{streamed / 2 ** 20:.0f} | {streamed / faces:.0f}", flush=True)


if __name__ == "__main__":
    main()
