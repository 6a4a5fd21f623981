"""Seconds per stage and peak memory of the DCUDF mesher on a sphere and an open disk.

    python benchmarks/bench_meshing.py [--res 128 256 512] [--iterations N] [--device cuda]

cpu s is the process time of the extraction (both threads of the field queries; under load it
is steadier than the wall times); opt it the iterations run (stage 2 stops early once converged),
ms/it the wall time per iteration, passes the optimisation's passes: ``compiled`` (numba), or
``numpy`` (without numba, or with ``UDF_RECON_KERNELS=numpy``), or ``torch``.

Fields: sphere of radius 0.5 and flat disk of radius 0.5 (z = 0, midway between node layers)
in [-1, 1]^3, dense grids (the grid interpolation path, as with a network's output). Peak memory
is the process's ru_maxrss after each run (a high-water mark: it never goes down), so run one
resolution per process for exact figures; tracemalloc's numpy peak is printed too. With
``--device cuda`` the optimisation runs in torch on the GPU (the other stages stay on the CPU)
and the GPU's peak allocated memory is printed as well.
"""

import argparse
import os
import resource
import sys
import time
import tracemalloc

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from engine.devices import resolve_device  # noqa: E402
from engine.meshing import MeshingSettings, extract_surface  # noqa: E402
from lab import analytic as A  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--res", type=int, nargs="+", default=[128, 256, 512])
    parser.add_argument("--shapes", nargs="+", default=["sphere", "disk"])
    parser.add_argument("--iterations", type=int, default=None)
    parser.add_argument("--device", default="cpu", choices=("cpu", "cuda", "auto"))
    args = parser.parse_args()
    gpu = resolve_device(args.device) == "cuda"
    shapes = {"sphere": A.sphere((0, 0, 0), 0.5), "disk": A.disk((0, 0, 0), 0.5)}
    header = (f"{'shape':7s} {'res':>4s} {'cover F':>9s} {'out F':>8s} {'grid s':>7s} "
              f"{'MC s':>6s} {'field s':>7s} {'opt s':>7s} {'layer s':>7s} {'clean s':>7s} "
              f"{'total s':>8s} {'cpu s':>6s} {'opt it':>6s} {'ms/it':>6s} {'py peak MB':>10s} "
              f"{'RSS MB':>7s} {'GPU MB':>7s} {'passes':>8s} layers")
    print(header, flush=True)
    for res in args.res:
        for name in args.shapes:
            start = time.perf_counter()
            grid = A.sample_grid(shapes[name], [-1] * 3, [1] * 3, res, exact=False)
            grid_s = time.perf_counter() - start
            settings = MeshingSettings(device=args.device)
            if gpu:
                import torch
                torch.cuda.reset_peak_memory_stats()
            if args.iterations is not None:
                settings.iterations = args.iterations
            tracemalloc.start()
            cpu = time.process_time()
            result = extract_surface(grid, settings)
            cpu = time.process_time() - cpu
            _, peak = tracemalloc.get_traced_memory()
            tracemalloc.stop()
            t = result.timings
            iters = int(result.stats.get("iterations", settings.iterations))
            rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            status = (f"double_pairs={int(result.stats.get('double_pairs', 0))} "
                      f"seams={int(result.stats.get('seam_vertices', 0))}")
            gpu_mb = torch.cuda.max_memory_allocated() / 2**20 if gpu else 0.0
            print(f"{name:7s} {res:4d} {int(result.stats['cover_faces']):9d} "
                  f"{len(result.mesh.faces):8d} {grid_s:7.1f} {t['marching_cubes']:6.2f} "
                  f"{t.get('field', 0):7.2f} {t['optimize']:7.1f} {t['layers']:7.2f} "
                  f"{t['cleanup']:7.2f} {sum(t.values()):8.1f} {cpu:6.1f} {iters:6d} "
                  f"{1e3 * t['optimize'] / max(iters, 1):6.0f} {peak / 2**20:10.0f} "
                  f"{rss:7.0f} {gpu_mb:7.0f} {result.stats['optimize_kernels']:>8s} {status}",
                  flush=True)
            del grid, result


if __name__ == "__main__":
    main()
