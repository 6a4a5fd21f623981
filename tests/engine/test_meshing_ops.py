"""Mesh operators and clean-up on small hand-made meshes."""

import numpy as np

from engine.meshing import mesh_ops as mo
from engine.meshing.cleanup import clean_mesh


def grid_mesh(n=6):
    """A flat n x n vertex grid in z = 0, two triangles per quad, consistently oriented."""
    xs, ys = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing="ij")
    verts = np.stack([xs.ravel(), ys.ravel(), np.zeros(n * n)], axis=1)
    faces = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            faces += [(a, b, c), (a, c, d)]
    return verts, np.array(faces, dtype=np.int64)


def test_laplacian_rows_and_linear_precision():
    verts, faces = grid_mesh()
    topo = mo.edge_topology(faces)
    lap = mo.uniform_laplacian(len(verts), topo.edges)
    assert np.allclose(np.asarray(lap.sum(axis=1)).ravel(), 1.0)
    # interior vertices of a regular, symmetric-enough patch: the umbrella of a linear field is 0
    x = verts @ np.array([[1.0, 0.5, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 0.0]])
    interior = (verts[:, 0] > 0) & (verts[:, 0] < 5) & (verts[:, 1] > 0) & (verts[:, 1] < 5)
    assert np.allclose((lap @ x - x)[interior], 0.0)


def test_centroids_edges_and_boundary():
    verts, faces = grid_mesh()
    cen = mo.centroid_matrix(len(verts), faces)
    assert np.allclose(cen @ verts, verts[faces].mean(axis=1))
    topo = mo.edge_topology(faces)
    assert set(np.unique(topo.counts)) == {1, 2}
    assert mo.boundary_loops(faces) == 1
    assert mo.euler_characteristic(faces) == 1
    assert mo.orientation_consistent(faces)
    pairs, _ = mo.dual_edges(faces, topo)
    assert len(pairs) == int((topo.counts == 2).sum())
    count, _ = mo.face_components(len(faces), pairs)
    assert count == 1
    normals, areas = mo.face_normals(verts, faces)
    assert np.allclose(normals, [0, 0, 1]) and np.allclose(areas, 0.5)


def test_bow_tie_is_split():
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
    faces = np.array([[0, 1, 2], [0, 3, 4]])  # two triangles sharing only vertex 0
    _, fans = mo.vertex_fans(len(verts), faces)
    assert fans[0] == 2
    v2, f2 = mo.split_nonmanifold_vertices(verts, faces)
    assert len(v2) == 6
    _, fans2 = mo.vertex_fans(len(v2), f2)
    assert fans2.max() == 1
    assert np.allclose(v2[f2], verts[faces])  # same geometry


def test_clean_mesh_degenerate_and_small_pieces():
    verts, faces = grid_mesh(4)
    far = verts + [10, 0, 0]
    verts2 = np.concatenate([verts, far, [[0, 0, 0]]])
    small = np.array([[16, 17, 20]])  # one lone triangle of the second copy
    degenerate = np.array([[0, 0, 1], [0, 1, 32]])  # repeated index; zero area (32 == vertex 0)
    faces2 = np.concatenate([faces, small, degenerate])
    v, f, counts = clean_mesh(verts2, faces2, spacing=1.0, min_component_faces=2)
    assert counts["degenerate"] == 2 and counts["small_pieces"] == 1
    assert len(f) == len(faces) and len(v) == len(verts)
    # at a finer voxel the lone triangle covers 2 voxels^2, far from the rest: a part, kept
    v, f, counts = clean_mesh(verts2, faces2, spacing=0.5, min_component_faces=0)
    assert len(f) == len(faces) + 1 and counts["specks"] == 0


def test_specks_go_small_parts_stay():
    """Pieces a few voxels across stay unless they lie on a larger piece (a fragment of the
    other layer) or are crumbs under a voxel's face; nothing else is touched."""
    pieces = []

    def add(n, shift, flip=False):
        v, f = grid_mesh(n)
        pieces.append((v + shift, f[:, ::-1] if flip else f))

    add(12, [0, 0, 0])  # the sheet: 121 voxels^2
    add(3, [4, 4, 0.6], flip=True)  # 4 voxels^2 lying 0.6 voxel over it, facing the other way
    add(5, [2, 6, 1.8])  # 16 voxels^2 stalled 1.8 voxels over it: a fragment of the other layer
    add(3, [30, 0, 0])  # a small part on its own: 4 voxels^2
    add(4, [0, 30, 0])  # two small pieces, one on the other: the larger (9) stays
    add(2, [1, 31, 0.5])  # ... the smaller (1) goes
    crumb = np.array([[30, 30, 0], [30.5, 30, 0], [30, 30.5, 0]])  # 0.125 voxels^2
    pieces.append((crumb, np.array([[0, 1, 2]])))
    verts, faces, start = [], [], 0
    for v, f in pieces:
        verts.append(v)
        faces.append(f + start)
        start += len(v)
    verts, faces = np.concatenate(verts), np.concatenate(faces)
    v, f, counts = clean_mesh(verts, faces, spacing=1.0)
    assert counts["specks"] == 4
    _, areas = mo.face_normals(v, f)
    count, labels = mo.vertex_components(len(v), f)
    assert sorted(np.round(np.bincount(labels, weights=areas), 6)) == [4, 9, 121]
    assert not np.any((v[:, 2] != 0))  # what stays is the flat pieces, untouched


def test_compiled_edge_topology_equals_the_numpy_one(monkeypatch):
    """numba is a runtime requirement (requirements.txt): the compiled edges are made here. A
    random soup has non-manifold edges (three or more faces), degenerate faces and unused
    vertices."""
    from engine.compiled import kernels

    assert kernels("meshing.mesh_ops_kernels") is not None
    rng = np.random.default_rng(3)
    faces = rng.integers(0, 400, size=(3000, 3))
    faces[:50, 1] = faces[:50, 0]  # degenerate
    got = mo.edge_topology(faces)
    monkeypatch.setenv("UDF_RECON_KERNELS", "numpy")
    want = mo.edge_topology(faces)
    assert want.counts.max() >= 3
    for name in ("edges", "face_edges", "counts"):
        assert np.array_equal(getattr(got, name), getattr(want, name)), name


def test_compiled_vertex_components_equal_the_numpy_ones(monkeypatch):
    """Labels in the order of each component's lowest vertex, both ways: many small pieces
    (faces among nearby vertices), unused vertices, degenerate faces, and no faces at all."""
    from engine.compiled import kernels

    assert kernels("meshing.mesh_ops_kernels") is not None
    rng = np.random.default_rng(5)
    start = rng.integers(0, 5000, 4000)
    faces = start[:, None] + rng.integers(0, 6, size=(4000, 3))
    faces[:30, 2] = faces[:30, 0]
    cases = [(5100, faces), (5100, faces[::-1]), (10, np.zeros((0, 3), np.int64))]
    got = [mo.vertex_components(n, f) for n, f in cases]
    counted = [mo.component_count(n, f) for n, f in cases]
    monkeypatch.setenv("UDF_RECON_KERNELS", "numpy")
    want = [mo.vertex_components(n, f) for n, f in cases]
    assert want[0][0] > 100
    for (count, labels), (want_count, want_labels) in zip(got, want):
        assert count == want_count and np.array_equal(labels, want_labels)
    assert counted == [count for count, _ in want]  # the count alone, without the labels


def test_compiled_vertex_fans_equal_the_numpy_ones(monkeypatch):
    """The corners' fans, by union-find and by scipy's sparse graph: the same labels, on a
    grid with bow-ties (pieces meeting at one vertex) and a fin on a shared edge."""
    n = 30
    index = np.arange(n * n).reshape(n, n)
    quads = np.stack([index[:-1, :-1], index[1:, :-1], index[1:, 1:], index[:-1, 1:]], -1)
    quads = quads.reshape(-1, 4)
    faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    rng = np.random.default_rng(3)
    faces = faces[rng.random(len(faces)) > 0.3]  # holes: many vertices with several fans
    fin = np.array([[faces[0, 0], faces[0, 1], n * n]])  # a third face on an edge
    faces = np.concatenate([faces, fin])
    got_labels, got_fans = mo.vertex_fans(n * n + 1, faces)
    monkeypatch.setenv("UDF_RECON_KERNELS", "numpy")
    want_labels, want_fans = mo.vertex_fans(n * n + 1, faces)
    assert want_fans.max() >= 2
    assert np.array_equal(got_labels, want_labels) and np.array_equal(got_fans, want_fans)


def test_compiled_twin_candidates_equal_the_numpy_ones(monkeypatch):
    """The opposite-facing neighbours of a double cover's faces, compiled and in numpy."""
    from scipy.spatial import cKDTree

    from engine.meshing import layers
    from engine.meshing.marching import double_cover
    from lab import analytic

    field = analytic.sample_grid(analytic.disk(radius=0.6), (-1, -1, -1), (1, 1, 1), 40,
                                 exact=False)
    vertices, faces, iso, _, _ = double_cover(field)
    cents = mo.centroid_matrix(len(vertices), faces) @ vertices / field.spacing
    normals = mo.face_normals(vertices, faces)[0]
    query = np.arange(len(faces))
    probe = cents - 2 * iso / field.spacing * normals  # the other layer, 2 iso behind
    tree = cKDTree(cents)
    got = layers._candidates(tree, cents, normals, query, probe, 12)
    monkeypatch.setenv("UDF_RECON_KERNELS", "numpy")
    want = layers._candidates(tree, cents, normals, query, probe, 12)
    assert len(want[0]) > len(faces) / 2  # most faces see their twin
    for a, b in zip(got[:2], want[:2]):
        assert np.array_equal(a, b)
    for a, b in zip(got[2:], want[2:]):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
