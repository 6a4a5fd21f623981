"""How close two sheets may lie and still come out as two: the mesher on exact distances.

    python benchmarks/close_sheets.py [--resolution 96] [--gaps 1 1.5 2 2.5 3 4]

Two parallel squares (0.6 x 0.6) ``gap`` voxels apart, 0.235 voxel off the node planes, their
exact unsigned distance sampled on the grid (no network), meshed with the default settings.
Prints, per gap: the output's area over the two squares' area, the share of its faces within
0.3 voxel of a true sheet, and of those within 0.3 voxel of the plane midway, and the
double-layered share (engine.metrics.double_layer_share).
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.meshing import extract_surface  # noqa: E402
from engine.meshing import mesh_ops  # noqa: E402
from engine.metrics import double_layer_share  # noqa: E402
from lab import analytic  # noqa: E402

SIDE = 0.3  # half the squares' side
NEAR = 0.3  # voxels


def measure(resolution: int, gap: float) -> dict:
    h = 1.0 / (resolution - 1)
    off = 0.235 * h + 4 * h
    half = 0.5 * gap * h
    shape = analytic.union(analytic.rectangle((0, 0, off - half), half_u=SIDE, half_v=SIDE),
                           analytic.rectangle((0, 0, off + half), half_u=SIDE, half_v=SIDE))
    grid = analytic.sample_grid(shape, [-0.5] * 3, [0.5] * 3, resolution, exact=False)
    mesh = extract_surface(grid).mesh
    _, face_area = mesh_ops.face_normals(mesh.vertices, mesh.faces)
    height = (mesh.vertices[mesh.faces].mean(axis=1)[:, 2] - off) / h
    on_sheet = np.abs(np.abs(height) - 0.5 * gap) < NEAR
    midway = np.abs(height) < NEAR
    return {"gap": gap, "area": face_area.sum() / (2 * (2 * SIDE) ** 2),
            "on_sheets": float(face_area[on_sheet].sum() / face_area.sum()),
            "midway": float(face_area[midway].sum() / face_area.sum()),
            "double": double_layer_share(mesh.vertices, mesh.faces, h)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=96)
    parser.add_argument("--gaps", type=float, nargs="+", default=[1, 1.5, 2, 2.5, 3, 4])
    args = parser.parse_args()
    print(f"resolution {args.resolution}; area over two sheets', faces' area on a sheet and "
          f"midway (within {NEAR} voxel), double-layered share")
    print("| gap (voxels) | area / two sheets | on the sheets | midway | double % |")
    print("|---:|---:|---:|---:|---:|")
    for gap in args.gaps:
        row = measure(args.resolution, gap)
        print(f"| {gap:g} | {row['area']:.3f} | {100 * row['on_sheets']:.1f} % | "
              f"{100 * row['midway']:.1f} % | {100 * row['double']:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
