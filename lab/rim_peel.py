"""An experiment, not part of the mesher: peel the faces along the open boundary whose vertices
the optimisation left off the zero level.

The small flaps that stand off a mesh's rims (docs/meshing.md, "Where the open boundary lies")
are where the cover folded and stalled: on the first clean test garment at 256 the vertices
more than a spacing from the truth sit where the field the mesher read is 0.5-0.6 voxel (median;
0.02 elsewhere), while the truth lies 1.4 voxels away, so the field there is too low but not
zero and the fold stopped short of where it reads zero. :func:`peel_unconverged` drops, in up to
``PASSES`` rounds, every face with an open-boundary vertex whose field value is over
``threshold`` voxels, so a flap is eaten from its free edge inwards and the converged surface
behind it stays.

``python -m lab.rim_peel garments [--condition noisy] [--seed 1000000]`` (and ``cars``) prints
what it does to a test shape at 256 with the product's defaults, fixed radius; docs/meshing.md has the
figures. It removes most flaps and raises NC, but it opens holes where a whole region stalled
(a car's crossings, a sparse scan) and cuts off fragments, so it is not in the mesher. Moving
those vertices onto the zero level instead (:func:`project_unconverged`, the last line it
prints) lays the flaps over the kept layer: they are folds turned back over it.
"""

import numpy as np

from engine.meshing import mesh_ops

PASSES = 6
THRESHOLDS = (0.3, 0.5)  # voxels


def peel_unconverged(faces: np.ndarray, vertex_field: np.ndarray, threshold: float,
                     passes: int = PASSES) -> np.ndarray:
    """The faces left once those with an open-boundary vertex whose field value (voxels,
    ``vertex_field`` per vertex) is over ``threshold`` are dropped, ``passes`` times over."""
    faces = np.asarray(faces, dtype=np.int64)
    return faces[kept_faces(faces, vertex_field, threshold, passes)]


def kept_faces(faces: np.ndarray, vertex_field: np.ndarray, threshold: float,
               passes: int = PASSES) -> np.ndarray:
    """:func:`peel_unconverged` as a mask over ``faces`` (True: kept)."""
    high = np.asarray(vertex_field) > threshold
    keep = np.ones(len(faces), bool)
    for _ in range(passes):
        index = np.flatnonzero(keep)
        if not len(index):
            break
        topo = mesh_ops.edge_topology(faces[index])
        open_high = np.zeros(len(high), bool)
        open_high[topo.edges[topo.counts == 1].reshape(-1)] = True
        open_high &= high
        drop = open_high[faces[index]].any(axis=1)
        if not drop.any():
            break
        keep[index[drop]] = False
    return keep


def project_unconverged(vertices: np.ndarray, faces: np.ndarray, field, frame,
                        threshold: float, steps: int = 3) -> np.ndarray:
    """The other remedy: the vertices of the faces :func:`peel_unconverged` would drop whose
    field value is over ``threshold``, moved onto the zero level instead (``steps`` jumps along
    the field's closest-point vector), every face kept. ``field``: the grid the mesher read, in
    ``frame`` (a :class:`engine.frame.UnitFrame` of ``vertices``' units). Returns the new
    vertices."""
    unit = frame.to_unit(np.asarray(vertices, np.float64))
    vertex_field = field.closest(unit)[0] / field.spacing
    faces = np.asarray(faces, dtype=np.int64)
    moved = np.zeros(len(unit), bool)
    moved[faces[~kept_faces(faces, vertex_field, threshold)].reshape(-1)] = True
    moved &= vertex_field > threshold
    for _ in range(steps):
        unit[moved] -= field.closest(unit[moved])[1]
    return frame.from_unit(unit)


def main():
    from lab.experiment import report, reconstructed_test_shape

    truth, mesh, spacing, field, frame = reconstructed_test_shape(
        "Peel the unconverged faces along a test shape's open boundary.", with_field=True)
    v, f = mesh.vertices, mesh.faces
    vertex_field = field.closest(frame.to_unit(v))[0] / field.spacing
    print(f"field at the mesh's vertices, voxels: median {np.median(vertex_field):.3f}, 90 % "
          f"{np.percentile(vertex_field, 90):.3f}")
    report("mesh", v, f, truth, spacing)
    for threshold in THRESHOLDS:
        report(f"peeled over {threshold} voxel", v, peel_unconverged(f, vertex_field, threshold),
               truth, spacing)
    report(f"projected over {THRESHOLDS[0]} voxel",
           project_unconverged(v, f, field, frame, THRESHOLDS[0]), f, truth, spacing)


if __name__ == "__main__":
    main()
