"""The radius policy on a coarser lattice: which step, exact blends, fewer policy positions, the
same field on any number of threads, and tiles that agree on their shared nodes."""

import numpy as np
import pytest

from engine import field, radius, radius_lattice
from engine.field import compute_udf_band
from engine.radius_lattice import lattice_radii, lattice_step
from engine.settings import ReconstructSettings

from .test_field_threads import sphere_points


def test_the_step_keeps_the_lattice_between_a_quarter_and_an_eighth_of_the_parent_radius():
    assert lattice_step(0.072, 1 / 256) == 4   # 0.0156 apart: R / 4.6
    assert lattice_step(0.072, 1 / 128) == 2   # the same 0.0156
    assert lattice_step(0.072, 1 / 64) == 1
    assert lattice_step(0.024, 1 / 256) == 1   # the curvature estimate's R: every node its own
    for spacing in (1 / 100, 1 / 300, 1 / 1000):
        step = lattice_step(0.072, spacing)
        assert step == 1 or 0.072 / 8 <= step * spacing <= 0.072 / 4


def test_the_blend_is_exact_for_an_affine_radius_and_runs_the_policy_on_the_lattice_only():
    rng = np.random.default_rng(0)
    nodes = rng.integers(-20, 20, size=(500, 3))
    origin, spacing, step = np.array([0.1, -0.2, 0.3]), 0.01, 4
    slope = np.array([0.3, -0.2, 0.1])
    asked = []

    def policy(positions):
        asked.append(positions)
        return 0.05 + positions @ slope

    radii, stats = lattice_radii(policy, nodes, origin, spacing, step)
    np.testing.assert_allclose(radii, 0.05 + (origin + nodes * spacing) @ slope, atol=1e-12)
    seen = np.concatenate(asked)
    on_lattice = (seen - origin) / (step * spacing)
    np.testing.assert_allclose(on_lattice, np.rint(on_lattice), atol=1e-9)
    assert stats["lattice_positions"] == len(seen) < 8 * len(nodes)
    # a node on the lattice gets the policy's own value there
    lattice_node = np.array([[8, -4, 12]])
    value, _ = lattice_radii(policy, lattice_node, origin, spacing, step)
    assert value[0] == pytest.approx(policy(origin + lattice_node * spacing)[0], abs=1e-15)


@pytest.fixture
def coarse_lattice(monkeypatch):
    """The lattice at resolution 48 in learned mode (R = 0.072 is 3.5 spacings): step 2."""
    monkeypatch.setattr(radius_lattice, "LATTICE_NODES_PER_R", 1.5)


def test_the_learned_field_reads_its_radii_from_the_lattice_the_same_on_any_threads(
        monkeypatch, coarse_lattice):
    points = sphere_points()
    settings = ReconstructSettings(resolution=48, radius_mode="learned", device="cpu")
    monkeypatch.setattr(field, "CPU_BATCH", 1500)
    fields = []
    for threads in (1, 3):
        monkeypatch.setattr(field, "cpu_threads", lambda: threads)
        monkeypatch.setattr(radius, "cpu_threads", lambda: threads)
        band = compute_udf_band(points, settings)
        assert band.stats["lattice_step"] == 2
        assert 0 < band.stats["lattice_positions"] < band.stats["network_queries"] / 3
        assert 0 < band.stats["seconds_radius"] < band.stats["seconds_udf"]
        fields.append(band.grid._band[1])
    np.testing.assert_array_equal(fields[1], fields[0])


def test_two_grids_on_one_anchor_give_their_shared_nodes_the_same_radii(coarse_lattice):
    """Tiles share the lattice: a grid clipped to a box (a tile) agrees with the whole grid on
    the nodes inside the box."""
    points = sphere_points(count=4000)
    settings = ReconstructSettings(resolution=48, radius_mode="learned", device="cpu")
    anchor = points.min(axis=0)
    whole = compute_udf_band(points, settings, anchor=anchor).grid
    low, high = np.array([-0.5, -0.5, 0.05]), np.array([0.5, 0.5, 0.5])
    part = compute_udf_band(points, settings, anchor=anchor, bounds=(low, high)).grid
    indices, values = part.band()
    positions = part.index_to_world(indices)
    # the nodes of the box's inside: their balls and parent balls lie within the box's points
    inside = np.all((positions >= low + 0.08) & (positions <= high - 0.08), axis=1)
    assert inside.sum() > 500
    shared = np.rint(whole.world_to_index(positions[inside])).astype(np.int64)
    # (the same up to float32 rounding: the two grids batch their queries differently)
    np.testing.assert_allclose(
        values[inside], whole.values_at(np.ravel_multi_index(tuple(shared.T), whole.shape)),
        rtol=1e-5, atol=0)
