"""Narrow strips between open rims: a grille of 4 x 4 round holes in a square plate, the holes
growing until the bars between them and the strips between the outer holes and the plate's edge
are a few voxels wide. Meshed from the sampled exact distances (``lab.analytic``); prints the
mesh's area against the truth, its pieces and boundary loops (one piece with 17 loops is right)
and the share of the truth farther than a voxel from the mesh, on the bars and on the edge
strips.

    python benchmarks/narrow_strips.py [--resolution 128] [--radii 0.05 0.06 0.07 0.075 0.08]
"""

import argparse

import numpy as np

HALF, HOLES, Z = 0.35, 4, 0.004  # the plate: side 2 HALF, in the plane z = Z
SAMPLES = 100_000


def main() -> None:
    from scipy.spatial import cKDTree

    from engine.meshing import extract_surface, mesh_ops
    from engine.sampling import sample_surface
    from lab import analytic

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--radii", type=float, nargs="+", default=[0.05, 0.06, 0.07, 0.075, 0.08])
    args = parser.parse_args()
    spacing = 1.0 / (args.resolution - 1)
    pitch = 2 * HALF / HOLES
    centres = -HALF + pitch * (np.arange(HOLES) + 0.5)
    middles = np.stack(np.meshgrid(centres, centres), -1).reshape(-1, 2)
    rng = np.random.default_rng(0)
    print("| hole radius | bars (voxels) | edge strips (voxels) | area / truth | pieces | "
          "boundary loops | truth > 1 voxel from the mesh: bars | edge strips |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for radius in args.radii:
        shape = analytic.perforated_plate((0, 0, Z), HALF, HOLES, radius)
        grid = analytic.sample_grid(shape, [-0.5] * 3, [0.5] * 3, args.resolution, exact=False)
        mesh = extract_surface(grid).mesh
        truth_area = (2 * HALF) ** 2 - HOLES * HOLES * np.pi * radius ** 2
        area = mesh_ops.face_normals(mesh.vertices, mesh.faces)[1].sum()
        plate = rng.uniform(-HALF, HALF, (SAMPLES, 2))
        plate = plate[np.linalg.norm(plate[:, None] - middles[None], axis=2).min(axis=1) > radius]
        edge_strip = (HALF - np.abs(plate)).min(axis=1) < HALF - centres[-1] - radius
        on_mesh = sample_surface(mesh.vertices, mesh.faces, 10 * SAMPLES, rng)[0]
        gap = cKDTree(on_mesh).query(np.c_[plate, np.full(len(plate), Z)])[0] / spacing
        print(f"| {radius:g} | {(pitch - 2 * radius) / spacing:.1f} "
              f"| {(HALF - centres[-1] - radius) / spacing:.1f} | {area / truth_area:.3f} "
              f"| {mesh_ops.vertex_components(len(mesh.vertices), mesh.faces)[0]} "
              f"| {mesh_ops.boundary_loops(mesh.faces)} "
              f"| {100 * (gap[~edge_strip] > 1).mean():.1f} % "
              f"| {100 * (gap[edge_strip] > 1).mean():.1f} % |", flush=True)


if __name__ == "__main__":
    main()
