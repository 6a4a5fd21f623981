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
point; cropped and sampled room by room, :func:`truth_samples`, so that memory stays bounded on
large floors), by exact point-to-triangle distances both ways (:func:`score`); and the scan's
own floor: a second scan of the same floor, of the same size, scored the same way as points
(what a perfect reconstruction of this sampling would score). Each method runs in a
fresh child process so its peak memory is its own; ours writes its mesh to a PLY file as the
CLI does (:func:`engine.reconstruct_to_file.reconstruct_to_file`: tile by tile), and the
scoring reads it back.
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

THRESHOLDS = (0.005, 0.01, 0.02)  # metres
CROP = 0.05  # metres: ground truth farther than this from every scanned point is not scored
SAMPLES = 1_000_000
MARGIN = 0.25  # metres: rooms stand at least twice this apart (floor.PITCH)


def build(rooms: int, points: int, seed: int, folder: Path):
    """Write the floor's scan, a second scan and the ground truth's samples as .npy files."""
    from .floor import make_floor, scan_floor

    _, parts = make_floor(rooms, seed)
    cloud, _ = scan_floor(parts, points, seed)
    again, _ = scan_floor(parts, points, seed + 1)
    np.save(folder / "cloud.npy", cloud)
    np.save(folder / "again.npy", again)
    truth, normals, rooms = truth_samples(parts, cloud, folder, np.random.default_rng(seed),
                                          samples=SAMPLES)
    np.savez(folder / "truth_samples.npz", points=truth, normals=normals, room=rooms)


def truth_samples(parts, cloud: np.ndarray, folder: Path, rng: np.random.Generator,
                  crop: float = CROP, samples: int = SAMPLES):
    """``samples`` points (and their normals and rooms) drawn by area over the ground truth
    cropped to what the scan saw (faces within ``crop`` of a point).

    The crop runs room by room: a room's scan sees no other room (they stand ``floor.PITCH``
    apart, with walls between), so this is the whole floor's crop, without ever holding the
    whole cropped floor (its faces are split to ``crop / 2``: gigabytes for a large floor).
    Each room's crop is written to ``folder`` (:func:`room_crop_path`, read again by
    :func:`score`) while the areas are summed; the samples are then shared out between the
    rooms by area and drawn room by room.

    Returns points (S, 3), normals (S, 3) and each sample's room (S,).
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
        np.savez(room_crop_path(folder, number), vertices=room.vertices, faces=room.faces)
    counts = rng.multinomial(samples, np.asarray(areas) / sum(areas))
    points, normals = [], []
    for number, count in enumerate(counts):
        room = np.load(room_crop_path(folder, number))
        if count:
            drawn, drawn_normals, _ = sample_surface(room["vertices"], room["faces"], count, rng)
            points.append(drawn)
            normals.append(drawn_normals)
    rooms = np.repeat(np.arange(len(counts)), counts)
    return np.concatenate(points), np.concatenate(normals), rooms


def room_crop_path(folder: Path, number: int) -> Path:
    """Where :func:`truth_samples` keeps room ``number``'s cropped ground truth."""
    return Path(folder) / f"truth_room_{number}.npz"


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


def run_ours(folder: Path, voxel: float, tile_cells: int, workers: int,
             udf_source: str = "network") -> dict:
    """Ours as the CLI runs it: into a PLY file, tile by tile when tiled; fixed radius."""
    from engine.reconstruct_to_file import reconstruct_to_file

    cloud = np.load(folder / "cloud.npy")
    started = time.perf_counter()
    result = reconstruct_to_file(cloud, ours_path(folder, udf_source),
                                 dict(detail="voxel_size", voxel_size=voxel,
                                      tile_cells=tile_cells, workers=workers,
                                      udf_source=udf_source, radius_mode="fixed"))
    seconds = time.perf_counter() - started
    return {"seconds": seconds, "tiles": result.stats.get("tiles", 1),
            "workers": result.stats.get("workers", 1), "faces": result.stats["faces"],
            "cells": result.stats["cells"],
            "worker_peak_gib": (result.stats["tile_peak_bytes"] / 2 ** 30
                                if "tile_peak_bytes" in result.stats else None)}


def ours_path(folder: Path, udf_source: str) -> Path:
    """Where ours is written in the work folder: a file per ``--udf-source``."""
    return folder / ("ours_nearest.ply" if udf_source == "nearest" else "ours.ply")


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
    """One method in this (child) process; prints its figures as JSON, with ``rss_trace``:
    this process's resident memory (GiB) every :data:`TRACE_SECONDS` seconds, as
    ``[seconds, GiB]`` pairs (empty where /proc cannot be read)."""
    import threading

    from engine.tile_runners import process_peak_bytes, process_resident_bytes

    folder = Path(args.work)
    trace, done = [], threading.Event()
    started = time.perf_counter()

    def sample() -> None:
        while True:
            resident = process_resident_bytes()
            if resident:
                trace.append([round(time.perf_counter() - started, 1),
                              round(resident / 2 ** 30, 3)])
            if done.wait(TRACE_SECONDS):
                return

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    if args.child == "ours":
        figures = run_ours(folder, args.voxel_size, args.tile_cells, args.workers,
                           args.udf_source)
    else:
        figures = run_poisson(folder, args.poisson_depth)
    done.set()
    sampler.join()
    # this process's own peak (VmHWM starts afresh at exec); the workers report theirs
    print(json.dumps({"worker_peak_gib": None, **figures,
                      "peak_gib": process_peak_bytes() / 2 ** 30, "rss_trace": trace}))


TRACE_SECONDS = 5.0

NEAREST = {"network": "", "nearest": ", nearest-point field"}
"""What the row's name adds for each ``--udf-source``."""


def score(vertices, faces, folder: Path, truth, seed: int = 0) -> dict:
    """A mesh against the cropped ground truth: CD, F1 and NC, in cm.

    Distances are exact, point to triangle (:func:`closest_on_mesh`), both ways: from
    ``SAMPLES`` points on the mesh to the rooms' crops (accuracy), and from the truth's samples
    to the mesh (completeness). A nearest-sample distance would read the sampling as well: a
    million samples over a floor of four rooms lie about 2 cm apart, so a perfect mesh would
    lose F1 at 1 cm that way.
    """
    from engine.sampling import sample_surface

    pred, pred_normals, _ = sample_surface(vertices, faces, SAMPLES,
                                           np.random.default_rng(seed))
    accuracy, truth_normals = distance_to_rooms(pred, folder)
    completeness, mesh_normals = distance_to_mesh_by_room(truth, vertices, faces, folder)
    scores = _distances_to_scores(accuracy, completeness)
    scores["nc"] = float(0.5 * (np.abs(np.sum(pred_normals * truth_normals, axis=1)).mean()
                                + np.abs(np.sum(truth["normals"] * mesh_normals, axis=1)).mean()))
    return scores


def distance_to_rooms(points: np.ndarray, folder: Path):
    """Exact distance from each point to the cropped ground truth of all the rooms, with the
    normal of the closest truth face.

    A point within ``MARGIN`` of a room's box is measured against that room alone; nearer
    another room it cannot be (the rooms stand farther apart), so this is exact wherever the
    distance is below ``MARGIN``. A point near no room's box is measured against every room.
    """
    from .surface_distance import closest_on_mesh

    distances = np.full(len(points), np.inf)
    normals = np.zeros((len(points), 3))
    boxes = _room_boxes(folder)
    rooms = len(boxes)
    near_any = np.zeros(len(points), bool)
    for number in range(rooms):
        room = np.load(room_crop_path(folder, number))
        low, high = boxes[number]
        near = np.all((points >= low - MARGIN) & (points <= high + MARGIN), axis=1)
        near_any |= near
        found, found_normals = closest_on_mesh(points[near], room["vertices"], room["faces"])
        _keep_closer(distances, normals, np.flatnonzero(near), found, found_normals)
    far = np.flatnonzero(~near_any)
    for number in range(rooms if len(far) else 0):
        room = np.load(room_crop_path(folder, number))
        found, found_normals = closest_on_mesh(points[far], room["vertices"], room["faces"])
        _keep_closer(distances, normals, far, found, found_normals)
    return distances, normals


def distance_to_mesh_by_room(truth, vertices, faces, folder: Path):
    """Exact distance from each truth sample to the mesh, with the normal of the closest mesh
    face. A room's samples are measured against the mesh's faces that reach within ``MARGIN``
    of the room's box, so the whole mesh is never in one search structure; exact wherever the
    distance is below ``MARGIN`` (a farther face lies outside the margin)."""
    from .surface_distance import closest_on_mesh

    points = truth["points"]
    distances = np.full(len(points), np.inf)
    normals = np.zeros((len(points), 3))
    corners = vertices[faces]
    face_low, face_high = corners.min(axis=1), corners.max(axis=1)
    del corners
    for number, (low, high) in enumerate(_room_boxes(folder)):
        mine = np.flatnonzero(truth["room"] == number)
        reach = np.all((face_high >= low - MARGIN) & (face_low <= high + MARGIN), axis=1)
        found, found_normals = closest_on_mesh(points[mine], vertices, faces[reach])
        distances[mine], normals[mine] = found, found_normals
    return distances, normals


def _keep_closer(distances, normals, where, found, found_normals) -> None:
    closer = found < distances[where]
    distances[where[closer]] = found[closer]
    normals[where[closer]] = found_normals[closer]


def _room_boxes(folder: Path) -> list:
    """The bounding box of each room's cropped truth, in room order."""
    boxes = []
    while room_crop_path(folder, len(boxes)).exists():
        vertices = np.load(room_crop_path(folder, len(boxes)))["vertices"]
        boxes.append((vertices.min(axis=0), vertices.max(axis=0)))
    return boxes


def _distances_to_scores(accuracy: np.ndarray, completeness: np.ndarray) -> dict:
    """CD-L1 and the F1 at ``THRESHOLDS`` from the two ways' distances (metres), in cm."""
    out = {"cd_cm": float(0.5 * (accuracy.mean() + completeness.mean()) * 100.0)}
    for t in THRESHOLDS:
        p, r = np.mean(accuracy <= t), np.mean(completeness <= t)
        out[f"f1_{t * 100:g}cm"] = float(2 * p * r / (p + r)) if p + r else 0.0
    return out


def scan_floor_score(folder: Path, truth) -> dict:
    """The second scan, as points, against the cropped ground truth (normals not scored): each
    point's exact distance to the truth, and each truth sample's distance to the nearest
    point."""
    from scipy.spatial import cKDTree

    again = np.load(folder / "again.npy")
    accuracy, _ = distance_to_rooms(again, folder)
    completeness = cKDTree(again).query(truth["points"], workers=-1)[0]
    return _distances_to_scores(accuracy, completeness)


COLUMNS = ("seconds", "peak_gib", "worker_peak_gib", "tiles", "faces", "cd_cm", "f1_0.5cm",
           "f1_1cm", "f1_2cm", "nc")


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
    parser.add_argument("--work", default="out/bench_scale",
                        help="folder for the clouds and the truth; a floor built there before "
                             "with the same --rooms, --points and --seed is reused")
    parser.add_argument("--out", default="bench_results/scale", help="folder for the JSON")
    parser.add_argument("--rescore", action="store_true",
                        help="score again the meshes the run with these settings left in "
                             "--work, and update its JSON's scores (its time and memory "
                             "stay); run nothing else")
    parser.add_argument("--report", action="store_true",
                        help="print the table of the JSON files in --out; run nothing")
    parser.add_argument("--write-cloud", metavar="PLY",
                        help="write the floor's scan (--rooms, --points, --seed) as a point "
                             "cloud file for Blender or the CLI, and run nothing else")
    parser.add_argument("--udf-source", choices=("network", "nearest"), default="network",
                        help="nearest: the distance to the nearest point instead of the "
                             "network, to exercise tiling and stitching at scale in less time "
                             "(a rougher surface; its own JSON file and row)")
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
    floor = {"rooms": args.rooms, "points": args.points, "seed": args.seed}
    built = folder / "floor.json"
    if built.exists() and json.loads(built.read_text()) == floor:
        print(f"floor of {args.rooms} rooms, {args.points:,} points: reusing {folder}",
              file=sys.stderr, flush=True)
    else:
        built.unlink(missing_ok=True)
        build(args.rooms, args.points, args.seed, folder)
        built.write_text(json.dumps(floor))  # written last: the folder is complete
        print(f"floor of {args.rooms} rooms, {args.points:,} points: built in "
              f"{time.perf_counter() - started:.0f} s", file=sys.stderr, flush=True)
    truth = dict(np.load(folder / "truth_samples.npz"))
    name = (f"floor_{args.rooms}r_{args.points}p_{args.voxel_size * 100:g}cm"
            f"{'_nearest' if args.udf_source == 'nearest' else ''}.json")
    if args.rescore:
        return rescore(args, folder, truth, out / name)
    rows = {"scan's own floor": scan_floor_score(folder, truth)}
    for method in ["ours"] + ([] if args.no_poisson else ["poisson"]):
        command = [sys.executable, "-m", "lab", "scale", "--child", method, "--work",
                   str(folder.resolve()), "--voxel-size", str(args.voxel_size), "--tile-cells",
                   str(args.tile_cells), "--workers", str(args.workers), "--poisson-depth",
                   str(args.poisson_depth), "--udf-source", args.udf_source]
        done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT)
        if done.returncode:
            sys.stderr.write(done.stderr[-4000:])
            print(f"{method} failed (exit status {done.returncode}); its last output is above",
                  file=sys.stderr)
            return 1
        figures = json.loads(done.stdout.strip().splitlines()[-1])
        made = {key: value for key, value in figures.items() if key != "rss_trace"}
        print(f"{method} made, scoring: {json.dumps(made)}", file=sys.stderr, flush=True)
        figures.update(score_made(method, folder, truth, args.udf_source))
        row = row_name(method, args)
        rows[row] = figures
        shown = {key: value for key, value in figures.items() if key != "rss_trace"}
        print(row, json.dumps(shown), file=sys.stderr, flush=True)
    out.mkdir(parents=True, exist_ok=True)
    settings = {key: value for key, value in vars(args).items()
                if key not in ("child", "report", "rescore")}
    (out / name).write_text(json.dumps({"settings": settings, "rows": rows}, indent=1))
    print(report([out / name]), end="")
    return 0


def row_name(method: str, args) -> str:
    """The table's row for ``method`` (ours or poisson) run with ``args``."""
    if method == "ours":
        return f"ours (voxel {args.voxel_size * 100:g} cm{NEAREST[args.udf_source]})"
    return f"poisson (depth {args.poisson_depth})"


def score_made(method: str, folder: Path, truth, udf_source: str) -> dict:
    """The scores of the mesh ``method`` left in the work folder."""
    if method == "ours":
        from engine.io import read_mesh

        mesh = read_mesh(ours_path(folder, udf_source))
        vertices, faces = mesh.vertices, mesh.faces
    else:
        mesh = np.load(folder / "poisson.npz")
        vertices, faces = mesh["vertices"], mesh["faces"]
    del mesh
    return score(vertices, faces, folder, truth)


def rescore(args, folder: Path, truth, path: Path) -> int:
    """Score again the meshes a run left in the work folder (after a change to the scoring),
    keeping the run's time and memory figures in its JSON file ``path``."""
    if not path.exists():
        print(f"--rescore: no {path} to update; run the benchmark first", file=sys.stderr)
        return 1
    run_file = json.loads(path.read_text())
    rows = run_file["rows"]
    rows["scan's own floor"] = scan_floor_score(folder, truth)
    for method in ("ours", "poisson"):
        row = row_name(method, argparse.Namespace(**run_file["settings"]))
        made = (ours_path(folder, args.udf_source) if method == "ours"
                else folder / "poisson.npz")
        if row not in rows:
            continue
        if not made.exists():
            print(f"--rescore: {made} is missing; {row} keeps its scores", file=sys.stderr)
            continue
        rows[row].update(score_made(method, folder, truth, args.udf_source))
        print(row, "rescored", file=sys.stderr, flush=True)
    path.write_text(json.dumps(run_file, indent=1))
    print(report([path]), end="")
    return 0


def report(paths) -> str:
    """One markdown table of the runs in ``paths`` (JSON files written by :func:`run`), the
    smallest floor first."""
    lines = ["| floor | | " + " | ".join(COLUMNS) + " |",
             "|---" * (len(COLUMNS) + 2) + "|"]
    runs = [json.loads(Path(path).read_text()) for path in paths]
    runs.sort(key=lambda run_data: (run_data["settings"]["rooms"],
                                    run_data["settings"]["points"]))
    for run_data in runs:
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
    return f"{value:,}" if isinstance(value, int) else str(value)
