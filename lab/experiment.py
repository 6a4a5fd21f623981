"""What the mesh experiments (:mod:`lab.junction_join`, :mod:`lab.rim_smoothing`,
:mod:`lab.rim_peel`) share: a benchmark test shape reconstructed as a user gets it, and a line
of what a change did to it."""

import numpy as np


def reconstructed_test_shape(description: str, with_field: bool = False):
    """Parse ``DOMAIN [--condition] [--seed] [--resolution]`` from the command line; reconstruct
    that test shape (clean unless told) on the CPU with the product's defaults but the fixed
    radius (Table I's ``ours`` rows). Returns
    ``(truth, mesh, spacing)`` (the unit frame's grid spacing); with ``with_field``, also the
    distance grid the mesher read (:class:`engine.udf_grid.UDFGrid`) and the frame it lies in
    (the cloud's :class:`engine.frame.UnitFrame`)."""
    import argparse

    from engine import meshing
    from engine.frame import UnitFrame
    from engine.geometry import PointCloud
    from engine.reconstruct import reconstruct
    from engine.settings import ReconstructSettings
    from lab.bench import dataset

    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("domain", choices=dataset.DOMAINS)
    parser.add_argument("--condition", choices=("clean", "sparse", "noisy"), default="clean")
    parser.add_argument("--seed", type=int, default=1_000_000)
    parser.add_argument("--resolution", type=int, default=256)
    args = parser.parse_args()
    truth = dataset.make_shape(args.domain, args.seed)
    cloud = dataset.make_input(truth, args.domain, args.condition, args.seed)
    fields = []
    extract = meshing.extract_surface

    def kept_field(field, *more, **named):
        fields.append(field)
        return extract(field, *more, **named)

    meshing.extract_surface = kept_field  # reconstruct() looks it up when it runs
    try:
        mesh = reconstruct(PointCloud(cloud.points),
                           ReconstructSettings(resolution=args.resolution, device="cpu",
                                               radius_mode="fixed")).mesh
    finally:
        meshing.extract_surface = extract
    made = (truth, mesh, 1.0 / args.resolution)
    if not with_field:
        return made
    # the mesher's frame: the cloud's unit frame (no outliers are dropped from these scans)
    frame = UnitFrame.from_points(np.asarray(cloud.points, np.float64))
    return made + (fields[0], frame)


UNCOVERED_SAMPLES = 300_000


def report(name: str, vertices: np.ndarray, faces: np.ndarray, truth, spacing: float) -> None:
    """Print the pieces, the open boundary's length (spacings), the mesh's vertices more than a
    spacing off the truth, the share of the truth farther than a spacing from the mesh (of
    ``UNCOVERED_SAMPLES`` area samples, against 5 times as many on the mesh) and the benchmark's
    scores."""
    from scipy.spatial import cKDTree

    from engine.geometry import Mesh
    from engine.meshing import mesh_ops
    from engine.metrics import evaluate
    from engine.sampling import sample_surface
    from lab.bench.surface_distance import closest_on_mesh

    topo = mesh_ops.edge_topology(faces)
    edges = topo.edges[topo.counts == 1]
    boundary = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1).sum()
    scores = evaluate(Mesh(vertices, faces), truth)
    used = np.unique(faces)
    truth_vertices, truth_faces = np.asarray(truth.vertices, np.float64), np.asarray(truth.faces)
    off = closest_on_mesh(vertices[used], truth_vertices, truth_faces)[0] > spacing
    rng = np.random.default_rng(0)
    on_truth = sample_surface(truth_vertices, truth_faces, UNCOVERED_SAMPLES, rng)[0]
    on_mesh = sample_surface(vertices, faces, 5 * UNCOVERED_SAMPLES, rng)[0]
    uncovered = (cKDTree(on_mesh).query(on_truth)[0] > spacing).mean()
    print(f"{name}: {mesh_ops.vertex_components(len(vertices), faces)[0]} pieces, open boundary "
          f"{boundary / spacing:.0f} spacings, {int(off.sum())} vertices off, truth uncovered "
          f"{100 * uncovered:.2f} %, CD x 10^2 {scores['cd_l1_x100']:.4f}, F1@0.005 "
          f"{scores['f1_0.005']:.4f}, NC {scores['nc']:.4f}, double "
          f"{100 * scores['double_layer']:.2f} %, area ratio {scores['area_ratio']:.4f}")
