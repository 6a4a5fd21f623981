"""How much the radius lattice changes the learned field (engine/radius_lattice.py).

For one benchmark shape (``--seed``, test seed 1000000 by default) it takes the band nodes that
get the network, the selector's radius at each node (per query) and blended from lattices of
step 2 and 4, and prints how far the blends are from the per-query radii. Then, on up to
60 000 of those nodes lying within 2 spacings of the true surface (where the mesher reads the
field), it prints the backbone's mean error against the true distance with each, and with two
fixed radii. Last, on those farther than 2 spacings, the share that read under 0.7 of their
true distance (a false minimum, where the mesh may wrinkle) with per-query radii, the blend of
step 4 alone, and the blend with the ridge nodes' own radii where wider (as the field runs):

    python benchmarks/radius_lattice_check.py rooms noisy 256
    python benchmarks/radius_lattice_check.py garments clean 256
    python benchmarks/radius_lattice_check.py cars clean 256 --seed 1000001
"""

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def main() -> None:
    from scipy.spatial import cKDTree

    from engine.field import (BAND_RADIUS_CAP, MAX_POINTS, MIN_BAND_NODES, MIN_PATCH_POINTS,
                              _network_nodes, backbone_predictor, find_band, gather_patches,
                              grid_layout, predict_trimmed)
    from engine.frame import UnitFrame, validate_points
    from engine.geometry import Mesh
    from engine.radius import max_radius, parent_ball, radii_for_queries
    from engine.radius_lattice import lattice_radii, ridge_nodes
    from engine.settings import ReconstructSettings
    from lab.bench import dataset
    from lab.bench.truth_udf import truth_distances

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("domain", choices=("cars", "garments", "rooms"))
    parser.add_argument("condition", choices=("clean", "sparse", "noisy"))
    parser.add_argument("resolution", type=int)
    parser.add_argument("--fixed", type=float, nargs="*", default=[0.018, 0.043])
    parser.add_argument("--seed", type=int, default=1000000, help="the test shape's seed")
    args = parser.parse_args()

    truth = dataset.make_shape(args.domain, args.seed)
    points = validate_points(dataset.make_input(truth, args.domain, args.condition,
                                                args.seed).points)
    frame = UnitFrame.from_points(points)
    points = frame.to_unit(points)
    settings = ReconstructSettings(resolution=args.resolution, radius_mode="learned",
                                   device="cpu")
    tree = cKDTree(points)
    spacing = 1.0 / args.resolution
    band_radius = max(min(max_radius(settings), BAND_RADIUS_CAP), MIN_BAND_NODES * spacing)
    shape, origin, spacing = grid_layout(points, args.resolution, band_radius)
    indices, nearest, owner = find_band(tree, points, shape, origin, spacing, band_radius,
                                        with_owner=True)
    near = _network_nodes(tree, points, nearest, owner, spacing)
    nodes, nearest = indices[near], nearest[near]
    queries = origin + nodes * spacing
    ridge = ridge_nodes(nodes, queries - points[owner[near]], spacing)

    def policy(positions):
        return radii_for_queries(settings, tree, points, positions,
                                 parent_ball(settings, tree, positions))

    own = policy(queries)
    print(f"{args.domain} {args.condition} {args.resolution}: {len(queries):,} network queries")
    for step in (2, 4):
        blended, stats = lattice_radii(policy, nodes, origin, spacing, step)
        change = np.abs(blended - own) / own
        print(f"  step {step}: {stats['lattice_positions']:,} lattice positions "
              f"({stats['lattice_positions'] / len(queries):.2f} per query); radius change "
              f"mean {change.mean():.3f}, 90 % {np.quantile(change, 0.9):.3f}")

    sample = np.random.default_rng(0).choice(len(queries), min(len(queries), 60_000),
                                             replace=False)
    sample_distance = truth_distances(Mesh(frame.to_unit(truth.vertices), truth.faces),
                                      queries[sample], spacing)
    close = sample_distance < 2 * spacing
    chosen, true_distance = sample[close], sample_distance[close]
    backbone = backbone_predictor("cpu")

    def field_values(which, radii):
        rel, mask, counts = gather_patches(tree, points, queries[which], radii, MAX_POINTS)
        seen = counts >= MIN_PATCH_POINTS
        values = nearest[which].astype(np.float64)
        values[seen] = predict_trimmed(backbone, rel[seen], mask[seen], counts[seen],
                                       1024) * radii[seen]
        return values

    def field_error(radii):
        return np.abs(field_values(chosen, radii) - true_distance).mean() / spacing

    reference = field_error(own[chosen])
    print(f"  field error at {len(chosen):,} nodes within 2 spacings of the surface "
          f"(spacings): per-query radii {reference:.4f}")
    for step in (2, 4):
        blended, _ = lattice_radii(policy, nodes[chosen], origin, spacing, step)
        error = field_error(blended)
        print(f"  lattice step {step}: {error:.4f} ({100 * (error / reference - 1):+.1f} %)")
    for radius in args.fixed:
        error = field_error(np.full(len(chosen), radius))
        print(f"  fixed {radius}: {error:.4f} ({100 * (error / reference - 1):+.1f} %)")

    away, away_distance = sample[~close], sample_distance[~close]
    print(f"  {len(away):,} nodes farther than 2 spacings from the surface, "
          f"{ridge[away].sum():,} of them on a ridge; the share reading under 0.7 of their "
          f"true distance:")
    for name, radii in (
            ("per-query radii", own[away]),
            ("lattice step 4", lattice_radii(policy, nodes[away], origin, spacing, 4)[0]),
            ("lattice step 4, ridge nodes' own where wider",
             lattice_radii(policy, nodes[away], origin, spacing, 4, own=ridge[away])[0])):
        low = field_values(away, radii) < 0.7 * away_distance
        print(f"  {name}: {100 * low.mean():.2f} %")


if __name__ == "__main__":
    main()
