"""Where a reconstruction's area differs from the truth's: the true surface it misses, by cause.

    python benchmarks/area_breakdown.py DOMAIN CONDITION [--seed 1000000] [--radius-mode fixed]
        [--resolution 256] [--mesh saved.npz] [--truth-udf]

DOMAIN ``real`` takes the ``--seed``-th mesh of ``lab.bench.dataset.REAL_SHAPES`` (0-11).

Reconstructs one test shape of the benchmark (``lab.bench.dataset``) as ``python -m lab bench``
does (rooms: both meshes cropped as the benchmark crops them), then samples the true surface and
splits the share of it that lies farther than 0.5, 1 and 2 grid spacings from the mesh into:

* **rim**: within 3 spacings of the truth's open boundary (a garment's hems, a room's crop edge);
* **close sheets**: where another sheet of the truth lies within 2.5 spacings: a sample of the
  truth there, its normal within 6 degrees of this one's either way, more than 0.25 spacing off
  the tangent plane (a car's panels, a shelf's board, a pocket on a shirt; no bend passes that
  test). Two sheets that close come out as one from a grid that coarse
  (``benchmarks/close_sheets.py``);
* **junctions**: within 4 spacings of another part of the truth (its vertex-connected pieces: a
  car's cabin crossing its body, a tyre in its arch, seats on the floor pan); the mesh rounds
  the crossing there;
* **elsewhere**: holes in the open.

It also prints the share of the mesh farther than one spacing from the truth, the area
ratio against the truth with its close sheets counted once (area x (1 - close share / 2)), and
where extra area lies: the mesh's and the truth's area within 1, 2, 4 and 8 spacings of the
truth's open boundary, with both boundaries' lengths; where the mesh's open boundary lies (its
length near the truth's rim, its close sheets, its junctions or elsewhere: a boundary away from
the truth's rim is a slit or a hole a user sees); the pieces of both; and the mesh's vertices
standing more than 1 and 2 spacings off the truth (exact distances), grouped by the mesh's
edges into clusters, with those on the open boundary (the tabs a render shows along a rim).
``--mesh`` reads (or, the first time, writes) the reconstruction as an ``.npz`` with ``v`` and ``f``.
``--truth-udf`` meshes the truth's exact distances on the same band instead of the network's
(``lab.bench.truth_udf``): what the mesher makes of a perfect field.
"""

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from engine.frame import UnitFrame  # noqa: E402
from engine.geometry import Mesh  # noqa: E402
from engine.meshing import mesh_ops  # noqa: E402
from engine.reconstruct import reconstruct  # noqa: E402
from engine.sampling import sample_surface  # noqa: E402
from lab.bench import dataset  # noqa: E402
from lab.bench.harness import DEFAULT_CROP_MAX_DIST  # noqa: E402
from lab.bench.truth_udf import make_truth_udf  # noqa: E402

RIM = 3.0  # spacings
JUNCTION = 4.0  # spacings from another part of the truth
CLOSE = 2.5  # spacings: another sheet this near ...
OFF_PLANE = 0.25  # ... this far off the tangent plane ...
PARALLEL = 0.995  # ... with its normal within 6 degrees of the sample's, either way
SAMPLES = 300_000


def close_sheet_mask(points, normals, spacing, chunk=10_000):
    """Samples with another sample within CLOSE spacings lying OFF_PLANE spacings off their
    tangent plane, its normal parallel to theirs (PARALLEL) either way."""
    tree = cKDTree(points)
    out = np.zeros(len(points), bool)
    for start in range(0, len(points), chunk):
        p, n = points[start:start + chunk], normals[start:start + chunk]
        near = tree.query_ball_point(p, CLOSE * spacing, workers=-1)
        rows = np.repeat(np.arange(len(p)), [len(j) for j in near])
        cols = np.concatenate([np.asarray(j, np.int64) for j in near])
        off = np.abs(np.einsum("nc,nc->n", points[cols] - p[rows], n[rows]))
        parallel = np.abs(np.einsum("nc,nc->n", normals[cols], n[rows])) > PARALLEL
        hit = rows[parallel & (off > OFF_PLANE * spacing)]
        out[start + hit] = True
    return out


def junction_mask(points, part, spacing, chunk=10_000):
    """Samples with a sample of another part (``part``: (n,) labels) within JUNCTION spacings."""
    tree = cKDTree(points)
    out = np.zeros(len(points), bool)
    for start in range(0, len(points), chunk):
        near = tree.query_ball_point(points[start:start + chunk], JUNCTION * spacing, workers=-1)
        rows = np.repeat(np.arange(len(near)), [len(j) for j in near])
        cols = np.concatenate([np.asarray(j, np.int64) for j in near])
        out[start + np.unique(rows[part[cols] != part[start + rows]])] = True
    return out


def rim_distance(vertices, faces, points):
    """Distance from each point to the mesh's open boundary (its edges sampled 8 times)."""
    topo = mesh_ops.edge_topology(faces)
    edges = topo.edges[topo.counts == 1]
    if not len(edges):
        return np.full(len(points), np.inf)
    t = np.linspace(0.0, 1.0, 8)[:, None, None]
    on_edges = (vertices[edges[:, 0]] * (1 - t) + vertices[edges[:, 1]] * t).reshape(-1, 3)
    return cKDTree(on_edges).query(points, workers=-1)[0]


def boundary_length(vertices, faces) -> float:
    topo = mesh_ops.edge_topology(faces)
    edges = topo.edges[topo.counts == 1]
    return float(np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1).sum())


def print_boundaries(pv, pf, tv, tf, points, kinds, spacing):
    """The mesh's open boundary, its length (spacings) split by the kind of the truth sample
    nearest each edge's midpoint (``kinds``: name -> mask over ``points``), and the pieces of
    the mesh and the truth."""
    topo = mesh_ops.edge_topology(pf)
    edges = topo.edges[topo.counts == 1]
    length = np.linalg.norm(pv[edges[:, 0]] - pv[edges[:, 1]], axis=1) / spacing
    nearest = cKDTree(points).query((pv[edges[:, 0]] + pv[edges[:, 1]]) / 2, workers=-1)[1]
    print("| mesh's open boundary (spacings) | all | "
          + " | ".join(f"near the truth's {name}" for name in kinds) + " |")
    print("|---|---:|" + "---:|" * len(kinds))
    print(f"| length | {length.sum():.0f} | "
          + " | ".join(f"{length[mask[nearest]].sum():.0f}" for mask in kinds.values()) + " |")
    for name, (v, f) in (("truth", (tv, tf)), ("mesh", (pv, pf))):
        count, label = mesh_ops.vertex_components(len(v), f)
        faces = np.bincount(label, minlength=count)
        print(f"{name}: {count} pieces, {int((faces < 100).sum())} of them under 100 faces")


def print_standing_off(pv, pf, tv, tf, spacing):
    """The mesh's vertices more than 1 and 2 spacings from the truth, and their clusters (joined
    by the mesh's edges), those with a vertex on the open boundary counted apart."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from lab.bench.surface_distance import closest_on_mesh

    off = closest_on_mesh(pv, tv, tf)[0] / spacing
    topo = mesh_ops.edge_topology(pf)
    on_boundary = np.zeros(len(pv), bool)
    on_boundary[topo.edges[topo.counts == 1].reshape(-1)] = True
    for limit in (1.0, 2.0):
        far = off > limit
        edges = topo.edges[far[topo.edges[:, 0]] & far[topo.edges[:, 1]]]
        graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])),
                           shape=(len(pv), len(pv)))
        label = connected_components(graph, directed=False)[1]
        clusters = np.unique(label[far])
        rim = np.unique(label[far & on_boundary])
        unit = "spacing" if limit == 1 else "spacings"
        print(f"mesh vertices more than {limit:g} {unit} off the truth: {int(far.sum())}, in "
              f"{len(clusters)} clusters, {len(rim)} of them on the open boundary")


def print_rim_area(tv, tf, pv, pf, on_truth, on_pred, area_ratio, spacing):
    """The mesh's and the truth's area near the truth's open boundary, as shares of the truth's
    area (``on_truth``, ``on_pred``: uniform samples of each; the mesh's share is scaled by
    ``area_ratio``)."""
    print(f"open boundary: truth {boundary_length(tv, tf) / spacing:.0f} spacings long, mesh "
          f"{boundary_length(pv, pf) / spacing:.0f}")
    to_truth = rim_distance(tv, tf, on_truth) / spacing
    to_pred = rim_distance(tv, tf, on_pred) / spacing
    print("| within the truth's rim | truth's area | mesh's area |")
    print("|---|---:|---:|")
    for limit in (1.0, 2.0, 4.0, 8.0, np.inf):
        print(f"| {limit:g} spacings | {(to_truth < limit).mean():.4f} | "
              f"{area_ratio * (to_pred < limit).mean():.4f} |")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("domain", choices=dataset.DOMAINS + (dataset.REAL,))
    parser.add_argument("condition", choices=("clean", "sparse", "noisy"))
    parser.add_argument("--seed", type=int, default=1_000_000)
    parser.add_argument("--radius-mode", default="fixed")
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--mesh", help="an .npz to read the reconstruction from, or write it to")
    parser.add_argument("--truth-udf", action="store_true",
                        help="mesh the truth's exact distances instead of the network's")
    args = parser.parse_args()

    truth = dataset.make_shape(args.domain, args.seed)
    cloud = dataset.make_input(truth, args.domain, args.condition, args.seed)
    if args.mesh and os.path.exists(args.mesh):
        saved = np.load(args.mesh)
        pred = Mesh(saved["v"], saved["f"])
    else:
        start = time.perf_counter()
        if args.truth_udf:
            pred = make_truth_udf(args.resolution)(cloud, truth)
        else:
            pred = reconstruct(np.asarray(cloud.points), {"resolution": args.resolution,
                                                          "radius_mode": args.radius_mode}).mesh
        print(f"reconstructed in {time.perf_counter() - start:.0f} s")
        if args.mesh:
            np.savez(args.mesh, v=pred.vertices, f=pred.faces)
    frame = UnitFrame.from_points(np.asarray(truth.vertices, np.float64))
    if args.domain == "rooms":
        visible = dataset.make_input(truth, args.domain, "clean", args.seed)
        truth = dataset.crop_to_input(truth, visible.points, DEFAULT_CROP_MAX_DIST,
                                      visible.normals)
        pred = dataset.crop_to_input(pred, np.asarray(cloud.points), DEFAULT_CROP_MAX_DIST)
    tv, tf = frame.to_unit(np.asarray(truth.vertices, np.float64)), np.asarray(truth.faces)
    pv, pf = frame.to_unit(np.asarray(pred.vertices, np.float64)), np.asarray(pred.faces)
    spacing = 1.0 / args.resolution
    rng = np.random.default_rng(0)
    points, normals, sampled_face = sample_surface(tv, tf, SAMPLES, rng)
    part = mesh_ops.vertex_components(len(tv), tf)[1][sampled_face]
    on_pred, _, _ = sample_surface(pv, pf, 5 * SAMPLES, rng)
    t_area = mesh_ops.face_normals(tv, tf)[1].sum()
    p_area = mesh_ops.face_normals(pv, pf)[1].sum()
    print(f"{args.domain} {args.condition} seed {args.seed}, {args.radius_mode}, "
          f"{args.resolution}: area ratio {p_area / t_area:.4f}")
    gap = cKDTree(on_pred).query(points, workers=-1)[0] / spacing
    rim = rim_distance(tv, tf, points) < RIM * spacing
    close_anywhere = close_sheet_mask(points, normals, spacing)
    close = close_anywhere & ~rim
    junction = junction_mask(points, part, spacing) & ~rim & ~close
    rest = ~rim & ~close & ~junction
    print(f"truth's area with another sheet within {CLOSE} spacings: "
          f"{100 * close_anywhere.mean():.2f} %; area ratio with those sheets once: "
          f"{p_area / (t_area * (1 - close_anywhere.mean() / 2)):.4f}")
    print(f"truth's area within {JUNCTION} spacings of another part: "
          f"{100 * junction.mean():.2f} % (besides rims and close sheets)")
    print("| true surface farther from the mesh than | all | rim | close sheets | junctions "
          "| elsewhere |")
    print("|---|---:|---:|---:|---:|---:|")
    for limit in (0.5, 1.0, 2.0):
        miss = gap > limit
        shares = [100 * (miss & kind).mean() for kind in (rim, close, junction, rest)]
        print(f"| {limit} spacing | {100 * miss.mean():.2f} % | "
              + " | ".join(f"{share:.2f} %" for share in shares) + " |")
    print_rim_area(tv, tf, pv, pf, points, on_pred[:SAMPLES], p_area / t_area, spacing)
    print_boundaries(pv, pf, tv, tf, points, {"rim": rim, "close sheets": close,
                                              "junctions": junction, "elsewhere": rest},
                     spacing)
    print_standing_off(pv, pf, tv, tf, spacing)
    off, nearest = cKDTree(points).query(on_pred[:SAMPLES], workers=-1)
    far = off / spacing > 1
    print(f"mesh farther than 1 spacing from the truth: {100 * far.mean():.2f} %; of the mesh, "
          f"near the truth's close sheets {100 * (far & close[nearest]).mean():.2f} %, "
          f"junctions {100 * (far & junction[nearest]).mean():.2f} %")


if __name__ == "__main__":
    main()
