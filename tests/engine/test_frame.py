import dataclasses

import numpy as np
import pytest

from engine.errors import InputError
from engine.frame import (LARGEST_COORDINATE, MIN_POINTS, SMALLEST_EXTENT, UnitFrame,
                          validate_points)


def _cloud(n=2000, seed=0, offset=(0.0, 0.0, 0.0), size=(1.0, 1.0, 1.0)):
    rng = np.random.default_rng(seed)
    return rng.uniform(-0.5, 0.5, (n, 3)) * np.asarray(size) + np.asarray(offset)


def test_from_unit_inverts_to_unit_to_float64_rounding():
    points = _cloud(offset=(5.0e5, -4.2e6, 120.0), size=(80.0, 35.0, 12.5))
    frame = UnitFrame.from_points(points)
    back = frame.from_unit(frame.to_unit(points))
    relative = np.max(np.abs(back - points)) / np.max(np.abs(points))
    assert relative < 1e-12
    # The other way the error is the world coordinates' rounding, seen in unit lengths.
    unit = np.random.default_rng(1).uniform(-0.5, 0.5, (1000, 3))
    world_ulp = np.finfo(np.float64).eps * np.max(np.abs(points)) / frame.scale
    np.testing.assert_allclose(frame.to_unit(frame.from_unit(unit)), unit, rtol=0,
                               atol=2 * world_ulp)


def test_unit_frame_box_is_centred_with_longest_side_one():
    points = _cloud(offset=(3.0, -7.0, 1000.0), size=(4.0, 9.0, 2.0))
    frame = UnitFrame.from_points(points)
    unit = frame.to_unit(points)
    low, high = unit.min(axis=0), unit.max(axis=0)
    np.testing.assert_allclose(low + high, 0.0, atol=1e-15)
    side = high - low
    assert np.argmax(side) == 1
    assert abs(side[1] - 1.0) <= 2 * np.finfo(np.float64).eps
    assert np.all(side <= 1.0 + 2 * np.finfo(np.float64).eps)
    np.testing.assert_allclose(frame.center, (points.min(0) + points.max(0)) / 2, rtol=1e-15)
    assert frame.scale == np.max(points.max(0) - points.min(0))


def test_frame_is_frozen_and_accepts_integer_lists():
    grid = [[x, y, (x * y) % 3] for x in range(4) for y in range(4)]
    frame = UnitFrame.from_points(grid)
    np.testing.assert_array_equal(frame.center, [1.5, 1.5, 1.0])
    assert frame.scale == 3.0 and isinstance(frame.scale, float)
    assert frame.center.dtype == np.float64
    with pytest.raises(dataclasses.FrozenInstanceError):
        frame.scale = 2.0
    with pytest.raises(ValueError):
        frame.center[0] = 9.0  # read-only: the frame cannot drift after use
    with pytest.raises(InputError, match="positive scale"):
        UnitFrame(center=np.zeros(3), scale=0.0)


def test_a_flat_square_is_a_valid_surface():
    points = _cloud(size=(1.0, 1.0, 0.0))
    assert validate_points(points) is points  # float64 input is not copied
    assert UnitFrame.from_points(points).scale > 0.99


@pytest.mark.parametrize("points, fragments", [
    ("not points", ["(N, 3) array of numbers", "str"]),
    ([["a", "b", "c"]] * 20, ["(N, 3) array of numbers"]),
    (np.zeros((20, 2)), ["(N, 3) array", "shape (20, 2)"]),
    (np.zeros(3), ["shape (3,)"]),
    (np.zeros((0, 3)), ["empty"]),
    (np.eye(3)[[0, 1, 2, 0, 1]] + [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]],
     ["only 5 points", f"at least {MIN_POINTS}"]),
    (np.ones((50, 3)) * [1.0, 2.0, 3.0], ["all 50 points are at the same position",
                                          "[1.0, 2.0, 3.0]"]),
])
def test_unusable_inputs_are_refused_with_what_to_do(points, fragments):
    with pytest.raises(InputError) as caught:
        UnitFrame.from_points(points)
    for fragment in fragments:
        assert fragment in str(caught.value), str(caught.value)


def test_nan_and_inf_are_counted():
    points = _cloud(50)
    points[3, 0], points[7, 2], points[9] = np.nan, np.inf, -np.inf
    with pytest.raises(InputError, match=r"^3 of 50 points have NaN or infinite coordinates; "
                                         r"remove them"):
        validate_points(points)


def test_duplicates_are_allowed_but_not_as_a_substitute_for_distinct_points():
    few = _cloud(MIN_POINTS - 1)
    with pytest.raises(InputError, match=rf"only {MIN_POINTS - 1} distinct points "
                                         rf"\({20 * (MIN_POINTS - 1)} with duplicates\)"):
        validate_points(np.tile(few, (20, 1)))
    enough = np.tile(_cloud(MIN_POINTS), (20, 1))
    assert validate_points(enough).shape == (20 * MIN_POINTS, 3)


def test_distinct_points_beyond_the_leading_sample_are_counted():
    # 10000 copies of one point, then the cloud: only the full count can accept it.
    points = np.concatenate([np.zeros((10000, 3)), _cloud(MIN_POINTS, seed=3)])
    assert validate_points(points).shape == (10000 + MIN_POINTS, 3)
    with pytest.raises(InputError, match=f"only {MIN_POINTS - 1} distinct points"):
        validate_points(points[:-2])


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (4.0e5, 3.0e6, 250.0), (1e8, 1e8, 1e8),
                                    (1e10, -3e9, 5e9)])
def test_points_on_a_line_are_refused(offset):
    t = np.random.default_rng(4).uniform(-10, 10, 500)
    points = np.outer(t, [0.3, -0.5, 0.8]) + np.asarray(offset)
    with pytest.raises(InputError, match="all points lie on a line; a surface needs a 2-D "
                                         "spread"):
        validate_points(points)
    # A thin but real strip is a surface.
    points[::2] += np.asarray([0.0, 0.0, 1e-3]) * 20.0
    assert validate_points(points).shape == (500, 3)


def test_a_million_points_validate_quickly():
    import time

    points = _cloud(1_000_000, seed=5)
    start = time.perf_counter()
    UnitFrame.from_points(points)
    assert time.perf_counter() - start < 1.0


@pytest.mark.parametrize("scale, fragment", [(1e-300, "the points span only"),
                                             (1e-160, "the points span only"),
                                             (1e160, "coordinates reach"),
                                             (1e300, "coordinates reach")])
def test_absurd_scales_are_refused_with_what_to_do(scale, fragment):
    points = _cloud(seed=6) * scale  # a cube: only its scale is wrong
    with pytest.raises(InputError, match=fragment) as caught:
        UnitFrame.from_points(points)
    assert "rescale the cloud" in str(caught.value)


def test_scales_inside_the_limits_keep_their_shape():
    points = _cloud(seed=7)
    for scale in (SMALLEST_EXTENT * 10, 1e-20, 1e20, LARGEST_COORDINATE / 10):
        assert UnitFrame.from_points(points * scale).scale == pytest.approx(
            UnitFrame.from_points(points).scale * scale, rel=1e-12)
    line = np.outer(np.linspace(-1, 1, 100), [0.6, 0.8, 0.0])
    for scale in (SMALLEST_EXTENT * 10, LARGEST_COORDINATE / 10):
        with pytest.raises(InputError, match="lie on a line"):
            validate_points(line * scale)
