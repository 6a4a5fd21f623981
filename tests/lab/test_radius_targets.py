import numpy as np
import pytest

from lab.training.radius_targets import (CANDIDATE_RADII, candidate_radii, expected_errors,
                                         inset_targets, loss_weights, parabola_targets,
                                         selector_loss)


def test_candidate_radii_are_the_papers_seven():
    np.testing.assert_allclose(CANDIDATE_RADII, [0.012, 0.014, 0.016, 0.018, 0.020, 0.022, 0.024])


@pytest.mark.parametrize("vertex", [0.0151, 0.017, 0.0183, 0.0209, 0.0222])
def test_parabola_recovers_a_known_vertex_exactly(vertex):
    errors = 3.0 * (CANDIDATE_RADII - vertex) ** 2 + 0.01
    assert parabola_targets(errors[None])[0] == pytest.approx(vertex, abs=1e-12)


def test_minimum_at_either_end_falls_back_to_the_grid():
    rising = 0.01 + CANDIDATE_RADII  # best at the smallest radius
    falling = 0.05 - CANDIDATE_RADII  # best at the largest radius
    targets = parabola_targets(np.stack([rising, falling]))
    np.testing.assert_allclose(targets, [0.012, 0.024])


def test_non_convex_or_flat_neighbourhood_falls_back_to_the_grid_minimum():
    flat = np.full(7, 0.02)
    kink = np.array([0.05, 0.04, 0.03, 0.01, 0.01, 0.03, 0.05])  # tie: argmin is the first
    targets = parabola_targets(np.stack([flat, kink]))
    assert targets[0] == pytest.approx(0.012)
    # the tie at indices 3 and 4 is convex around index 3: vertex half-way towards index 4
    assert 0.018 <= targets[1] <= 0.019


def test_targets_stay_within_half_a_step_of_the_grid_minimum():
    rng = np.random.default_rng(0)
    errors = rng.random((5000, 7))
    targets = parabola_targets(errors)
    grid_best = CANDIDATE_RADII[np.argmin(errors, axis=1)]
    assert np.all(np.abs(targets - grid_best) <= 0.001 + 1e-12)
    assert targets.min() >= 0.012 and targets.max() <= 0.024


def test_loss_weight_is_zero_where_the_error_curve_is_flat():
    errors = np.stack([np.full(7, 0.3), np.linspace(0.1, 0.4, 7)])
    np.testing.assert_allclose(loss_weights(errors), [0.0, 0.3])
    # a flat query contributes nothing to the loss however wrong the prediction is
    assert selector_loss(np.array([0.024]), np.array([0.012]), np.array([0.0]), 0.012, 0.024) == 0


def test_selector_loss_is_normalised_by_the_radius_span():
    loss = selector_loss(np.array([0.018]), np.array([0.012]), np.array([2.0]), 0.012, 0.024)
    assert loss == pytest.approx(2.0 * 0.006 / 0.012)


def test_expected_errors_average_the_nearest_queries_curves():
    queries = np.array([[0.0, 0, 0], [0.001, 0, 0], [1.0, 0, 0], [1.001, 0, 0]])
    errors = np.array([[1.0, 2.0], [3.0, 4.0], [10.0, 20.0], [30.0, 40.0]])
    np.testing.assert_array_equal(expected_errors(errors, queries, 1), errors)
    np.testing.assert_allclose(expected_errors(errors, queries, 2),
                               [[2, 3], [2, 3], [20, 30], [20, 30]])
    # more neighbours than queries: every curve becomes the shape's mean curve
    np.testing.assert_allclose(expected_errors(errors, queries, 99), [[11, 16.5]] * 4)


def test_a_curve_whose_noise_hides_its_vertex_gets_it_back_in_expectation():
    """Per-query curves = a parabola with its vertex at 0.017 plus noise: their own targets
    scatter over the grid, the expected curves' targets gather at the vertex."""
    rng = np.random.default_rng(0)
    curve = (CANDIDATE_RADII - 0.017) ** 2 * 1e3
    errors = curve + rng.normal(0, 0.03, (2000, 7))
    queries = rng.uniform(0, 1, (2000, 3))
    raw = parabola_targets(errors)
    expected = parabola_targets(expected_errors(errors, queries, 64))
    assert np.std(raw) > 3 * np.std(expected)
    assert abs(np.median(expected) - 0.017) < 0.0005


def test_inset_keeps_targets_off_the_ends_of_the_range():
    targets = np.array([0.012, 0.0125, 0.018, 0.024])
    np.testing.assert_allclose(inset_targets(targets, 0.012, 0.024, 0.05),
                               [0.0126, 0.0126, 0.018, 0.0234])
    np.testing.assert_array_equal(inset_targets(targets, 0.012, 0.024, 0.0), targets)


def test_log_spaced_radii_take_the_parabola_in_log_r():
    radii = candidate_radii(0.015, 0.072, 10, "log")
    np.testing.assert_allclose(radii[1] / radii[0], radii[-1] / radii[-2])
    vertex = 0.033
    errors = 2.0 * (np.log(radii) - np.log(vertex)) ** 2 + 0.01
    assert parabola_targets(errors[None], radii)[0] == pytest.approx(vertex, rel=1e-9)
    # at the ends: the end radius itself
    assert parabola_targets((radii - 0.01)[None], radii)[0] == pytest.approx(0.015, rel=1e-12)
    with pytest.raises(ValueError, match="evenly spaced"):
        parabola_targets(errors[None], np.array([0.01, 0.02, 0.05] + list(radii[3:])))


def test_balanced_held_out_shapes_are_never_trained_on_and_cover_each_condition_alike():
    import argparse

    import pytest

    from lab.training import train_selector as ts
    from lab.training.selector_data import TRAINING_CONDITIONS, condition_of

    conditions = [TRAINING_CONDITIONS[condition_of(seed)] for seed in ts.BALANCED_SEEDS]
    assert sorted(conditions.count(name) for name in TRAINING_CONDITIONS) == [5, 5, 5]
    args = argparse.Namespace(shapes=40, dense_shapes=10, dense_points=150_000)
    trained = {seed for _, seed, _, _ in ts.training_shapes(args)}
    assert trained.isdisjoint(ts.BALANCED_SEEDS)
    assert trained.isdisjoint(ts.held_out_seeds(args))
    with pytest.raises(SystemExit):  # dense shapes would reach the balanced ones
        ts.main(["--shapes", "40", "--dense-shapes", "60"])


def test_selector_evaluation_compares_against_the_radii_the_selector_was_trained_with(tmp_path):
    import json
    from engine.selector import DEFAULT_WEIGHTS
    from lab.training.evaluate_selector import training_grid
    record = json.loads(DEFAULT_WEIGHTS.with_suffix(".json").read_text())["args"]
    assert training_grid(str(DEFAULT_WEIGHTS)) == (record["candidates"], record["spacing"])
    (tmp_path / "other.json").write_text(json.dumps({"args": {"candidates": 7,
                                                              "spacing": "linear"}}))
    assert training_grid(str(tmp_path / "other.npz")) == (7, "linear")
    with pytest.raises(SystemExit, match="training record"):
        training_grid(str(tmp_path / "missing.npz"))
