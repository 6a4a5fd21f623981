"""What the mesher's automatic iso-value does to a test shape: the same field meshed at the
iso-value the mesher picks (one voxel unless the cover is shredded) and at 1.95 voxels, where a
rule that also counted the cover's handles put every benchmark shape.

``python -m lab.iso_rule garments [--condition noisy|sparse] [--seed 1000000]`` (and ``cars``,
``rooms``) prints a line for each: the report of :func:`lab.experiment.report` (pieces, open
boundary, vertices off the truth, truth left uncovered, CD, F1, NC, double share, area ratio).
Rooms are scored as the benchmark scores them: both meshes and the truth cropped to the clean
scan (:func:`lab.bench.dataset.crop_to_input`). docs/meshing.md has the figures.
"""

import numpy as np

HIGH_ISO = 1.953125  # voxels: 1.25^3, the highest the iso-value reaches from one voxel


def main():
    from engine.geometry import Mesh
    from engine.meshing import MeshingSettings, extract_surface
    from lab.bench import dataset, harness
    from lab.experiment import report, reconstructed_test_shape

    truth, mesh, spacing, field, frame = reconstructed_test_shape(
        "Mesh a test shape's field at the automatic iso-value and at 1.95 voxels.",
        with_field=True)
    meshes = {"automatic iso": mesh}
    high = extract_surface(field, MeshingSettings(iso=HIGH_ISO * field.spacing, device="cpu"))
    meshes[f"iso {HIGH_ISO:.2f} voxels"] = Mesh(frame.from_unit(high.mesh.vertices),
                                                 high.mesh.faces)
    scan = _clean_scan_of(truth)
    if scan is not None:  # a room: score what the scan saw
        truth = harness._cropped_truth(dataset.crop_to_input, truth, scan,
                                       harness.DEFAULT_CROP_MAX_DIST)
        meshes = {name: dataset.crop_to_input(m, scan.points, harness.DEFAULT_CROP_MAX_DIST)
                  for name, m in meshes.items()}
    for name, m in meshes.items():
        report(name, np.asarray(m.vertices, np.float64), np.asarray(m.faces), truth, spacing)


def _clean_scan_of(truth):
    """The clean scan a room is scored against, or None for a domain the benchmark does not
    crop; the domain and seed as :func:`lab.experiment.reconstructed_test_shape` read them."""
    import argparse

    from lab.bench import dataset, harness

    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("domain")
    parser.add_argument("--seed", type=int, default=1_000_000)
    args, _ = parser.parse_known_args()
    if args.domain not in harness.CROP_DOMAINS:
        return None
    return dataset.make_input(truth, args.domain, "clean", args.seed)


if __name__ == "__main__":
    main()
