"""``python -m lab scale``: a generated floor of furnished rooms, scanned to millions of points,
reconstructed at a detail in metres in tiles, beside Open3D's screened Poisson on the same cloud
in the same run.

Examples::

    python -m lab scale --rooms 4 --points 1000000 --voxel-size 0.01 --out bench_results/scale
    python -m lab scale --report --out bench_results/scale      # the table of the JSON files
    python -m lab scale --rooms 4 --points 1000000 --write-cloud floor.ply   # the scan alone

Writes ``floor_<rooms>r_<points>p_<voxel>cm.json`` to ``--out`` and prints, for ours
(``--detail voxel_size``) and for Poisson: wall seconds, peak resident memory of the main
process and of the largest worker, the tiles, and Chamfer-L1 (cm), F1 at 5 mm, 1 cm and 2 cm and
normal consistency against the ground truth cropped to what the scan saw (faces within 5 cm of a
point; sampled room by room, :func:`truth_samples`, so that memory stays bounded on large
floors); and the scan's own floor: a second scan of the same floor, of the same size, scored the
same way (what a perfect reconstruction of this sampling would score). Each method runs in a
fresh child process so its peak memory is its own.
"""

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

THRESHOLDS = (0.005, 0.01, 0.02)  # metres
CROP = 0.05  # metres: ground truth farther than this from every scanned point is not scored
SAMPLES = 1_000_000


def build(rooms: int, points: int, seed: int, folder: Path):
    """Write the floor's scan, a second scan and the ground truth's samples as .npy files."""
    from .floor import make_floor, scan_floor

    _, parts = make_floor(rooms, seed)
    cloud, _ = scan_floor(parts, points, seed)
    again, _ = scan_floor(parts, points, seed + 1)
    np.save(folder / "cloud.npy", cloud)
    np.save(folder / "again.npy", again)
    truth, normals = truth_samples(parts, cloud, folder, np.random.default_rng(seed))
    np.savez(folder / "truth_samples.npz", points=truth, normals=normals)


def truth_samples(parts, cloud: np.ndarray, folder: Path, rng: np.random.Generator,
                  crop: float = CROP, samples: int = SAMPLES):
    """``samples`` points (and their normals) drawn by area over the ground truth cropped to
    what the scan saw (faces within ``crop`` of a point).

    The crop runs room by room: a room's scan sees no other room (they stand ``floor.PITCH``
    apart, with walls between), so this is the whole floor's crop, without ever holding the
    whole cropped floor (its faces are split to ``crop / 2``: gigabytes for a large floor).
    Each room's crop goes to ``folder`` while the areas are summed; the samples are then
    shared out between the rooms by area and drawn room by room.
    """
    from engine.sampling import face_areas_and_normals, sample_surface

    from .dataset import crop_to_input

    areas = []
    for number, (mesh, _) in enumerate(parts):
        low = mesh.vertices.min(axis=0) - crop
        high = mesh.vertices.max(axis=0) + crop
        seen = cloud[np.all((cloud >= low) & (cloud <= high), axis=1)]
        room = crop_to_input(mesh, seen, crop)
        areas.append(float(face_areas_and_normals(room.vertices, room.faces)[0].sum())
                     if len(room.faces) else 0.0)
        np.savez(folder / f"truth_room_{number}.npz", vertices=room.vertices, faces=room.faces)
    counts = rng.multinomial(samples, np.asarray(areas) / sum(areas))
    points, normals = [], []
    for number, count in enumerate(counts):
        room = np.load(folder / f"truth_room_{number}.npz")
        if count:
            drawn, drawn_normals, _ = sample_surface(room["vertices"], room["faces"], count, rng)
            points.append(drawn)
            normals.append(drawn_normals)
        (folder / f"truth_room_{number}.npz").unlink()
    return np.concatenate(points), np.concatenate(normals)


def write_cloud(rooms: int, points: int, seed: int, path: str) -> None:
    """The scan that :func:`build` makes, as a point cloud file (metres, z up)."""
    from engine.geometry import Mesh
    from engine.io import check_output_path, write_mesh

    from .floor import make_floor, scan_floor

    check_output_path(path)
    _, parts = make_floor(rooms, seed)
    cloud, _ = scan_floor(parts, points, seed)
    write_mesh(path, Mesh(cloud, np.zeros((0, 3), np.int64)))
    print(f"wrote {path}: {len(cloud):,} points of a floor of {rooms} rooms", file=sys.stderr)


def run_ours(folder: Path, voxel: float, tile_cells: int, workers: int) -> dict:
    from engine.reconstruct import reconstruct

    cloud = np.load(folder / "cloud.npy")
    started = time.perf_counter()
    result = reconstruct(cloud, dict(detail="voxel_size", voxel_size=voxel,
                                     tile_cells=tile_cells, workers=workers))
    seconds = time.perf_counter() - started
    np.savez(folder / "ours.npz", vertices=result.mesh.vertices, faces=result.mesh.faces)
    return {"seconds": seconds, "tiles": result.stats.get("tiles", 1),
            "workers": result.stats.get("workers", 1), "faces": result.stats["faces"],
            "cells": result.stats["cells"]}


def run_poisson(folder: Path, depth: int) -> dict:
    from engine.geometry import PointCloud
    from .methods import make_poisson

    cloud = np.load(folder / "cloud.npy")
    started = time.perf_counter()
    mesh = make_poisson(depth=depth)(PointCloud(cloud))
    seconds = time.perf_counter() - started
    np.savez(folder / "poisson.npz", vertices=mesh.vertices, faces=mesh.faces)
    return {"seconds": seconds, "tiles": 1, "workers": 1, "faces": int(len(mesh.faces))}


def child(args) -> None:
    """One method in this (child) process; prints its figures as JSON."""
    from .harness import _status_kb

    folder = Path(args.work)
    if args.child == "ours":
        figures = run_ours(folder, args.voxel_size, args.tile_cells, args.workers)
    else:
        figures = run_poisson(folder, args.poisson_depth)
    # VmHWM starts afresh at exec; ru_maxrss would carry this process's parent's size at the
    # fork
    peak_kb = _status_kb("VmHWM")
    self = (peak_kb if peak_kb is not None
            else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) / 2 ** 20
    workers = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2 ** 20
    print(json.dumps({**figures, "peak_gib": self, "worker_peak_gib": workers}))


def score(vertices, faces, truth, seed: int = 0) -> dict:
    """A mesh against the truth's samples (``truth_samples.npz``): CD, F1 and NC, in cm."""
    from engine.metrics import chamfer_f_nc
    from engine.sampling import sample_surface

    pred, pred_n, _ = sample_surface(vertices, faces, SAMPLES, np.random.default_rng(seed))
    return _in_cm(chamfer_f_nc(pred, pred_n, truth["points"], truth["normals"], THRESHOLDS))


def _in_cm(scores: dict) -> dict:
    out = {"cd_cm": scores["cd_l1_x100"], "nc": scores["nc"]}
    out.update({f"f1_{t * 100:g}cm": scores[f"f1_{t:g}"] for t in THRESHOLDS})
    return out


def scan_floor_score(folder: Path, truth) -> dict:
    """The second scan, as points, against the truth's samples (normals not scored)."""
    from scipy.spatial import cKDTree

    again = np.load(folder / "again.npy")
    gt = truth["points"]
    acc = cKDTree(gt).query(again, workers=-1)[0]
    comp = cKDTree(again).query(gt, workers=-1)[0]
    out = {"cd_cm": 0.5 * (acc.mean() + comp.mean()) * 100.0}
    for t in THRESHOLDS:
        p, r = np.mean(acc <= t), np.mean(comp <= t)
        out[f"f1_{t * 100:g}cm"] = 2 * p * r / (p + r) if p + r else 0.0
    return out


COLUMNS = ("seconds", "peak_gib", "worker_peak_gib", "tiles", "cd_cm", "f1_0.5cm", "f1_1cm",
           "f1_2cm", "nc")


def add_arguments(parser) -> None:
    """Register the command's arguments on an ``argparse`` parser."""
    parser.add_argument("--rooms", type=int, default=4)
    parser.add_argument("--points", type=int, default=1_000_000)
    parser.add_argument("--voxel-size", type=float, default=0.01, help="metres")
    parser.add_argument("--tile-cells", type=int, default=0, help="0: automatic")
    parser.add_argument("--workers", type=int, default=0, help="0: every core")
    parser.add_argument("--poisson-depth", type=int, default=10)
    parser.add_argument("--no-poisson", action="store_true")
    parser.add_argument("--seed", type=int, default=0, help="the floor's and the scan's")
    parser.add_argument("--work", default="out/bench_scale", help="folder for the clouds")
    parser.add_argument("--out", default="bench_results/scale", help="folder for the JSON")
    parser.add_argument("--report", action="store_true",
                        help="print the table of the JSON files in --out; run nothing")
    parser.add_argument("--write-cloud", metavar="PLY",
                        help="write the floor's scan (--rooms, --points, --seed) as a point "
                             "cloud file for Blender or the CLI, and run nothing else")
    parser.add_argument("--child", choices=("ours", "poisson"), help=argparse.SUPPRESS)


def run(args) -> int:
    if args.child:
        child(args)
        return 0
    out = Path(args.out)
    if args.report:
        print(report(sorted(out.glob("floor_*.json"))), end="")
        return 0
    if args.write_cloud:
        write_cloud(args.rooms, args.points, args.seed, args.write_cloud)
        return 0
    folder = Path(args.work)
    folder.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    build(args.rooms, args.points, args.seed, folder)
    print(f"floor of {args.rooms} rooms, {args.points:,} points: built in "
          f"{time.perf_counter() - started:.0f} s", file=sys.stderr, flush=True)
    truth = dict(np.load(folder / "truth_samples.npz"))
    rows = {"scan's own floor": scan_floor_score(folder, truth)}
    for method in ["ours"] + ([] if args.no_poisson else ["poisson"]):
        command = [sys.executable, "-m", "lab", "scale", "--child", method, "--work",
                   str(folder.resolve()), "--voxel-size", str(args.voxel_size), "--tile-cells",
                   str(args.tile_cells), "--workers", str(args.workers), "--poisson-depth",
                   str(args.poisson_depth)]
        done = subprocess.run(command, capture_output=True, text=True, check=True, cwd=ROOT)
        figures = json.loads(done.stdout.strip().splitlines()[-1])
        mesh = np.load(folder / f"{method}.npz")
        figures.update(score(mesh["vertices"], mesh["faces"], truth))
        name = (f"ours (voxel {args.voxel_size * 100:g} cm)" if method == "ours"
                else f"poisson (depth {args.poisson_depth})")
        rows[name] = figures
        print(name, json.dumps(figures), file=sys.stderr, flush=True)
    out.mkdir(parents=True, exist_ok=True)
    name = f"floor_{args.rooms}r_{args.points}p_{args.voxel_size * 100:g}cm.json"
    settings = {key: value for key, value in vars(args).items() if key not in ("child", "report")}
    (out / name).write_text(json.dumps({"settings": settings, "rows": rows}, indent=1))
    print(report([out / name]), end="")
    return 0


def report(paths) -> str:
    """One markdown table of the runs in ``paths`` (JSON files written by :func:`run`)."""
    lines = ["| floor | | " + " | ".join(COLUMNS) + " |",
             "|---" * (len(COLUMNS) + 2) + "|"]
    for path in paths:
        run_data = json.loads(Path(path).read_text())
        settings = run_data["settings"]
        floor = f"{settings['rooms']} rooms, {settings['points']:,} points"
        for name, row in run_data["rows"].items():
            cells = [_cell(row.get(column)) for column in COLUMNS]
            lines.append(f"| {floor} | {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _cell(value) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return f"{value:.1f}" if value >= 10 else f"{value:.3f}"
    return str(value)
