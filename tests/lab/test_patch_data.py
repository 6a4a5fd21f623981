"""Synthetic patch generator: exact ground truth, the patch contract, family coverage."""

import numpy as np
import pytest

from engine.patches import MAX_POINTS
from lab.training import patch_data as pd


def test_ground_truth_plane_is_abs_z():
    rng = np.random.default_rng(0)
    q = rng.uniform(-0.8, 0.8, (500, 3))
    sheet = pd.Sheet(lambda x, y: 0.0 * x)
    np.testing.assert_allclose(pd.height_field_distance(q, sheet), np.abs(q[:, 2]), atol=1e-6)


@pytest.mark.parametrize("radius", [0.6, 1.5])
def test_ground_truth_sphere(radius):
    """Lower cap of a sphere of centre (0, 0, R): distance | |q - c| - R |, both sides."""
    rng = np.random.default_rng(1)
    q = rng.uniform(-0.3, 0.3, (500, 3))
    sheet = pd.Sheet(lambda x, y: radius - np.sqrt(np.maximum(radius ** 2 - x * x - y * y, 0.0)),
                     lambda x, y: x * x + y * y < radius ** 2)
    exact = np.abs(np.linalg.norm(q - np.array([0.0, 0.0, radius]), axis=1) - radius)
    assert np.abs(pd.height_field_distance(q, sheet) - exact).max() < 1e-3


def test_ground_truth_concave_paraboloid_beyond_focal_distance():
    """Inside z = k(x^2 + y^2)/2 above the focal point the nearest point leaves the axis."""
    k = 2.0
    sheet = pd.Sheet(lambda x, y: 0.5 * k * (x * x + y * y))
    z = np.array([0.2, 0.9])
    q = np.stack([0 * z, 0 * z, z], axis=1)
    # Exact: minimise rho^2 + (k rho^2 / 2 - z)^2 over rho >= 0.
    rho = np.linspace(0, 1.5, 200001)[None, :]
    exact = np.sqrt(np.min(rho ** 2 + (0.5 * k * rho ** 2 - z[:, None]) ** 2, axis=1))
    np.testing.assert_allclose(pd.height_field_distance(q, sheet), exact, atol=1e-4)
    assert exact[1] < z[1] - 1e-3   # the second query really is beyond the focal distance


def test_ground_truth_truncated_plane():
    """Half-plane x <= 0: points past the edge measure to the edge line."""
    sheet = pd.Sheet(lambda x, y: 0.0 * x, lambda x, y: x <= 0.0)
    q = np.array([[-0.3, 0.1, 0.4], [0.5, -0.2, 0.3], [0.2, 0.0, 0.0]])
    exact = np.array([0.4, np.hypot(0.5, 0.3), 0.2])
    assert np.abs(pd.height_field_distance(q, sheet) - exact).max() < 1e-3


def test_ground_truth_crease_apex():
    sheet = pd.Sheet(lambda x, y: -2.0 * np.abs(x))
    q = np.array([[0.0, 0.3, 0.5], [0.0, 0.0, -0.4]])
    # Above the ridge the apex line is nearest; below, the distance to either plane.
    exact = np.array([0.5, 0.4 / np.sqrt(5.0)])
    assert np.abs(pd.height_field_distance(q, sheet) - exact).max() < 1e-3


def test_generated_patches_follow_the_contract():
    rng = np.random.default_rng(2)
    data = pd.generate_patches(3000, rng)
    rel, mask, udf = data["rel"], data["mask"], data["udf"]
    assert rel.shape == (3000, MAX_POINTS, 3) and rel.dtype == np.float32
    assert mask.shape == (3000, MAX_POINTS) and mask.dtype == bool
    dist = np.linalg.norm(rel, axis=2)
    assert mask[:, 0].all()                                   # at least one real point
    assert (dist[mask] <= 1.0 + 1e-6).all()                   # inside the unit ball
    assert (rel[~mask] == 0).all()                            # zero padding
    assert (np.diff(mask.astype(int), axis=1) <= 0).all()     # real rows form a prefix
    d = np.where(mask, dist, 2.0)
    assert (np.diff(d, axis=1) >= -1e-6).all()                 # sorted nearest first
    assert ((udf >= 0) & (udf <= pd.MAX_UDF)).all()
    counts = mask.sum(axis=1)
    assert counts.min() <= 3 and counts.max() == MAX_POINTS
    assert 0.2 < (counts <= 16).mean() < 0.8
    assert set(np.unique(data["family"])) == set(range(len(pd.FAMILIES)))
    assert 0.2 < (data["noise"] > 0).mean() < 0.4


def test_rotations_are_uniform():
    """Uniform on SO(3): the image of a fixed axis has mean ~0 and every octant is hit."""
    rot = pd._random_rotations(np.random.default_rng(3), 20000)
    np.testing.assert_allclose(np.einsum("nij,nkj->nik", rot, rot), np.broadcast_to(np.eye(3), rot.shape), atol=1e-9)
    z = rot[:, :, 2]
    assert np.abs(z.mean(axis=0)).max() < 0.03
    octants = np.unique((z > 0) @ np.array([1, 2, 4]))
    assert len(octants) == 8


def test_generation_is_reproducible():
    a = pd.generate_patches(300, np.random.default_rng(5))
    b = pd.generate_patches(300, np.random.default_rng(5))
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])


def test_nearest_point_baseline():
    rel = np.zeros((1, MAX_POINTS, 3), np.float32)
    rel[0, 0] = [0.0, 0.3, 0.4]
    rel[0, 1] = [0.0, 0.0, -0.8]
    mask = np.zeros((1, MAX_POINTS), bool)
    mask[0, :2] = True
    np.testing.assert_allclose(pd.nearest_point_baseline(rel, mask), [0.5], rtol=1e-6)
