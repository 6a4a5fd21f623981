"""The UDF band: the right nodes, the right values, truncated safely, cancellable."""

import os

import numpy as np
import pytest
import torch  # a runtime requirement (requirements.txt): never skipped
from scipy.spatial import cKDTree

from engine.errors import Cancelled, InputError
from engine.field import compute_udf_band, resolve_device
from engine.settings import ReconstructSettings


def sphere_points(count=4000, radius=0.4, seed=0):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(count, 3))
    return radius * points / np.linalg.norm(points, axis=1, keepdims=True)


def node_positions(grid):
    axes = [grid.origin[a] + np.arange(grid.shape[a]) * grid.spacing for a in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def band_of(grid):
    flat, values = grid._band
    return flat, values


def test_band_is_exactly_the_nodes_within_the_radius():
    points = sphere_points()
    # the gap fill would add nodes past the band where the 4000 points leave gaps
    settings = ReconstructSettings(radius_mode="fixed",
                                   resolution=160, radius=0.022, fill_gaps=False)
    band = compute_udf_band(points, settings, udf_source="nearest")
    grid = band.grid
    # brute force over every node of the grid (160^3-ish nodes: cheap enough)
    distance, _ = cKDTree(points).query(node_positions(grid), k=1, workers=-1)
    radius = band.stats["band_radius"]
    assert radius == pytest.approx(0.022)
    want = np.flatnonzero(distance <= radius)
    flat, values = band_of(grid)
    np.testing.assert_array_equal(np.sort(flat), want)
    np.testing.assert_allclose(values, distance[flat], rtol=1e-6, atol=1e-7)
    # the grid covers the cloud and the whole band, with margin on every side
    assert np.all(grid.origin < points.min(axis=0) - radius)
    assert np.all(grid.index_to_world(np.array(grid.shape) - 1) > points.max(axis=0) + radius)


def test_coarse_grids_widen_the_band_to_a_few_spacings():
    points = sphere_points()
    band = compute_udf_band(points, ReconstructSettings(radius_mode="fixed",
                                                        resolution=32, radius=0.018),
                            udf_source="nearest")
    spacing = band.stats["spacing"]
    assert band.stats["band_radius"] == pytest.approx(3 * spacing)
    flat, values = band_of(band.grid)
    assert values.max() <= 3 * spacing + 1e-7


def test_far_nodes_hold_at_least_the_radius():
    points = sphere_points()
    settings = ReconstructSettings(radius_mode="fixed", resolution=64, radius=0.05)
    band = compute_udf_band(points, settings, udf_source="nearest")
    grid, radius = band.grid, band.stats["band_radius"]  # 3 spacings: the band's cap is below
    dense = np.concatenate([grid.slab(x, x + 1).reshape(-1) for x in range(grid.shape[0])])
    distance, _ = cKDTree(points).query(node_positions(grid), k=1, workers=-1)
    far = distance > radius
    assert grid.far_value >= radius
    assert np.all(dense[far] >= radius)
    # the field never claims a node is farther than it is, where it is below the truncation
    assert np.all(dense[~far] <= distance[~far] + 1e-6)


def nearest_through_patches(rel, mask):
    """Predicts UDF / r as the first patch point's distance: exact for a dense sampling."""
    return np.where(mask[:, 0], np.linalg.norm(rel[:, 0], axis=1), 0.0)


def test_network_plumbing_scales_by_each_query_radius():
    # a predictor that reads the nearest patch point reproduces the nearest-point distance only
    # if the patches are gathered at the right radius and the output is multiplied back by it
    points = sphere_points()
    settings = ReconstructSettings(radius_mode="fixed", resolution=64, radius=0.05)
    network = compute_udf_band(points, settings, predictor=nearest_through_patches)
    nearest = compute_udf_band(points, settings, udf_source="nearest")
    flat_n, values_n = band_of(network.grid)
    flat_d, values_d = band_of(nearest.grid)
    np.testing.assert_array_equal(flat_n, flat_d)
    np.testing.assert_allclose(values_n, values_d, rtol=1e-5, atol=1e-7)
    assert network.stats["sparse_balls"] < 0.2 * network.stats["band_nodes"]
    assert network.stats["mean_patch_points"] > 5


def test_curvature_radii_reach_the_field():
    points = sphere_points(count=8000)
    settings = ReconstructSettings(resolution=64, radius_mode="curvature", custom_range=True,
                                   parent_radius=0.05, rho_min=0.5, rho_max=1.0)
    band = compute_udf_band(points, settings, predictor=nearest_through_patches)
    assert band.stats["band_radius"] == pytest.approx(3 / 64)  # the cap, widened to 3 nodes
    nearest = compute_udf_band(points, settings, udf_source="nearest")
    # band nodes whose smaller ball holds too few points use the nearest-point distance
    np.testing.assert_allclose(band_of(band.grid)[1], band_of(nearest.grid)[1], rtol=1e-5,
                               atol=1e-7)


def test_every_radius_mode_has_a_policy_and_an_unknown_one_is_refused():
    from engine.radius import POLICIES
    from engine.settings import RADIUS_MODES

    assert set(POLICIES) == set(RADIUS_MODES)
    with pytest.raises(InputError, match="radius mode must be one of fixed, curvature, learned"):
        compute_udf_band(sphere_points(), ReconstructSettings(resolution=64, radius_mode="auto"))


def test_cancel_stops_the_field():
    calls = []

    def cancel():
        calls.append(1)
        return len(calls) > 1

    settings = ReconstructSettings(radius_mode="fixed", resolution=64, radius=0.03)
    with pytest.raises(Cancelled):
        compute_udf_band(sphere_points(), settings, cancel=cancel,
                         predictor=nearest_through_patches)


def test_auto_picks_cuda_only_where_there_is_one_and_cuda_is_refused_clearly_elsewhere():
    assert resolve_device("cpu") == "cpu"
    if torch.cuda.is_available():
        assert resolve_device("auto") == resolve_device("cuda") == "cuda"
    else:
        assert resolve_device("auto") == "cpu"
        with pytest.raises(InputError, match="cuda"):
            resolve_device("cuda")


def test_auto_on_a_machine_without_an_nvidia_driver_does_not_import_torch():
    import subprocess
    import sys

    code = ("import sys, engine.devices as d; d._no_nvidia_driver = lambda: True; "
            "print(d.resolve_device('auto'), 'torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))))
    assert out.stdout.split() == ["cpu", "False"]


def test_trimming_the_padding_leaves_the_backbone_output_unchanged(tmp_path):
    from engine.backbone import build_backbone_torch, load_backbone_numpy, save_backbone
    from engine.field import predict_trimmed
    from engine.patches import gather_patches

    torch.manual_seed(0)
    path = save_backbone(build_backbone_torch(), tmp_path / "random.npz")
    network = load_backbone_numpy(path)
    points = sphere_points(count=20000)
    queries = points[:2000] + np.random.default_rng(1).normal(scale=0.01, size=(2000, 3))
    rel, mask, counts = gather_patches(cKDTree(points), points, queries, 0.03)
    keep = counts > 0
    rel, mask, counts = rel[keep], mask[keep], counts[keep]
    assert counts.min() < 16 and counts.max() < 64
    whole = network.predict(rel, mask)
    trimmed = predict_trimmed(network.predict, rel, mask, counts, group_size=256)
    np.testing.assert_allclose(trimmed, whole, rtol=1e-5, atol=1e-6)
    # on two threads (each with a one-thread BLAS): the same answers, and the same every time
    threaded = predict_trimmed(network.predict, rel, mask, counts, group_size=256, threads=2)
    np.testing.assert_allclose(threaded, whole, rtol=1e-5, atol=1e-6)
    again = predict_trimmed(network.predict, rel, mask, counts, group_size=256, threads=2)
    np.testing.assert_array_equal(threaded, again)


def plane_height_predictor(rel, mask):
    """A stand-in backbone that is exact for points on one plane z = const: the patch
    centroid's height, |mean z| (in units of r, as the backbone answers)."""
    count = np.maximum(mask.sum(axis=1), 1)
    return np.abs((rel[:, :, 2] * mask).sum(axis=1) / count)


def test_balls_with_too_few_points_are_widened_not_left_to_the_nearest_point():
    # a plane sampled every 0.03: a ball of r = 0.018 between four samples holds none of them;
    # the nearest-point fallback would dent the field there (and wrap samples in bubbles)
    step = 0.03
    xy = np.stack(np.meshgrid(np.arange(-0.3, 0.3001, step), np.arange(-0.3, 0.3001, step),
                              indexing="ij"), axis=-1).reshape(-1, 2)
    points = np.column_stack([xy, np.zeros(len(xy))])
    settings = ReconstructSettings(radius_mode="fixed", resolution=128, radius=0.018)
    band = compute_udf_band(points, settings, predictor=plane_height_predictor)
    assert band.stats["widened_balls"] > 0 and band.stats["sparse_balls"] == 0
    flat, values = band_of(band.grid)
    nodes = node_positions(band.grid)[flat]
    inner = np.all(np.abs(nodes[:, :2]) < 0.25, axis=1)
    near = cKDTree(points).query(nodes)[0] <= 3 * band.stats["spacing"]  # the network's nodes
    chosen = inner & near
    np.testing.assert_allclose(values[chosen], np.abs(nodes[chosen, 2]), atol=1e-6)


def test_an_isolated_point_keeps_the_nearest_point_distance():
    points = np.concatenate([sphere_points(), [[0.0, 0.0, 0.0]]])  # the centre: far from all
    band = compute_udf_band(points, ReconstructSettings(radius_mode="fixed",
                                                        resolution=64, radius=0.03),
                            predictor=plane_height_predictor)
    assert band.stats["sparse_balls"] > 0
    flat, values = band_of(band.grid)
    nodes = node_positions(band.grid)[flat]
    centre = np.linalg.norm(nodes, axis=1) < 0.02
    np.testing.assert_allclose(values[centre], np.linalg.norm(nodes[centre], axis=1), rtol=1e-5)


def _lattice_square(step, half=0.3):
    """Points of the square [-half, half]^2 in z = 0 on a lattice of ``step``."""
    g = np.arange(-half, half + 1e-9, step)
    x, y = np.meshgrid(g, g, indexing="ij")
    return np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])


def test_a_sparse_scan_is_meshed_without_holes_between_its_samples():
    """A square sampled every 4.5 spacings (at 128): midway between four samples the surface is
    3.2 spacings from every point. The network is asked there as well, and the mesh covers the
    square; a dense square gets no more network queries than the 3-spacing band."""
    from engine.field import NETWORK_BAND_NODES, _network_nodes, find_band, grid_layout
    from engine.meshing import extract_surface
    from engine.sampling import face_areas_and_normals

    settings = ReconstructSettings(resolution=128)
    sparse = _lattice_square(4.5 / 128)
    band = compute_udf_band(sparse, settings)
    mesh = extract_surface(band.grid).mesh
    inside = (np.abs(mesh.vertices[:, :2]) <= 0.3).all(axis=1)[mesh.faces].all(axis=1)
    area = face_areas_and_normals(mesh.vertices, mesh.faces[inside])[0].sum()
    assert area >= 0.97 * 0.6 ** 2

    for points, widened in ((sparse, True), (_lattice_square(0.5 / 128), False)):
        tree, h = cKDTree(points), 1 / 128
        shape, origin, _ = grid_layout(points, 128, 6 * h)
        indices, nearest, owner = find_band(tree, points, shape, origin, h, 6 * h,
                                            with_owner=True)
        asked = _network_nodes(tree, points, nearest, owner, h)
        three = nearest <= NETWORK_BAND_NODES * h
        assert (asked >= three).all() and (asked.sum() > three.sum()) == widened
