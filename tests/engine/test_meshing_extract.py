"""End to end on analytic fields: distance to the true surface, pieces, loops, manifoldness, and
one layer everywhere (the double-layered share of the area and the area against the truth)."""

from functools import lru_cache

import numpy as np
import pytest

from engine.errors import Cancelled
from engine.meshing import MeshingSettings, UDFGrid, extract_surface
from engine.meshing import mesh_ops as mo
from engine.metrics import double_layer_share
from lab import analytic as A

RES = 64
H = 1.0 / (RES - 1)  # voxel size over [-0.5, 0.5]


def shapes():
    return {
        "sphere": A.sphere((0.01, 0.02, -0.03), 0.3),
        "torus": A.torus((0, 0, 0.013), 0.3, 0.1),
        "disk": A.disk((0, 0, 0), 0.3),  # z = 0 lies midway between two node layers
        "square": A.rectangle((0, 0, 0.01), half_u=0.3, half_v=0.3),
        "hemisphere": A.hemisphere((0, 0, -0.1), 0.3),
        "sheets": A.union(A.rectangle((0, 0, -1.5 * H), half_u=0.3, half_v=0.3),
                          A.rectangle((0, 0, 1.5 * H), half_u=0.3, half_v=0.3)),
        "two_disks": A.union(A.disk((-0.15, 0, 0.003), 0.3), A.disk((0.3, 0.3, 0.01), 0.03)),
        "mobius": A.mobius(0.3, 0.12, spacing=H / 6),
        "t_junction": A.t_junction(0.3, 0.3),
        "shelf": A.shelf_on_wall(0.3, 0.35, 0.25),
        "boxes": A.touching_boxes(0.15),
    }


TRUE_AREA = {"disk": np.pi * 0.09, "square": 0.36, "hemisphere": 2 * np.pi * 0.09,
             "t_junction": 0.6 * 0.6 + 0.3 * 0.6, "shelf": 0.6 * 0.7 + 0.36 * 0.25,
             "boxes": 11 * 0.3 ** 2, "mobius": 2 * np.pi * 0.3 * 0.24}


def area(mesh):
    return float(mo.face_normals(mesh.vertices, mesh.faces)[1].sum())


def double_share(mesh):
    return double_layer_share(mesh.vertices, mesh.faces, H)


@lru_cache(maxsize=None)
def run(name, seed=0):
    shape = shapes()[name]
    grid = A.sample_grid(shape, [-0.5] * 3, [0.5] * 3, RES, exact=False)
    result = extract_surface(grid, MeshingSettings(seed=seed))
    return shape, result


def summary(mesh):
    topo = mo.edge_topology(mesh.faces)
    pairs, _ = mo.dual_edges(mesh.faces, topo)
    count, labels = mo.face_components(len(mesh.faces), pairs)
    _, fans = mo.vertex_fans(len(mesh.vertices), mesh.faces, topo)
    return dict(components=count, labels=labels, loops=mo.boundary_loops(mesh.faces, topo),
                nonmanifold_edges=int((topo.counts > 2).sum()),
                nonmanifold_vertices=int((fans > 1).sum()),
                boundary_vertices=np.unique(topo.edges[topo.counts == 1]))


def face_quality(mesh):
    normals, areas = mo.face_normals(mesh.vertices, mesh.faces)
    return areas.min() / H ** 2, mo.orientation_consistent(mesh.faces)


@pytest.mark.parametrize("name,chi", [("sphere", 2), ("torus", 0)])
def test_closed_shapes(name, chi):
    shape, result = run(name)
    mesh = result.mesh
    s = summary(mesh)
    assert s["components"] == 1 and s["loops"] == 0
    assert s["nonmanifold_edges"] == 0 and s["nonmanifold_vertices"] == 0
    assert mo.euler_characteristic(mesh.faces) == chi
    assert double_share(mesh) == 0.0
    d = shape(mesh.vertices)[0] / H
    assert d.mean() < 0.05 and d.max() < 0.3
    centroids = mesh.vertices[mesh.faces].mean(axis=1)
    assert shape(centroids)[0].max() / H < 0.3
    min_area, consistent = face_quality(mesh)
    assert consistent and min_area > 1e-6
    assert mo.signed_volume(mesh.vertices, mesh.faces) > 0  # outward normals: not flipped


def rim_distance(name, points):
    """Distance (voxels) from points to the true rim of an open test shape."""
    if name == "disk":
        return np.hypot(np.hypot(points[:, 0], points[:, 1]) - 0.3, points[:, 2]) / H
    if name == "hemisphere":
        return np.hypot(np.hypot(points[:, 0], points[:, 1]) - 0.3, points[:, 2] + 0.1) / H
    if name == "square":
        q = np.abs(points[:, :2])
        outside = np.maximum(q - 0.3, 0)
        inside = np.minimum(0.3 - q[:, 0], 0.3 - q[:, 1])
        planar = np.where(np.any(q > 0.3, axis=1), np.linalg.norm(outside, axis=1), inside)
        return np.hypot(planar, points[:, 2] - 0.01) / H
    raise KeyError(name)


def rim_points(name):
    t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    if name in ("disk", "hemisphere"):
        z = 0.0 if name == "disk" else -0.1
        return np.stack([0.3 * np.cos(t), 0.3 * np.sin(t), np.full_like(t, z)], axis=1)
    s = np.linspace(-0.3, 0.3, 100)
    sides = [np.stack([s, np.full_like(s, k), np.full_like(s, 0.01)], 1) for k in (-0.3, 0.3)]
    sides += [np.stack([np.full_like(s, k), s, np.full_like(s, 0.01)], 1) for k in (-0.3, 0.3)]
    return np.concatenate(sides)


@pytest.mark.parametrize("name", ["disk", "square", "hemisphere"])
def test_open_shapes_one_layer(name):
    shape, result = run(name)
    mesh = result.mesh
    s = summary(mesh)
    _, face_area = mo.face_normals(mesh.vertices, mesh.faces)
    assert np.bincount(s["labels"], weights=face_area).max() > 0.995 * face_area.sum()  # one piece
    assert double_share(mesh) < 0.01  # one layer: no opposite-facing sheet within a voxel
    assert 0.985 < area(mesh) / TRUE_AREA[name] < 1.015  # not doubled, rims in place
    d = shape(mesh.vertices)[0] / H
    assert d.mean() < 0.05 and d.max() < 0.8
    rim = mesh.vertices[s["boundary_vertices"]]
    # the boundary follows the true rim; at 64^3 some of it a voxel or so in where the rim step
    # was held back (finer grids: test_open_rims_in_place)
    to_rim = rim_distance(name, rim)
    assert np.median(to_rim) < 0.2 and to_rim.max() < 2.0
    from scipy.spatial import cKDTree
    gap, _ = cKDTree(rim).query(rim_points(name))
    assert gap.max() / H < 2.5  # and the whole true rim is followed
    # the rim is one loop, maybe pinched at a few vertices: no other long boundary
    assert s["loops"] <= 30
    # wound consistently, but for a few faces welded near the rim
    directed = np.stack([mesh.faces, np.roll(mesh.faces, -1, axis=1)], axis=2).reshape(-1, 2)
    _, counts = np.unique(directed, axis=0, return_counts=True)
    assert (counts > 1).sum() <= 0.005 * len(mesh.faces)


def rim_distance_at(name, points, spacing):
    return rim_distance(name, points) * H / spacing


@pytest.mark.parametrize("name", ["disk", "square"])
@pytest.mark.parametrize("res,exact", [(128, False), (256, False), (128, True)])
def test_open_rims_in_place(name, res, exact):
    """Open rims come out where the surface ends: the area within 1 % of the truth and the
    boundary on the true rim. On a sampled grid (as a reconstruction's field is) the median
    boundary vertex is within a tenth of a voxel and 90 % within half a voxel; the rest (up to
    about 6 %: a corner of the square, stretches of the disk where the rim step was held back
    to keep faces from turning over) stay up to 2 voxels in. With the exact field every
    boundary vertex is within half a voxel."""
    shape = shapes()[name]
    grid = A.sample_grid(shape, [-0.5] * 3, [0.5] * 3, res, exact=exact)
    mesh = extract_surface(grid).mesh
    assert abs(area(mesh) / TRUE_AREA[name] - 1) < 0.01
    to_rim = rim_distance_at(name, mesh.vertices[summary(mesh)["boundary_vertices"]],
                             grid.spacing)
    assert np.median(to_rim) < 0.1 and np.quantile(to_rim, 0.9) < 0.5 and to_rim.max() < 2.0
    if exact:
        assert to_rim.max() < 0.5
    assert double_share(mesh) < 0.001


def test_two_close_sheets_stay_separate():
    _, result = run("sheets")
    mesh = result.mesh
    s = summary(mesh)
    assert s["components"] == 2
    for k in range(2):
        z = mesh.vertices[np.unique(mesh.faces[s["labels"] == k]), 2]
        assert np.ptp(z) < 0.2 * H  # each piece is flat, on one of the sheets
        assert abs(abs(z.mean()) - 1.5 * H) < 0.05 * H
    assert 0.9 < area(mesh) / (2 * 0.36) < 1.02


@pytest.mark.parametrize("gap", [1.0, 1.5, 3.0, 4.0])
def test_sheets_closer_than_the_grid_resolves_come_out_once(gap):
    """Two parallel sheets ``gap`` voxels apart, off the nodes. From 3 voxels apart each comes
    out on its own plane. Closer than 2, the closest-point field the mesher reads (central
    differences of d^2, interpolated) has one zero between them, not two: one sheet comes out
    midway, once (no double layer), with one sheet's area. Between 2 and 3 voxels apart the
    two are resolved in part (docs/meshing.md)."""
    off = 0.013  # 0.8 voxel off the node planes
    half = 0.5 * gap * H
    shape = A.union(A.rectangle((0, 0, off - half), half_u=0.3, half_v=0.3),
                    A.rectangle((0, 0, off + half), half_u=0.3, half_v=0.3))
    grid = A.sample_grid(shape, [-0.5] * 3, [0.5] * 3, RES, exact=False)
    mesh = extract_surface(grid).mesh
    height = (mesh.vertices[mesh.faces].mean(axis=1)[:, 2] - off) / H
    assert double_share(mesh) < 0.01
    if gap >= 3.0:
        assert abs(area(mesh) / (2 * 0.36) - 1) < 0.02
        assert np.all(np.abs(np.abs(height) - 0.5 * gap) < 0.3)
    else:
        assert abs(area(mesh) / 0.36 - 1) < 0.03
        assert np.all(np.abs(height) < 0.25)


def test_small_disk_is_kept():
    _, result = run("two_disks")
    mesh = result.mesh
    s = summary(mesh)
    assert s["components"] == 2
    centres = np.array([mesh.vertices[np.unique(mesh.faces[s["labels"] == k])].mean(axis=0)
                        for k in range(2)])
    assert np.min(np.linalg.norm(centres - [0.3, 0.3, 0.01], axis=1)) < 2 * H
    assert double_share(mesh) < 0.01


@pytest.mark.parametrize("name,limit,least", [("t_junction", 0.01, 0.93), ("shelf", 0.01, 0.93),
                                              ("boxes", 0.03, 0.92), ("mobius", 0.01, 0.93)])
def test_non_manifold_and_non_orientable_come_out_single_layered(name, limit, least):
    """A T-junction, a shelf touching a wall, two boxes sharing a face, a Möbius strip: the
    min-cut of DCUDF keeps both layers of these; here one layer remains, the surface's area
    once. Within a voxel of a junction the welded faces turn and face each other; one of each
    such pair is dropped, which leaves a slot under a voxel wide along the junction (the boxes'
    area limit). A Möbius strip cannot be wound consistently: along its seam the faces on
    either side face opposite ways and read as a little double area. A kept double layer would
    read as about half of the area."""
    shape, result = run(name)
    mesh = result.mesh
    assert double_share(mesh) < limit
    assert least < area(mesh) / TRUE_AREA[name] < 1.03
    d = shape(mesh.vertices)[0] / H
    assert np.median(d) < 0.1 and np.mean(d) < 0.15
    # the whole surface is covered: every point of the truth is near the mesh
    from scipy.spatial import cKDTree
    truth = shape(np.random.default_rng(0).uniform(-0.45, 0.45, (20000, 3)))[1]
    gap, _ = cKDTree(mesh.vertices).query(truth)
    assert np.quantile(gap / H, 0.99) < 2.0
    assert not result.messages  # nothing a user has to act on


def test_fragmented_cover_comes_out_single_layered():
    """A noisy field fragments the double cover (pieces, handles); one layer, in one piece, still
    remains."""
    shape = A.disk((0, 0, 0.004), 0.3)
    grid = A.sample_grid(shape, [-0.5] * 3, [0.5] * 3, RES, exact=False)
    udf = grid.slab(0, grid.shape[0])
    noise = np.random.default_rng(3).uniform(-0.45, 0.45, udf.shape) * H
    noisy = UDFGrid(np.abs(udf + noise), grid.origin, H)
    result = extract_surface(noisy, MeshingSettings(iso=0.7 * H))
    assert result.stats["cover_pieces"] > 1  # the cover did fragment
    mesh = result.mesh
    assert double_share(mesh) < 0.01
    assert 0.85 < area(mesh) / TRUE_AREA["disk"] < 1.05
    # one piece: the fragments' specks (a dozen or so pieces under 20 faces) are gone
    assert mo.vertex_components(len(mesh.vertices), mesh.faces)[0] == 1


def test_same_seed_same_mesh_and_band_input():
    _, a = run("hemisphere")
    shape = shapes()["hemisphere"]
    dense = A.sample_grid(shape, [-0.5] * 3, [0.5] * 3, RES, exact=False)
    udf = dense.slab(0, dense.shape[0])
    idx = np.argwhere(udf < 4 * H)
    band = UDFGrid.from_band(idx, udf[tuple(idx.T)], dense.shape, dense.origin, H, 4 * H)
    b = extract_surface(band, MeshingSettings(seed=0))
    assert np.array_equal(a.mesh.faces, b.mesh.faces)
    assert np.array_equal(a.mesh.vertices, b.mesh.vertices)


def test_exact_callable_and_timings():
    shape = A.sphere((0, 0, 0), 0.3)
    grid = A.sample_grid(shape, [-0.5] * 3, [0.5] * 3, 40, exact=True)
    seen = []
    result = extract_surface(grid, MeshingSettings(iterations=120),
                             progress=lambda f, m: seen.append(f))
    d = shape(result.mesh.vertices)[0] / grid.spacing
    assert d.mean() < 0.05 and d.max() < 0.3
    assert set(result.timings) >= {"marching_cubes", "optimize", "layers", "cleanup"}
    assert seen and seen[-1] == 1.0 and all(0 <= f <= 1 for f in seen)
    assert result.iso == pytest.approx(grid.spacing)


def test_cancel_is_honoured():
    grid = A.sample_grid(A.sphere((0, 0, 0), 0.3), [-0.5] * 3, [0.5] * 3, 40, exact=False)
    calls = []

    def cancel():
        calls.append(1)
        return len(calls) > 3

    with pytest.raises(Cancelled):
        extract_surface(grid, cancel=cancel)


def test_no_cut_keeps_double_layer():
    grid = A.sample_grid(A.disk((0, 0, 0), 0.3), [-0.5] * 3, [0.5] * 3, 40, exact=False)
    result = extract_surface(grid, MeshingSettings(cut=False, iterations=100))
    assert summary(result.mesh)["loops"] == 0  # the closed pancake
    assert double_share(result.mesh) > 0.9


def sheet(n, spacing, z, up=True):
    """A flat n x n vertex grid at height z, normals up (or down), world units."""
    xs, ys = np.meshgrid(np.arange(n) * spacing, np.arange(n) * spacing, indexing="ij")
    verts = np.stack([xs.ravel(), ys.ravel(), np.full(n * n, z)], axis=1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a, b, c, d = (i * n + j).ravel(), ((i + 1) * n + j).ravel(), ((i + 1) * n + j + 1).ravel(), \
        (i * n + j + 1).ravel()
    faces = np.concatenate([np.c_[a, b, c], np.c_[a, c, d]])
    return verts, faces if up else faces[:, ::-1]


def test_faces_turned_against_a_sheet_are_dropped_a_thin_part_stays():
    """A strip of a stalled layer half a voxel over a sheet, tilted so it is no twin (normals
    135 degrees apart), reads as double; it goes and the sheet stays whole. The two sides of a
    thin part 0.9 voxel apart (the field rises between them) both stay."""
    from engine.meshing.layers import drop_facing_pairs

    h = 0.01
    verts, faces = sheet(21, h, 0.0)
    patch, patch_faces = sheet(3, 0.4 * h, 0.0, up=False)
    patch[:, 2] = 0.5 * h - (patch[:, 0] - 0.4 * h)  # 45 degrees: from 0.1 to 0.9 voxel up
    patch[:, :2] += 8 * h
    both_v = np.concatenate([verts, patch])
    both_f = np.concatenate([faces, patch_faces + len(verts)])
    normals, _ = mo.face_normals(both_v, both_f)
    assert np.allclose(normals[len(faces):, 2], -np.sqrt(0.5))
    grid = A.sample_grid(A.rectangle((0.1, 0.1, 0.0), half_u=0.2, half_v=0.2),
                         [-0.2, -0.2, -0.1], [0.4, 0.4, 0.1], 61, exact=True)
    assert double_layer_share(both_v, both_f, h) > 0.005  # the strip and the sheet under it
    kept, dropped = drop_facing_pairs(both_v, both_f, grid, h)
    assert dropped == len(patch_faces) and np.array_equal(kept, faces)
    assert double_layer_share(both_v, kept, h) == 0.0

    low, low_f = sheet(21, h, -0.45 * h, up=False)
    high, high_f = sheet(21, h, 0.45 * h)
    thin_v = np.concatenate([low, high])
    thin_f = np.concatenate([low_f, high_f + len(low)])
    two = A.union(A.rectangle((0.1, 0.1, -0.45 * h), half_u=0.2, half_v=0.2),
                  A.rectangle((0.1, 0.1, 0.45 * h), half_u=0.2, half_v=0.2))
    grid = A.sample_grid(two, [-0.2, -0.2, -0.1], [0.4, 0.4, 0.1], 61, exact=True)
    assert double_layer_share(thin_v, thin_f, h) > 0.5
    kept, dropped = drop_facing_pairs(thin_v, thin_f, grid, h)
    assert dropped == 0


@pytest.mark.parametrize("profile,twinned", [("valley", True), ("two_sheets", False),
                                             ("blurred_sheets", False)])
def test_layers_stalled_across_a_low_slab_are_twins_a_thin_part_is_not(profile, twinned):
    """On a sparse or noisy scan the field stays low across a slab a voxel or more thick, lowest
    inside, and the cover's two layers stall on its two sides, 2 to 3 voxels apart: they are the
    two layers of one sheet: one of them goes, and the other moves to the middle of the slab
    (before, such pairs were read as a thin part and both stayed, a double wall). Two converged sheets as far apart, with the field rising
    between them (a thin part) or reading zero all the way between them (a thin part on the
    grid's nodes, which the closest-point field blurs into one zero slab), are two sheets, and
    both stay."""
    from engine.meshing.layers import choose_layer, find_twins

    h = 0.01
    half = 1.5 if profile == "two_sheets" else 1.0
    low, low_f = sheet(21, h, -half * h, up=False)
    high, high_f = sheet(21, h, half * h)
    verts = np.concatenate([low, high])
    faces = np.concatenate([low_f, high_f + len(low)])
    axes = [np.arange(-10, 31) * h, np.arange(-10, 31) * h, np.arange(-6, 7) * h]
    z = np.meshgrid(*axes, indexing="ij")[2]
    udf = {"valley": 0.1 * h + 0.5 * np.abs(z),  # 0.3 voxel at the layers, 0 midway
           "two_sheets": np.abs(np.abs(z) - half * h),  # 0 at the sheets, 1.5 voxels between
           "blurred_sheets": np.abs(np.abs(z) - half * h)}[profile]
    grid = UDFGrid(udf, [a[0] for a in axes], h)
    cents = verts[faces].mean(axis=1) / h
    normals, _ = mo.face_normals(verts, faces)
    f, g, gap = find_twins(cents, normals, grid, h, 4.0)
    assert len(f) == (len(low_f) if twinned else 0)
    assert np.allclose(gap, 2 * half)
    keep, moved, _ = choose_layer(verts, verts, faces, h, grid, iso=2.0)
    kept = faces[keep]
    assert len(kept) == (len(low_f) if twinned else len(faces))
    z = moved[np.unique(kept), 2] / h
    if twinned:  # one sheet, moved to the middle of the slab where the surface lies
        assert np.abs(z).max() < 1e-9
    else:  # both sheets, where they were
        assert np.array_equal(moved, verts)


def test_pinholes_closed_a_small_piece_rim_left_open():
    """A hole in a sheet is closed; the rim of a piece of a few faces is not (a fan across it
    would lay a second sheet on the piece)."""
    from engine.meshing.layers import close_pinholes

    n = 6  # a 6 x 6 grid of quads with its middle vertex's fan taken out: a 6-edge hole
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quads = [(idx[i, j], idx[i + 1, j], idx[i + 1, j + 1], idx[i, j + 1])
             for i in range(n) for j in range(n)]
    sheet = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    sheet = sheet[~(sheet == idx[3, 3]).any(axis=1)]
    closed, count = close_pinholes(sheet)
    assert count == 1 and mo.boundary_loops(closed) == 1
    assert mo.orientation_consistent(closed)

    piece = np.array([(0, 1, 2), (0, 2, 3), (0, 3, 4)]) + 100  # a fan of 3 faces, 5-edge rim
    both = np.concatenate([sheet, piece])
    closed, count = close_pinholes(both)
    assert count == 1 and len(closed) == len(sheet) + 4 + len(piece)
    assert mo.boundary_loops(closed) == 2


def test_handles_alone_keep_the_iso_at_one_voxel():
    """A grille's cover has a handle through each of its 16 holes but no fragments: the automatic
    iso-value stays at one voxel (at two, the covers of close sheets merge, and this grille's
    mesh comes out 6 % too large, in two pieces), and the mesh is one piece of one layer with
    every hole open."""
    from engine.meshing.marching import double_cover

    res, half, holes, radius = 128, 0.35, 4, 0.03  # holes 3.8 voxels across their radius
    h = 1.0 / (res - 1)
    shape = A.perforated_plate((0, 0, 0.004), half, holes, radius)
    grid = A.sample_grid(shape, [-0.5] * 3, [0.5] * 3, res, exact=False)
    _, _, iso, report, messages = double_cover(grid)
    assert report.handles >= holes * holes and not report.fragmented
    assert iso == pytest.approx(h) and not messages
    mesh = extract_surface(grid).mesh
    assert double_layer_share(mesh.vertices, mesh.faces, h) < 0.01
    true_area = (2 * half) ** 2 - holes * holes * np.pi * radius ** 2
    assert abs(area(mesh) / true_area - 1) < 0.03
    assert summary(mesh)["components"] == 1
    pitch = 2 * half / holes
    centres = -half + pitch * (np.arange(holes) + 0.5)
    middles = np.stack(np.meshgrid(centres, centres), -1).reshape(-1, 2)
    cents = mesh.vertices[mesh.faces].mean(axis=1)[:, :2]
    from scipy.spatial import cKDTree
    near, _ = cKDTree(cents).query(middles)
    assert near.min() > 0.5 * radius  # no hole is bridged
