"""The radius policy on a coarser lattice: which step, exact blends, fewer policy positions, the
same field on any number of threads, tiles that agree on their shared nodes, and the nodes
between two close sheets, which take their own radius."""

import numpy as np
import pytest

from engine import field, radius, radius_lattice
from engine.field import compute_udf_band
from engine.radius_lattice import lattice_radii, lattice_step, ridge_nodes
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


def test_own_nodes_take_the_policy_at_their_own_position_where_wider_the_others_the_blend():
    rng = np.random.default_rng(1)
    nodes = rng.integers(-20, 20, size=(400, 3))
    origin, spacing, step = np.array([0.1, -0.2, 0.3]), 0.01, 4

    def policy(positions):  # far from affine: a blend misses it
        return 0.02 + 0.01 * np.sin(40 * positions[:, 0]) ** 2

    own = rng.random(len(nodes)) < 0.2
    radii, stats = lattice_radii(policy, nodes, origin, spacing, step, own=own)
    blended, _ = lattice_radii(policy, nodes, origin, spacing, step)
    itself = policy(origin + nodes[own] * spacing)
    np.testing.assert_array_equal(radii[own], np.maximum(itself, blended[own]))
    np.testing.assert_array_equal(radii[~own], blended[~own])
    assert (itself > 1.1 * blended[own]).any() and (itself < blended[own] / 1.1).any()
    assert stats["lattice_own_nodes"] == own.sum()


def _band_offsets(points, spacing):
    """The network's band nodes of ``points`` on a grid of ``spacing``: indices and offsets to
    their nearest points."""
    from scipy.spatial import cKDTree

    tree = cKDTree(points)
    shape, origin, spacing = field.grid_layout(points, round(1 / spacing), 5 * spacing, None,
                                               None)
    indices, nearest, owner = field.find_band(tree, points, shape, origin, spacing,
                                              5 * spacing, with_owner=True)
    near = field._network_nodes(tree, points, nearest, owner, spacing)
    positions = origin + indices[near] * spacing
    return indices[near], positions, positions - points[owner[near]]


def test_ridge_nodes_lie_midway_between_two_close_sheets_and_nowhere_beside_one_sheet():
    h = 1 / 128
    rng = np.random.default_rng(0)
    plane = np.column_stack([rng.uniform(-0.45, 0.45, (20000, 2)), np.zeros(20000)])
    two = np.concatenate([plane, plane[:, [1, 0, 2]] + [0, 0, 5 * h]])  # 5 spacings apart
    nodes, positions, offsets = _band_offsets(two, h)
    ridge = ridge_nodes(nodes, offsets, h)
    height = np.rint(positions[:, 2] / h)  # the grid's nodes lie on the sheets' planes
    inside = (np.abs(positions[:, :2]) < 0.4).all(axis=1)
    between = inside & (height > 0) & (height < 5)
    assert np.array_equal(np.unique(height[ridge & between]), [2, 3])  # the two beside midway
    assert ridge[inside & ~between].mean() < 0.05  # on the sheets: holes of their sampling
    assert ridge[inside & np.isin(height, [2, 3])].mean() > 0.95
    nodes, positions, offsets = _band_offsets(plane, h)  # one sheet: none off it
    ridge = ridge_nodes(nodes, offsets, h)
    assert not ridge[np.abs(positions[:, 2]) > 0.5 * h].any() and ridge.mean() < 0.001
    # one sheet sampled sparsely (points 2.4 spacings apart): some nodes in the holes of the
    # sampling, within 2 spacings of the sheet
    nodes, positions, offsets = _band_offsets(plane[::9], h)
    ridge = ridge_nodes(nodes, offsets, h)
    assert ridge.mean() < 0.1 and np.abs(positions[ridge, 2]).max() <= 2.01 * h


def test_the_learned_field_between_a_cars_floor_and_its_underbody_has_no_false_minimum():
    """Midway between two sheets a few spacings apart the selector picks a far wider ball than
    beside them; blended from the lattice, those nodes got the narrow balls of their
    neighbours and the backbone a false minimum there (the mesh wrinkled between the sheets).
    On the underbody of the first clean test car at 256: the nodes more than 2 spacings from
    the surface that read under 0.7 of their true distance (5 % with the blend alone)."""
    from engine.frame import UnitFrame
    from lab.bench import dataset
    from lab.bench.surface_distance import closest_on_mesh

    truth = dataset.make_shape("cars", 1000001)
    points = np.asarray(dataset.make_input(truth, "cars", "clean", 1000001).points)
    frame = UnitFrame.from_points(points)
    unit = frame.to_unit(points)
    anchor = field.grid_layout(unit, 256, 0.0, None, None)[1]  # the whole car's grid
    patch = unit[(unit[:, 0] > -0.33) & (unit[:, 0] < 0.03) & (np.abs(unit[:, 1]) < 0.13)
                 & (unit[:, 2] < -0.06)]
    settings = ReconstructSettings(resolution=256, radius_mode="learned", device="cpu",
                                   fill_gaps=False)
    band = compute_udf_band(patch, settings, anchor=anchor)
    assert band.stats["lattice_step"] == 4 and band.stats["lattice_own_nodes"] > 0
    indices, values = band.grid.band()
    positions = band.grid.index_to_world(indices)
    inner = ((positions[:, 0] > -0.28) & (positions[:, 0] < -0.02)
             & (np.abs(positions[:, 1]) < 0.08) & (positions[:, 2] < -0.09))
    distance = closest_on_mesh(frame.from_unit(positions[inner]), truth.vertices,
                               truth.faces)[0] / frame.scale
    away = distance > 2 * band.grid.spacing
    assert away.sum() > 10000
    assert (values[inner][away] < 0.7 * distance[away]).mean() < 0.02


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
