"""Time and memory of one reconstruction per grid resolution, on the bundled 50 000-point cloud.

Usage (from the repository root)::

    python benchmarks/bench_reconstruct.py [--resolutions 128 256] [--device cpu]
                                           [--udf-source network] [--input examples/owl_50k.ply]
                                           [--radius-mode fixed|curvature|learned]

Each resolution runs in a fresh child process so its peak resident memory (``ru_maxrss``) is
its own. Prints one table row per resolution: wall seconds per stage (frame, band, udf,
meshing, finish, total), the child's CPU seconds (user + system, whole process: a fairer figure
on a shared machine), peak memory, band nodes, mean points per ball and the output's size; then
the field's cost per network query, and how much of it the radius policy took (the selector's
or the curvature estimate's share: compare ``--radius-mode learned`` with ``fixed``).
Targets on the 2-core CI machine at 256: total <= 90 s, peak <= 4 GB.
"""

import argparse
import json
import os
import resource
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_INPUT = ROOT / "examples" / "owl_50k.ply"
STAGES = ("outliers", "frame", "band", "udf", "meshing", "finish", "total", "cpu_s")


def run_one(path: str, resolution: int, device: str, udf_source: str, radius_mode: str) -> dict:
    """Reconstruct ``path`` once in this process; the figures as a dict."""
    sys.path.insert(0, str(ROOT))
    from engine.io import read_point_cloud
    from engine.reconstruct import reconstruct
    from engine.settings import ReconstructSettings

    cloud = read_point_cloud(path)
    settings = ReconstructSettings(resolution=resolution, device=device, radius_mode=radius_mode)
    result = reconstruct(cloud, settings, udf_source=udf_source)
    usage = resource.getrusage(resource.RUSAGE_SELF)
    stats = result.stats
    return {"resolution": resolution, "points": len(cloud), **result.timings,
            "cpu_s": usage.ru_utime + usage.ru_stime,
            "peak_gib": usage.ru_maxrss / 2 ** 20,  # ru_maxrss is in KiB on Linux
            "band_nodes": stats["band_nodes"],
            "mean_patch_points": stats["mean_patch_points"], "vertices": stats["vertices"],
            "faces": stats["faces"], "device": stats["device"], "udf_source": udf_source,
            "network_queries": stats.get("network_queries", 0),
            "radius_s": stats.get("seconds_radius", 0.0)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--input", default=str(DEFAULT_INPUT))
    parser.add_argument("--resolutions", type=int, nargs="+", default=[128, 256])
    parser.add_argument("--device", default="cpu", choices=("auto", "cpu", "cuda"))
    parser.add_argument("--udf-source", default="network", choices=("network", "nearest"))
    parser.add_argument("--radius-mode", default="fixed", choices=("fixed", "curvature", "learned"))
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(run_one(args.input, args.child, args.device, args.udf_source,
                                 args.radius_mode)))
        return 0

    header = (f"{'res':>4} " + " ".join(f"{s:>8}" for s in STAGES)
              + f" {'peak GiB':>8} {'band':>9} {'pts/ball':>8} {'verts':>8} {'faces':>8}")
    print(f"input {args.input}, device {args.device}, udf source {args.udf_source}, "
          f"radius mode {args.radius_mode}, "
          f"{os.cpu_count()} CPUs; seconds per stage")
    print(header)
    details = []
    for resolution in args.resolutions:
        child = subprocess.run(
            [sys.executable, __file__, "--child", str(resolution), "--input", args.input,
             "--device", args.device, "--udf-source", args.udf_source,
             "--radius-mode", args.radius_mode],
            capture_output=True, text=True, cwd=ROOT)
        if child.returncode != 0:
            print(f"{resolution:>4} failed:\n{child.stderr.strip()}")
            return 1
        row = json.loads(child.stdout.strip().splitlines()[-1])
        print(f"{resolution:>4} " + " ".join(f"{row[s]:8.2f}" for s in STAGES)
              + f" {row['peak_gib']:8.2f} {row['band_nodes']:9,d} "
                f"{row['mean_patch_points']:8.1f} {row['vertices']:8,d} {row['faces']:8,d}")
        mesher = ", ".join(f"{key[len('meshing_'):]} {value:.2f}" for key, value in row.items()
                           if key.startswith("meshing_"))
        details.append(f"{resolution:>4} meshing stages (s): {mesher}; network on {row['device']}")
        queries = max(row["network_queries"], 1)
        details.append(f"{resolution:>4} field: {row['network_queries']:,} network queries, "
                       f"{1e6 * row['udf'] / queries:.1f} us per query, of which radius policy "
                       f"{1e6 * row['radius_s'] / queries:.1f} us: it adds "
                       f"{100 * row['radius_s'] / max(row['udf'] - row['radius_s'], 1e-9):.0f}% "
                       f"to the rest of the field's time")
    print("\n".join(details))
    return 0


if __name__ == "__main__":
    sys.exit(main())
