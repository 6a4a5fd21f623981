"""The benchmark's procedural shapes, virtual scanner and scan conditions."""

import os
from dataclasses import replace

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from engine.geometry import Mesh
from engine.sampling import face_areas_and_normals
from lab.bench import dataset
from lab.bench.dataset import (CONDITIONS, DOMAINS, crop_to_input, make_input, make_shape,
                               room_viewpoints, train_seeds)
from lab.bench.dataset import test_seeds as held_out_seeds
from lab.bench.scan import virtual_scan
from lab.bench.shapes.rooms import room_layout


def _edges(faces):
    """Unique undirected edges (E, 2) and how many faces use each (E,)."""
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    base = int(faces.max()) + 1
    keys, uses = np.unique(e[:, 0] * base + e[:, 1], return_counts=True)
    return np.stack([keys // base, keys % base], axis=1), uses


def _components(count, edges):
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(count, count))
    return connected_components(graph, directed=False)


def _boundary_loops(mesh):
    edges, uses = _edges(mesh.faces)
    boundary = edges[uses == 1]
    if len(boundary) == 0:
        return 0
    _, labels = _components(len(mesh.vertices), boundary)
    return len(np.unique(labels[np.unique(boundary)]))


@pytest.mark.parametrize("domain", DOMAINS)
def test_same_seed_gives_identical_shape(domain):
    seed = held_out_seeds(domain)[3]
    a, b = make_shape(domain, seed), make_shape(domain, seed)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)


@pytest.mark.parametrize("domain", DOMAINS)
def test_shapes_are_in_the_unit_frame_with_bounded_face_count(domain):
    for seed in held_out_seeds(domain, 5):
        mesh = make_shape(domain, seed)
        low, high = mesh.vertices.min(0), mesh.vertices.max(0)
        assert abs((high - low).max() - 1.0) < 1e-9
        assert np.abs((low + high) / 2).max() < 1e-9
        assert 5_000 <= len(mesh.faces) <= 60_000
        assert mesh.faces.dtype == np.int64 and mesh.vertices.dtype == np.float64


def test_garments_are_open_with_at_least_two_boundary_loops():
    for seed in held_out_seeds("garments", 10):
        assert _boundary_loops(make_shape("garments", seed)) >= 2


def test_cars_are_closed_parts_with_many_components():
    for seed in held_out_seeds("cars", 5):
        mesh = make_shape("cars", seed)
        edges, uses = _edges(mesh.faces)
        assert (uses == 2).all()  # every part closed and manifold
        parts, _ = _components(len(mesh.vertices), edges)
        assert parts >= 8


def test_train_and_test_seeds_are_disjoint():
    for domain in DOMAINS:
        assert len(held_out_seeds(domain)) == 100 and len(train_seeds(domain)) == 40
        assert not set(held_out_seeds(domain)) & set(train_seeds(domain, 100_000))


@pytest.mark.parametrize("domain", DOMAINS)
def test_twenty_test_shapes_all_differ(domain):
    signatures = []
    for seed in held_out_seeds(domain, 20):
        mesh = make_shape(domain, seed)
        extent = np.ptp(mesh.vertices, axis=0)
        area = face_areas_and_normals(mesh.vertices, mesh.faces)[0].sum()
        signatures.append(np.concatenate([extent, [area]]))
    signatures = np.array(signatures)
    gaps = np.linalg.norm(signatures[:, None] - signatures[None], axis=2)
    np.fill_diagonal(gaps, np.inf)
    assert gaps.min() > 1e-3


def _room_with_cabinet():
    for seed in held_out_seeds("rooms"):
        if any(item.kind == "cabinet" for item in room_layout(seed).items):
            return seed
    raise AssertionError("no test room has a cabinet")


@pytest.fixture(scope="module")
def scanned_room():
    seed = _room_with_cabinet()
    gt = make_shape("rooms", seed)
    return seed, gt, make_input(gt, "rooms", "clean", seed)


def test_room_scan_has_the_count_and_varying_density(scanned_room):
    _, _, cloud = scanned_room
    assert cloud.points.shape == (CONDITIONS["clean"].count, 3)
    knn = cKDTree(cloud.points).query(cloud.points, 9)[0][:, 8]
    assert np.percentile(knn, 95) / np.percentile(knn, 5) > 2.0


def test_room_scan_misses_the_floor_under_a_cabinet(scanned_room):
    seed, gt, cloud = scanned_room
    layout = room_layout(seed)
    size = np.asarray(layout.size)
    metres = cloud.points * size.max() + size / 2  # back to the layout's frame
    on_floor = metres[metres[:, 2] < 0.005]
    assert len(on_floor) > 1000  # the open floor is seen
    for item in (i for i in layout.items if i.kind == "cabinet"):
        c, s = np.cos(item.yaw), np.sin(item.yaw)
        dx, dy = on_floor[:, 0] - item.x, on_floor[:, 1] - item.y
        local_x, local_y = c * dx + s * dy, -s * dx + c * dy
        under = (np.abs(local_x) < 0.35 * item.size[0]) & (np.abs(local_y) < 0.35 * item.size[1])
        assert under.sum() == 0


def test_room_viewpoints_are_inside_the_room():
    for seed in held_out_seeds("rooms", 10):
        views = room_viewpoints(seed)
        assert 2 <= len(views) <= 4 and (np.abs(views) < 0.5).all()


def test_crop_keeps_only_faces_near_the_scan(scanned_room):
    _, gt, cloud = scanned_room
    crop = crop_to_input(gt, cloud.points, 0.01)
    assert 0 < _area(crop) < _area(gt)
    centroids = crop.vertices[crop.faces].mean(axis=1)
    farthest = cKDTree(cloud.points).query(centroids)[0].max()
    corners = crop.vertices[crop.faces]
    edge = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max()
    assert edge <= 0.005 and farthest <= 0.01 + edge  # split to max_dist / 2, then cropped


def test_uneven_object_scan_is_deterministic_with_the_count():
    car = make_shape("cars", held_out_seeds("cars")[0])
    views = np.array([[1.0, 0.4, 0.3], [-0.8, -0.6, 0.5]])
    a, na = virtual_scan(car, 5_000, np.random.default_rng(7), views, uneven=True)
    b, _ = virtual_scan(car, 5_000, np.random.default_rng(7), views, uneven=True)
    assert a.shape == (5_000, 3) and np.array_equal(a, b)
    assert np.allclose(np.linalg.norm(na, axis=1), 1.0)


@pytest.mark.parametrize("domain", ["cars", "garments"])
def test_noise_and_outliers_match_their_conditions(domain):
    seed = held_out_seeds(domain)[1]
    gt = make_shape(domain, seed)
    clean = make_input(gt, domain, "clean", seed).points
    noisy = make_input(gt, domain, "noisy", seed).points
    assert abs(np.std(noisy - clean) - 0.0025) < 0.0001
    outliers = make_input(gt, domain, "outliers", seed).points
    moved = np.linalg.norm(outliers - clean, axis=1) > 0
    assert abs(moved.mean() - 0.10) < 0.002
    assert np.abs(outliers).max() <= 0.52
    assert len(make_input(gt, domain, "sparse", seed)) == 10_000


def test_make_input_takes_a_condition_of_ones_own():
    seed = held_out_seeds("garments")[2]
    gt = make_shape("garments", seed)
    dense = replace(CONDITIONS["noisy"], name="dense-noisy", count=80_000)
    points = make_input(gt, "garments", dense, seed).points
    clean = make_input(gt, "garments", replace(dense, noise_sigma=0.0), seed).points
    assert len(points) == 80_000
    assert abs(np.std(points - clean) - 0.0025) < 0.0001


@pytest.mark.skipif(not os.path.isdir(os.path.join(dataset.shared_dir(), "data", "real")),
                    reason="shared real data not present")
def test_real_shapes_load_in_the_unit_frame():
    shapes = dataset.real_shapes()
    assert [name for name, _ in shapes] == [
        "bunny00", "fandisk", "mushroom", "horizons", "elephant-with-holes",
        "ChineseDragon-10kv", "owl", "plasticVase", "face000", "airplane", "blackVase",
        "birdBath"]
    for _, mesh in shapes:
        extent = np.ptp(mesh.vertices, axis=0)
        assert abs(extent.max() - 1.0) < 1e-9 and len(mesh.faces) > 0


@pytest.mark.skipif(not os.path.isdir(os.path.join(dataset.shared_dir(), "data", "real")),
                    reason="shared real data not present")
def test_real_domain_is_the_real_meshes_sampled_like_objects():
    assert held_out_seeds("real", 100) == list(range(len(dataset.REAL_SHAPES)))
    gt = make_shape("real", 6)  # the owl's mesh
    assert np.array_equal(gt.faces, dataset.real_shapes()[6][1].faces)
    cloud = make_input(gt, "real", "clean", 6)
    assert len(cloud.points) == CONDITIONS["clean"].count
    assert np.abs(cloud.points).max() <= 0.5 + 1e-9
    with pytest.raises(ValueError):
        make_shape("reals", 0)


def _square(size=1.0):
    """A square of two triangles in z = 0, facing +z."""
    v = np.array([[0, 0, 0], [size, 0, 0], [size, size, 0], [0, size, 0]], float)
    return Mesh(v, np.array([[0, 1, 2], [0, 2, 3]]))


def _area(mesh):
    corners = mesh.vertices[mesh.faces]
    return 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                         corners[:, 2] - corners[:, 0]), axis=1).sum()


def test_crop_follows_the_scan_not_the_mesh_cells():
    """Points on the left half of a square of two big triangles: the crop keeps the left half and
    a margin of at most max_dist, not the whole triangles the points touch."""
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(0, 0.5, 20000), rng.uniform(0, 1, 20000),
                              np.zeros(20000)])
    crop = crop_to_input(_square(), points, 0.01)
    assert 0.5 <= _area(crop) <= 0.5 + 0.01 + 0.002


def test_crop_with_normals_leaves_out_the_surface_hidden_beside_a_seen_one():
    """A wall stands on the floor; the scan saw the wall only. Without normals the floor strip
    within max_dist of the wall's foot is kept; with the scan's normals it is not seen."""
    rng = np.random.default_rng(1)
    points = np.column_stack([np.full(20000, 0.5), rng.uniform(0, 1, 20000),
                              rng.uniform(0, 0.5, 20000)])
    normals = np.tile([1.0, 0.0, 0.0], (len(points), 1))
    blind = crop_to_input(_square(), points, 0.01)
    assert _area(blind) >= 0.015  # a strip of about 2 x 0.01 along the foot
    seen = crop_to_input(_square(), points, 0.01, normals)
    assert len(seen.faces) == 0


def test_crop_with_normals_leaves_out_a_sheet_hidden_under_a_seen_one():
    """A board lies 0.007 above the floor, both facing +z; the scan saw the board's top only.
    The floor under it is within max_dist of the scan and faces as it does, but no scan point
    lies in its plane: it is not seen."""
    rng = np.random.default_rng(2)
    points = np.column_stack([rng.uniform(0, 1, 20000), rng.uniform(0, 1, 20000),
                              np.full(20000, 0.007)])
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    board = Mesh(_square().vertices + [0.0, 0.0, 0.007], _square().faces)
    both = Mesh(np.vstack([_square().vertices, board.vertices]),
                np.vstack([_square().faces, board.faces + 4]))
    crop = crop_to_input(both, points, 0.01, normals)
    assert _area(crop) == pytest.approx(_area(crop_to_input(board, points, 0.01, normals)))
    assert _area(crop) > 0.99 and np.allclose(crop.vertices[:, 2], 0.007)


def _near_reference(v, f, points, max_dist, normals=None):
    """``dataset._near`` written out probe by probe: each face's corners, edge midpoints and
    centroid, with the 8 nearest points of each (same surface with ``normals``)."""
    tree = cKDTree(points)
    keep = np.zeros(len(f), bool)
    for i, (a, b, c) in enumerate(v[f]):
        normal = np.cross(b - a, c - a)
        normal /= np.linalg.norm(normal)
        for probe in (a, b, c, (a + b) / 2, (b + c) / 2, (c + a) / 2, (a + b + c) / 3):
            dist, idx = tree.query(probe, k=8, distance_upper_bound=max_dist)
            for d, j in zip(dist, idx):
                if d > max_dist:
                    continue
                if normals is None or (abs(normals[j] @ normal) > 0.7
                                       and abs((points[j] - a) @ normal) < 0.25 * max_dist):
                    keep[i] = True
    return keep


@pytest.mark.parametrize("with_normals", [False, True])
def test_crop_probes_each_corner_midpoint_and_centroid(with_normals):
    """The crop's face test, which queries a corner or midpoint shared by several faces once,
    keeps exactly the faces that the probe-by-probe test keeps: a bumpy sheet of small faces
    and a scan of part of it, some points tilted away from it."""
    rng = np.random.default_rng(3)
    n = 24
    u, w = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    v = np.column_stack([u.ravel(), w.ravel(), 0.01 * np.sin(9 * u.ravel()) * np.cos(7 * w.ravel())])
    cell = np.arange(n * n).reshape(n, n)[:-1, :-1].ravel()
    f = np.concatenate([np.column_stack([cell, cell + n, cell + 1]),
                        np.column_stack([cell + 1, cell + n, cell + n + 1])])
    points = np.column_stack([rng.uniform(0, 0.6, 3000), rng.uniform(0, 1, 3000),
                              rng.normal(0, 0.004, 3000)])
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    normals[::3] = [0.8, 0.0, 0.6]  # tilted: not the sheet's own points
    normals = normals if with_normals else None
    keep = dataset._near(v, f, cKDTree(points), 0.02, normals)
    expected = _near_reference(v, f, points, 0.02, normals)
    assert 0 < expected.sum() < len(f)
    np.testing.assert_array_equal(keep, expected)
