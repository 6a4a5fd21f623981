"""Peeling unconverged rim faces (an experiment outside the mesher) on a grid with a flap."""

import numpy as np

from lab.rim_peel import peel_unconverged


def grid(n):
    """An n x n grid of vertices on z = 0 and its 2 (n - 1)^2 faces."""
    x, y = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    vertices = np.column_stack([x.ravel(), y.ravel(), np.zeros(n * n)]).astype(float)
    at = np.arange(n * n).reshape(n, n)
    a, b, c, d = at[:-1, :-1].ravel(), at[1:, :-1].ravel(), at[1:, 1:].ravel(), at[:-1, 1:].ravel()
    return vertices, np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


def test_a_flap_is_peeled_from_its_free_edge_and_the_converged_sheet_stays():
    vertices, faces = grid(10)
    field = np.zeros(len(vertices))
    # a flap of two rows standing up from part of the edge x = 9, its vertices off the zero level
    edge = np.arange(9 * 10 + 2, 9 * 10 + 7)  # (9, 2) .. (9, 6)
    rows = [edge]
    for height in (1, 2):
        rows.append(len(vertices) + np.arange(len(edge)))
        vertices = np.vstack([vertices, np.column_stack([np.full(len(edge), 9.0),
                                                         np.arange(2, 7), np.full(5, height)])])
        field = np.concatenate([field, np.full(len(edge), 0.6)])
    flap = []
    for low, high in zip(rows[:-1], rows[1:]):
        for k in range(len(edge) - 1):
            flap += [[low[k], low[k + 1], high[k + 1]], [low[k], high[k + 1], high[k]]]
    with_flap = np.vstack([faces, np.array(flap)])
    kept = peel_unconverged(with_flap, field, 0.3)
    assert np.array_equal(np.sort(kept, axis=0), np.sort(faces, axis=0))


def test_below_the_threshold_or_away_from_the_boundary_nothing_goes():
    vertices, faces = grid(10)
    field = np.full(len(vertices), 0.2)
    assert np.array_equal(peel_unconverged(faces, field, 0.3), faces)
    field[[44, 45, 54, 55]] = 0.9  # inside, no open edge there
    assert np.array_equal(peel_unconverged(faces, field, 0.3), faces)
    field[:] = 0.9  # all of it stalled: eaten ring by ring, PASSES rings at most
    assert 0 < len(peel_unconverged(faces, field, 0.3, passes=2)) < len(faces)


def test_projection_puts_a_stalled_rim_back_on_the_zero_level():
    from engine.frame import UnitFrame
    from engine.meshing import extract_surface, mesh_ops
    from lab import analytic as A
    from lab.rim_peel import project_unconverged

    field = A.sample_grid(A.disk((0, 0, 0), 0.3), [-0.5] * 3, [0.5] * 3, 64, exact=False)
    mesh = extract_surface(field).mesh
    v, f = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces)
    topo = mesh_ops.edge_topology(f)
    rim = np.unique(topo.edges[topo.counts == 1])
    lifted = v.copy()
    lifted[rim, 2] += 1.5 * field.spacing  # the rim stalled off the disk
    moved = project_unconverged(lifted, f, field, UnitFrame(np.zeros(3), 1.0), 0.3)
    assert np.abs(lifted[rim, 2]).min() > 1.4 * field.spacing
    assert np.abs(moved[rim, 2]).max() < 0.25 * field.spacing
    low = field.closest(lifted)[0] <= 0.3 * field.spacing  # on the zero level: left alone
    assert low.sum() > 0.8 * len(v)
    assert np.array_equal(moved[low], lifted[low])
