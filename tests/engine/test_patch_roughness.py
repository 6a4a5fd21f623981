"""Proofs for the selector's roughness features: what they read on known patches."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from engine.patch_roughness import MIN_POINTS, patch_roughness
from engine.patches import nearest_within, patches_from_neighbours

R = 0.024


def _features(points, queries, max_points=128):
    neighbours = nearest_within(cKDTree(points), queries, R, max_points)
    rel, mask, _ = patches_from_neighbours(points, queries, neighbours, R, max_points)
    return patch_roughness(rel, mask)


def _sheet(n, height, seed=0):
    rng = np.random.default_rng(seed)
    uv = rng.uniform(-0.1, 0.1, (n, 2))
    return np.column_stack([uv, height(uv)])


def test_a_plane_is_flat_and_a_smooth_quadric_leaves_no_residual():
    queries = np.array([[0.0, 0.0, 0.003], [0.02, -0.01, -0.002]])
    plane = _features(_sheet(20000, lambda uv: 0.0 * uv[:, 0]), queries)
    np.testing.assert_allclose(plane, 0.0, atol=1e-6)
    bowl = _features(_sheet(20000, lambda uv: 4.0 * uv[:, 0] ** 2 - 2.0 * uv[:, 1] ** 2), queries)
    assert np.all(bowl[:, 0] > 0.01)         # curvature thickens the patch...
    assert np.all(bowl[:, 1] < 2e-3)         # ...but a quadric follows it


@pytest.mark.parametrize("sigma", [0.001, 0.0025])
def test_the_quadric_residual_measures_the_noise(sigma):
    rng = np.random.default_rng(1)
    points = _sheet(2500, lambda uv: 3.0 * uv[:, 0] * uv[:, 1])  # ~110 points per ball
    points[:, 2] += rng.normal(0, sigma, len(points))
    queries = points[rng.choice(len(points), 50, replace=False)] * np.array([0.5, 0.5, 1.0])
    residual = _features(points, queries)[:, 1]
    # the fit absorbs 6 of ~100 degrees of freedom: the rms is a little under sigma
    assert np.median(residual) == pytest.approx(sigma / R, rel=0.15)


def test_too_few_points_read_zero_and_padding_is_ignored():
    points = np.array([[0.0, 0, 0], [0.01, 0, 0], [0, 0.01, 0], [0.01, 0.01, 0.005],
                       [0.005, 0.0, 0.01], [-0.01, 0.0, 0.0], [1.0, 1.0, 1.0]])
    assert MIN_POINTS == 7
    few = _features(points, np.zeros((1, 3)))        # 6 points in the ball
    np.testing.assert_array_equal(few, 0.0)
    sheet = _sheet(1500, lambda uv: 0.5 * uv[:, 0] ** 2)
    queries = sheet[:20]
    np.testing.assert_allclose(_features(sheet, queries, 128), _features(sheet, queries, 300),
                               atol=1e-6)            # ball holds < 128: same with more padding


def test_the_split_tells_two_close_sheets_from_noise():
    """Two flat sheets a tenth of R apart read a split near 1; one sheet with noise of the same
    rms height reads about 2/pi, as Gaussian heights do; a plane reads 0."""
    rng = np.random.default_rng(2)
    gap = 0.1 * R
    def flat(n, seed):
        return _sheet(n, lambda uv: 0.0 * uv[:, 0], seed)

    lower = flat(2000, 3)
    two = np.concatenate([lower, flat(2000, 4) + (0.0, 0.0, gap)])
    noisy = flat(4000, 5)
    noisy[:, 2] += rng.normal(0, gap / 2, len(noisy))
    queries = rng.uniform(-0.05, 0.05, (40, 3)) * (1.0, 1.0, 0.1)
    split = {name: _features(points, queries)[:, 2] for name, points in
             (("two", two), ("noisy", noisy), ("plane", lower))}
    assert np.median(split["two"]) > 0.95
    assert np.median(split["noisy"]) == pytest.approx(2 / np.pi, abs=0.06)
    np.testing.assert_allclose(split["plane"], 0.0, atol=1e-3)
