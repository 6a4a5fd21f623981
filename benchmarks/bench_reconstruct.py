"""Time and memory of one reconstruction per grid resolution, on the bundled 50 000-point cloud,
beside Open3D's screened Poisson on the same cloud in the same run.

Usage (from the repository root)::

    python benchmarks/bench_reconstruct.py [--resolutions 128 256] [--device cpu]
                                           [--udf-source network] [--input examples/owl_50k.ply]
                                           [--radius-mode fixed|curvature|learned] [--no-poisson]
    python benchmarks/bench_reconstruct.py --kernels [--resolutions 128] [--widths 32/64 ...]

Each run (ours per resolution, then Poisson at depth 9) goes in a fresh child process so its peak
resident memory (``ru_maxrss``) is its own. Prints one table row per resolution: wall seconds
per stage (frame, band, udf, meshing, finish, total), the child's CPU seconds (user + system,
whole process: a fairer figure on a shared machine), peak memory, band nodes, mean points per
ball and the output's size; then Poisson's time and the ratio ours / Poisson; then the field's
cost per network query (wall, and the process time of all threads with the band: steadier on
a shared machine), how much of it the radius policy took (the selector's or the curvature
estimate's share: compare ``--radius-mode learned`` with ``fixed``) and of that the parent
ball's neighbour search (which also gives the backbone its patches), the mesher's stages,
iterations and passes (compiled, or numpy without numba or with ``UDF_RECON_KERNELS=numpy``), and the field's floor: network queries x multiply-adds per query / the
multiply-add rate these cores reach on a large float32 matrix product, measured in the same run.
Poisson needs open3d (requirements-bench.txt).

``--kernels`` times only the numpy backbone and selector, on one thread, on the patches and
parent balls the field gives them at the first resolution (process time per query, the best of
three passes): the figure to compare between two versions of the kernels. ``--widths 48/96
32/64`` adds the backbone's time at narrower per-point and head widths on the same patches
(random weights, for the cost alone).
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_INPUT = ROOT / "examples" / "owl_50k.ply"
STAGES = ("outliers", "frame", "band", "udf", "meshing", "finish", "total", "cpu_s")


def run_one(path: str, resolution: int, device: str, udf_source: str, radius_mode: str) -> dict:
    """Reconstruct ``path`` once in this process; the figures as a dict."""
    sys.path.insert(0, str(ROOT))
    from engine import reconstruct as reconstruct_module
    from engine.io import read_point_cloud
    from engine.settings import ReconstructSettings

    field_cpu = []  # the field's process time (band and network, every thread)
    compute_udf_band = reconstruct_module.compute_udf_band

    def timed_field(*args, **kwargs):
        start = time.process_time()
        band = compute_udf_band(*args, **kwargs)
        field_cpu.append(time.process_time() - start)
        return band

    reconstruct_module.compute_udf_band = timed_field
    cloud = read_point_cloud(path)
    settings = ReconstructSettings(resolution=resolution, device=device, radius_mode=radius_mode)
    result = reconstruct_module.reconstruct(cloud, settings, udf_source=udf_source)
    usage = resource.getrusage(resource.RUSAGE_SELF)
    stats = result.stats
    return {"resolution": resolution, "points": len(cloud), **result.timings,
            "cpu_s": usage.ru_utime + usage.ru_stime, "field_cpu_s": sum(field_cpu),
            "peak_gib": usage.ru_maxrss / 2 ** 20,  # ru_maxrss is in KiB on Linux
            "band_nodes": stats["band_nodes"],
            "mean_patch_points": stats["mean_patch_points"], "vertices": stats["vertices"],
            "faces": stats["faces"], "device": stats["device"], "udf_source": udf_source,
            "network_queries": stats.get("network_queries", 0),
            "radius_s": stats.get("seconds_radius", 0.0),
            "gap_fill_s": stats.get("seconds_gap_fill", 0.0),
            "gap_nodes": stats.get("gap_nodes", 0),
            "parent_s": stats.get("seconds_parent_ball", 0.0),
            "lattice_step": stats.get("lattice_step", 1),
            "lattice_positions": stats.get("lattice_positions", 0),
            "lattice_own_nodes": stats.get("lattice_own_nodes", 0),
            "iterations": stats["meshing"].get("iterations", 0),
            "optimize_kernels": stats["meshing"].get("optimize_kernels", "numpy"),
            "macs_per_query": _macs_per_query(stats["mean_patch_points"])}


def _policy_detail(row: dict, queries: int, rest: float) -> str:
    """Where the radius policy ran: on a lattice of the grid, or at every query with its
    parent-ball search (whose lists also give the backbone its patches)."""
    if row["lattice_step"] > 1:
        return (f"(on a lattice of one node in {row['lattice_step']} along each axis: "
                f"{row['lattice_positions']:,} positions, "
                f"{100 * row['lattice_positions'] / queries:.0f}% of the queries, and at "
                f"{row['lattice_own_nodes']:,} ridge nodes, "
                f"{100 * row['lattice_own_nodes'] / queries:.0f}%)")
    return (f"(its parent-ball neighbour search, whose lists also give the backbone its "
            f"patches: {1e6 * row['parent_s'] / queries:.1f} us per query; the policy without "
            f"it adds {100 * (row['radius_s'] - row['parent_s']) / rest:.0f}%)")


def _macs_per_query(points: float, hidden: int = 0, head_width: int = 0) -> int:
    """The backbone's multiply-adds for one query of ``points`` patch points (the shipped
    backbone's, or at another ``hidden`` and ``head_width``)."""
    from engine.backbone import macs_per_query, weights_meta

    config = weights_meta()["config"]
    if hidden:
        config = dict(config, hidden=hidden, head_width=head_width)
    return macs_per_query(config, max(int(round(points)), 1))


def run_poisson(path: str) -> dict:
    """Open3D screened Poisson (depth 9, the Table I baseline) once in this process."""
    sys.path.insert(0, str(ROOT))
    from engine.io import read_point_cloud
    from lab.bench.methods import make_poisson

    cloud = read_point_cloud(path)
    start = time.perf_counter()
    mesh = make_poisson()(cloud)
    seconds = time.perf_counter() - start
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return {"total": seconds, "cpu_s": usage.ru_utime + usage.ru_stime,
            "peak_gib": usage.ru_maxrss / 2 ** 20, "faces": int(len(mesh.faces))}


def kernel_timings(path: str, resolution: int, repeats: int = 3, widths=()) -> str:
    """The numpy backbone and selector alone, on one thread, on the inputs the field gives them
    for ``path`` at ``resolution``: process time per query, the best of ``repeats`` passes.

    ``widths``: ``(hidden, head_width)`` pairs; the backbone's forward pass at each of those
    configurations (seeded random weights: the time does not depend on them) on the same
    patches, one line each."""
    sys.path.insert(0, str(ROOT))
    import numpy as np
    from scipy.spatial import cKDTree
    from threadpoolctl import threadpool_limits

    from engine import field, selector
    from engine.backbone import load_backbone_numpy
    from engine.frame import UnitFrame
    from engine.io import read_point_cloud
    from engine.settings import ReconstructSettings

    cloud = read_point_cloud(path)
    points = UnitFrame.from_points(cloud.points).to_unit(cloud.points)
    tree = cKDTree(points)
    patches, parents = [], []

    def record_patches(rel, mask):
        patches.append((rel.copy(), mask.copy()))
        return np.zeros(len(rel), dtype=np.float32)

    predict_unit = selector.NumpySelector.predict_unit

    def record_parents(self, rel, mask, extra, *args, **kwargs):
        parents.append((rel.copy(), mask.copy(), extra.copy()))
        return predict_unit(self, rel, mask, extra, *args, **kwargs)

    selector.NumpySelector.predict_unit = record_parents
    try:
        for mode in ("fixed", "learned"):
            settings = ReconstructSettings(resolution=resolution, device="cpu", radius_mode=mode)
            field.compute_udf_band(points, settings, tree=tree, predictor=record_patches)
            if mode == "fixed":
                fixed_patches, patches = patches, []
    finally:
        selector.NumpySelector.predict_unit = predict_unit
    backbone, radius_net = load_backbone_numpy(), selector.load_selector_numpy()
    rel, mask, extra = (np.concatenate(arrays) for arrays in zip(*parents))

    def best(run) -> float:
        times = []
        for _ in range(repeats):
            start = time.process_time()
            run()
            times.append(time.process_time() - start)
        return min(times)

    narrower = {width: _random_backbone(*width) for width in widths}
    with threadpool_limits(1):
        seconds_backbone = best(lambda: [backbone.predict(r, m) for r, m in fixed_patches])
        seconds_selector = best(lambda: radius_net.predict_unit(rel, mask, extra))
        seconds_narrower = {width: best(lambda: [net.predict(r, m) for r, m in fixed_patches])
                            for width, net in narrower.items()}
    count = sum(len(r) for r, _ in fixed_patches)
    lines = []
    for (hidden, head_width), seconds in seconds_narrower.items():
        lines.append(f"{resolution:>4} backbone H = {hidden}, head {head_width} (random weights): "
                     f"{1e6 * seconds / count:.1f} us per query, "
                     f"{_macs_per_query(_mean_points(fixed_patches), hidden, head_width):,} "
                     f"multiply-adds per query")
    return "\n".join([f"{resolution:>4} kernels, one thread, process time (best of {repeats}): backbone "
            f"{1e6 * seconds_backbone / count:.1f} us per query on the fixed radius's "
            f"{count:,} trimmed patches; selector network {1e6 * seconds_selector / len(rel):.1f}"
            f" us per query on the learned mode's {len(rel):,} parent balls"] + lines)


def _random_backbone(hidden: int, head_width: int):
    """A numpy backbone of that width with seeded random weights (for timing only)."""
    import torch

    from engine.backbone import DEFAULT_CONFIG, NumpyBackbone, build_backbone_torch

    torch.manual_seed(0)
    config = dict(DEFAULT_CONFIG, hidden=hidden, head_width=head_width)
    module = build_backbone_torch(config)
    return NumpyBackbone({k: v.detach().numpy() for k, v in module.state_dict().items()}, config)


def _mean_points(patches) -> float:
    return sum(int(m.sum()) for _, m in patches) / max(sum(len(m) for _, m in patches), 1)


def multiply_add_rate(threads: int) -> float:
    """Multiply-adds per second of a 2048^3 float32 matrix product on ``threads`` threads."""
    import numpy as np
    from threadpoolctl import threadpool_limits

    a = np.random.default_rng(0).random((2048, 2048), dtype=np.float32)
    with threadpool_limits(threads):
        a @ a  # warm-up
        start = time.perf_counter()
        for _ in range(3):
            a @ a
        return 3 * 2048 ** 3 / (time.perf_counter() - start)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--input", default=str(DEFAULT_INPUT))
    parser.add_argument("--resolutions", type=int, nargs="+", default=[128, 256])
    parser.add_argument("--device", default="cpu", choices=("auto", "cpu", "cuda"))
    parser.add_argument("--udf-source", default="network", choices=("network", "nearest"))
    parser.add_argument("--radius-mode", default="fixed", choices=("fixed", "curvature", "learned"))
    parser.add_argument("--no-poisson", action="store_true",
                        help="skip Open3D's Poisson (needs open3d) on the same cloud")
    parser.add_argument("--kernels", action="store_true",
                        help="only time the numpy backbone and selector, on one thread, on the "
                             "inputs the field gives them at the first resolution")
    parser.add_argument("--widths", nargs="*", default=[], metavar="H/HEAD",
                        help="with --kernels: also time the backbone at these widths (per-point "
                             "H / head MLP), e.g. 48/96 32/64, with random weights")
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--poisson-child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.poisson_child:
        print(json.dumps(run_poisson(args.input)))
        return 0
    if args.kernels:
        print(kernel_timings(args.input, args.resolutions[0],
                             widths=[tuple(int(x) for x in w.split("/")) for w in args.widths]))
        return 0
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
    details, totals, floors = [], [], []
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
        details.append(f"{resolution:>4} meshing stages (s): {mesher}; {row['iterations']} "
                       f"iterations ({row['optimize_kernels']} passes); network on {row['device']}")
        totals.append((resolution, row["total"]))
        floors.append((resolution, row["network_queries"] * row["macs_per_query"]))
        queries = max(row["network_queries"], 1)
        network = row["udf"] - row["gap_fill_s"]
        rest = max(network - row["radius_s"], 1e-9)
        details.append(f"{resolution:>4} field: gap fill {row['gap_fill_s']:.2f} s "
                       f"({row['gap_nodes']:,} nodes set); {row['network_queries']:,} network "
                       f"queries, {1e6 * network / queries:.1f} us per query "
                       f"({1e6 * row['field_cpu_s'] / queries:.1f} us of process time per query "
                       f"with the band and gap fill, all threads), of which radius policy "
                       f"{1e6 * row['radius_s'] / queries:.1f} us: it adds "
                       f"{100 * row['radius_s'] / rest:.0f}% to the rest of the field's time "
                       + _policy_detail(row, queries, rest))
    if not args.no_poisson:
        child = subprocess.run([sys.executable, __file__, "--poisson-child", "--input", args.input],
                               capture_output=True, text=True, cwd=ROOT)
        if child.returncode != 0:
            print(f"poisson failed:\n{child.stderr.strip()}")
            return 1
        poisson = json.loads(child.stdout.strip().splitlines()[-1])
        print(f"poisson depth 9: {poisson['total']:.2f} s wall, {poisson['cpu_s']:.2f} cpu s, "
              f"{poisson['peak_gib']:.2f} GiB, {poisson['faces']:,} faces")
        for resolution, total in totals:
            print(f"{resolution:>4} ours / poisson: {total / poisson['total']:.2f}x wall")
    rate = multiply_add_rate(os.cpu_count() or 1)
    details.append(f"matrix product rate on {os.cpu_count()} threads: {rate / 1e9:.1f} G "
                   f"multiply-adds/s")
    for resolution, floor_macs in floors:
        details.append(f"{resolution:>4} field floor: {floor_macs / rate:.2f} s "
                       f"(network queries x multiply-adds per query / that rate)")
    print("\n".join(details))
    return 0


if __name__ == "__main__":
    sys.exit(main())
