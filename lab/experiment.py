"""What the mesh experiments (:mod:`lab.junction_join`, :mod:`lab.rim_smoothing`) share: a
benchmark test shape reconstructed as a user gets it, and a line of what a change did to it."""

import numpy as np


def reconstructed_test_shape(description: str):
    """Parse ``DOMAIN [--seed] [--resolution]`` from the command line; reconstruct that clean
    test shape on the CPU. Returns ``(truth, mesh, spacing)`` (the unit frame's grid spacing)."""
    import argparse

    from engine.geometry import PointCloud
    from engine.reconstruct import reconstruct
    from engine.settings import ReconstructSettings
    from lab.bench import dataset

    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("domain", choices=dataset.DOMAINS)
    parser.add_argument("--seed", type=int, default=1_000_000)
    parser.add_argument("--resolution", type=int, default=256)
    args = parser.parse_args()
    truth = dataset.make_shape(args.domain, args.seed)
    cloud = dataset.make_input(truth, args.domain, "clean", args.seed)
    mesh = reconstruct(PointCloud(cloud.points),
                       ReconstructSettings(resolution=args.resolution, device="cpu")).mesh
    return truth, mesh, 1.0 / args.resolution


def report(name: str, vertices: np.ndarray, faces: np.ndarray, truth, spacing: float) -> None:
    """Print the pieces, the open boundary's length (spacings) and the benchmark's scores."""
    from engine.geometry import Mesh
    from engine.meshing import mesh_ops
    from engine.metrics import evaluate

    topo = mesh_ops.edge_topology(faces)
    edges = topo.edges[topo.counts == 1]
    boundary = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1).sum()
    scores = evaluate(Mesh(vertices, faces), truth)
    print(f"{name}: {mesh_ops.vertex_components(len(vertices), faces)[0]} pieces, open boundary "
          f"{boundary / spacing:.0f} spacings, CD x 10^2 {scores['cd_l1_x100']:.4f}, F1@0.005 "
          f"{scores['f1_0.005']:.4f}, NC {scores['nc']:.4f}, double "
          f"{100 * scores['double_layer']:.2f} %, area ratio {scores['area_ratio']:.4f}")
