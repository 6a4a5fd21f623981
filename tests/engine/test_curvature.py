import numpy as np
from scipy.spatial import cKDTree

from engine.curvature import curvature_radii, surface_variation

R = 0.024


def _plane(rng, n=40000):
    xy = rng.uniform(-0.5, 0.5, (n, 2))
    return np.column_stack([xy, np.zeros(n)])


def _cylinder(rng, radius, n=None):
    n = n or int(33000 * 2 * np.pi * radius)  # benchmark density: ~33k points per unit area
    theta = rng.uniform(0, 2 * np.pi, n)
    return np.column_stack([radius * np.cos(theta), radius * np.sin(theta),
                            rng.uniform(-0.5, 0.5, n)])


def test_plane_has_zero_variation_and_gets_the_largest_radius():
    points = _plane(np.random.default_rng(0))
    queries = np.array([[0.0, 0.0, 0.005], [0.1, -0.2, -0.01]])
    sigma, counts = surface_variation(cKDTree(points), points, queries, R)
    assert np.all(counts > 20)
    assert np.all(sigma < 1e-12)
    radii = curvature_radii(cKDTree(points), points, queries, R, 0.5, 1.0)
    np.testing.assert_allclose(radii, R)


def test_tighter_bends_get_smaller_radii_monotonically():
    rng = np.random.default_rng(1)
    radii = []
    for bend in (0.3, 0.1, 0.03, 0.015):
        points = _cylinder(rng, bend)
        tree = cKDTree(points)
        radii.append(curvature_radii(tree, points, np.array([[bend, 0, 0]]), R, 0.5, 1.0)[0])
    assert all(a >= b for a, b in zip(radii, radii[1:])), radii
    assert radii[0] > 0.9 * R and radii[-1] < 0.6 * R


def test_two_close_sheets_get_a_small_radius():
    rng = np.random.default_rng(2)
    sheet = _plane(rng, 30000)
    points = np.concatenate([sheet, sheet + [0, 0, 0.012]])
    radius = curvature_radii(cKDTree(points), points, np.array([[0, 0, 0.006]]), R, 0.5, 1.0)
    assert radius[0] < 0.6 * R


def test_radii_follow_the_requested_range_and_sparse_balls_keep_the_largest():
    rng = np.random.default_rng(3)
    points = np.concatenate([_cylinder(rng, 0.02, 20000), [[0.4, 0.4, 0.4]]])
    queries = np.array([[0.02, 0.0, 0.0], [0.4, 0.4, 0.41]])
    radii = curvature_radii(cKDTree(points), points, queries, R, 0.7, 0.9)
    assert 0.7 * R - 1e-12 <= radii[0] <= 0.9 * R + 1e-12
    assert radii[1] == np.float64(0.9 * R)  # a lone point: too few to judge
