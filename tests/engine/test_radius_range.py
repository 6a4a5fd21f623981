"""Each per-query radius mode has its own range unless the user sets one."""

import argparse
import json

import numpy as np
import pytest

from engine.commands import reconstruct as reconstruct_command
from engine.field import BAND_RADIUS_CAP, compute_udf_band
from engine.radius import max_radius, radii_for_queries
from engine.selector import DEFAULT_WEIGHTS
from engine.settings import MODE_RANGES, ReconstructSettings, radius_range


def test_the_learned_range_is_the_one_the_shipped_selector_was_trained_for():
    trained = json.loads(DEFAULT_WEIGHTS.with_suffix(".json").read_text())["args"]
    parent, rho_min, rho_max = MODE_RANGES["learned"]
    assert trained["parent_radius"] == pytest.approx(parent, rel=1e-6)
    assert trained["rho_min"] == pytest.approx(rho_min, rel=1e-6)
    assert trained["rho_max"] == pytest.approx(rho_max, rel=1e-6)


def test_each_mode_uses_its_own_range_until_a_custom_one_is_asked_for():
    assert radius_range(ReconstructSettings(radius_mode="curvature")) == (0.024, 0.5, 1.0)
    learned = ReconstructSettings(radius_mode="learned")
    assert radius_range(learned) == MODE_RANGES["learned"]
    assert max_radius(learned) == pytest.approx(0.072)
    custom = ReconstructSettings(radius_mode="learned", custom_range=True, parent_radius=0.03,
                                 rho_min=0.6, rho_max=0.9)
    assert radius_range(custom) == (0.03, 0.6, 0.9)
    assert max_radius(custom) == pytest.approx(0.027)
    # the range fields alone change nothing without custom_range
    assert radius_range(ReconstructSettings(radius_mode="learned", parent_radius=0.03)) == \
        MODE_RANGES["learned"]


def test_a_range_flag_on_the_command_line_makes_the_range_custom():
    parser = argparse.ArgumentParser()
    reconstruct_command.add_arguments(parser)
    plain = ReconstructSettings.from_attributes(
        parser.parse_args(["in.ply", "out.ply", "--radius-mode", "learned"]))
    assert not plain.custom_range and radius_range(plain) == MODE_RANGES["learned"]
    for flags in (["--parent-radius", "0.03"], ["--rho-min", "0.7"], ["--rho-max", "0.9"]):
        args = parser.parse_args(["in.ply", "out.ply", "--radius-mode", "curvature"] + flags)
        settings = ReconstructSettings.from_attributes(args)
        assert settings.custom_range, flags
    args = parser.parse_args(["in.ply", "out.ply", "--radius-mode", "curvature",
                              "--rho-min", "0.7"])
    assert radius_range(ReconstructSettings.from_attributes(args)) == (0.024, 0.7, 1.0)


def _plane(count=4000, seed=0):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-0.5, 0.5, (count, 2))
    return np.column_stack([xy, np.zeros(count)])


def test_learned_radii_span_the_selectors_range_and_the_band_stays_capped():
    from scipy.spatial import cKDTree

    points = _plane()
    queries = points[:500] + np.array([0.0, 0.0, 0.004])
    settings = ReconstructSettings(radius_mode="learned", resolution=64)
    radii = radii_for_queries(settings, cKDTree(points), points, queries)
    low, high = MODE_RANGES["learned"][1] * 0.072, 0.072
    assert radii.min() >= low - 1e-9 and radii.max() <= high + 1e-9
    field = compute_udf_band(points, settings)
    # the balls reach 0.072, the band of nearest-point distances stops at the cap
    assert field.stats["band_radius"] == pytest.approx(max(BAND_RADIUS_CAP, 3 / 64))


def test_a_large_fixed_radius_keeps_its_balls_but_not_its_band():
    points = _plane()
    field = compute_udf_band(points, ReconstructSettings(radius_mode="fixed",
                                                         resolution=128, radius=0.05),
                             udf_source="nearest")
    assert field.stats["band_radius"] == pytest.approx(BAND_RADIUS_CAP)
    assert max_radius(ReconstructSettings(radius_mode="fixed", radius=0.05)) == pytest.approx(0.05)


def test_the_custom_range_tooltip_names_each_modes_range():
    from dataclasses import fields

    from engine.settings import setting_info

    item = next(f for f in fields(ReconstructSettings) if f.name == "custom_range")
    text = setting_info(item).description
    for mode in ("curvature", "learned"):
        parent, rho_min, rho_max = MODE_RANGES[mode]
        assert f"{mode.title()} {rho_min * parent:.3f} to {rho_max * parent:.3f}" in text
