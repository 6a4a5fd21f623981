"""UDFGrid: closest-point field V = 1/2 grad(d^2), bricks, band input, coordinates."""

import numpy as np
import pytest

from engine.errors import InputError
from engine.meshing import UDFGrid
from lab import analytic as A


def test_plane_between_nodes_is_exact():
    z0 = 0.0123  # not on a node layer
    grid = A.sample_grid(A.rectangle((0, 0, z0), half_u=2, half_v=2), [-1] * 3, [1] * 3, 48,
                         exact=False)
    rng = np.random.default_rng(0)
    p = rng.uniform(-0.5, 0.5, (2000, 3))
    p[:, 2] = z0 + rng.uniform(-2, 2, 2000) * grid.spacing
    d, v = grid.closest(p)
    assert np.abs(d - np.abs(p[:, 2] - z0)).max() < 1e-5 * grid.spacing
    assert np.abs(v[:, :2]).max() < 1e-5 * grid.spacing
    # the zero of the interpolated field is the plane itself, not a node layer
    closest = p - v
    assert np.abs(closest[:, 2] - z0).max() < 1e-5 * grid.spacing


def test_sphere_interpolation_error_small():
    c = np.array([0.1, -0.05, 0.02])
    shape = A.sphere(c, 0.5)
    grid = A.sample_grid(shape, [-1] * 3, [1] * 3, 96, exact=False)
    rng = np.random.default_rng(1)
    dirs = rng.normal(size=(5000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    p = c + dirs * (0.5 + rng.uniform(-1.5, 1.5, (5000, 1)) * grid.spacing)
    d_true, cp_true = shape(p)
    d, v = grid.closest(p)
    assert np.abs(d - d_true).mean() < 0.02 * grid.spacing
    assert np.abs(d - d_true).max() < 0.05 * grid.spacing
    assert np.abs((p - v) - cp_true).max() < 0.05 * grid.spacing


def test_moving_points_through_a_cell_cache_give_the_uncached_values_bit_for_bit():
    from engine.udf_grid import CellCache

    grid = A.sample_grid(A.sphere((0.1, -0.05, 0.02), 0.5), [-1] * 3, [1] * 3, 64, exact=False)
    rng = np.random.default_rng(2)
    g = grid.world_to_index(rng.uniform(-0.7, 0.7, (5000, 3)))
    cells = CellCache()
    moved = 0
    for step in range(6):  # small steps (most points stay in their cell) and one large one
        g = g + rng.normal(0, 0.05 if step != 3 else 3.0, g.shape)
        before = None if cells.cell is None else cells.cell.copy()
        d_cached, v_cached = grid.closest_index(g, cells)
        d, v = grid.closest_index(g)
        assert np.array_equal(d_cached, d) and np.array_equal(v_cached, v)
        if before is not None:
            moved += int((before != cells.cell).any(axis=1).sum())
    assert 0 < moved < 6 * len(g)  # the cache was both reused and refreshed
    assert np.isinf(d).any() and np.isfinite(d).any()  # points inside and outside the band
    grid.prepare(8 * grid.spacing)  # a wider band: other bricks, the cache reads afresh
    d_cached, v_cached = grid.closest_index(g, cells)
    d, v = grid.closest_index(g)
    assert np.array_equal(d_cached, d) and np.array_equal(v_cached, v)


def test_band_equals_dense_near_surface():
    dense = A.sample_grid(A.torus((0.02, 0, 0), 0.5, 0.2), [-1] * 3, [1] * 3, 64, exact=False)
    h = dense.spacing
    udf = dense.slab(0, dense.shape[0])
    idx = np.argwhere(udf < 5 * h)
    band = UDFGrid.from_band(idx, udf[tuple(idx.T)], dense.shape, dense.origin, h,
                             far_value=5 * h)
    dense.prepare(3 * h)
    band.prepare(3 * h)
    rng = np.random.default_rng(2)
    p = A.torus((0.02, 0, 0), 0.5, 0.2)(rng.uniform(-1, 1, (3000, 3)))[1]
    p += rng.normal(scale=h, size=p.shape)
    d1, v1 = dense.closest(p)
    d2, v2 = band.closest(p)
    assert np.array_equal(v1, v2)
    expected = np.where(udf[:4] < 5 * h, udf[:4], np.float32(5 * h))
    assert np.array_equal(band.slab(0, 4), expected)


def test_index_world_mapping():
    grid = UDFGrid(np.ones((5, 6, 7), np.float32), origin=(1.0, -2.0, 0.5), spacing=0.25)
    idx = np.array([[0, 0, 0], [4, 5, 6], [1.5, 2.25, 3.0]])
    world = grid.index_to_world(idx)
    assert np.allclose(world[1], [2.0, -0.75, 2.0])
    assert np.allclose(grid.world_to_index(world), idx)


def test_outside_band_is_far():
    grid = A.sample_grid(A.sphere((0, 0, 0), 0.3), [-0.5] * 3, [0.5] * 3, 40, exact=False)
    grid.prepare(2 * grid.spacing)
    d, v = grid.closest(np.array([[0.0, 0.0, 0.0]]))  # centre: far from the band
    assert d[0] == grid.far_value and np.all(v == 0)


@pytest.mark.parametrize("make", [
    lambda: UDFGrid(np.full((4, 4, 4), np.nan, np.float32), (0, 0, 0), 0.1),
    lambda: UDFGrid(np.ones((4, 4), np.float32), (0, 0, 0), 0.1),
    lambda: UDFGrid(np.ones((4, 4, 4), np.float32), (0, 0), 0.1),
    lambda: UDFGrid(np.ones((4, 4, 4), np.float32), (0, 0, 0), -1.0),
    lambda: UDFGrid.from_band(np.array([[9, 0, 0]]), np.ones(1), (4, 4, 4), (0, 0, 0), 0.1, 1.0),
    lambda: UDFGrid.from_band(np.array([[1, 0, 0], [1, 0, 0]]), np.ones(2), (4, 4, 4),
                              (0, 0, 0), 0.1, 1.0),
])
def test_bad_grids_refused(make):
    with pytest.raises(InputError):
        make()


@pytest.mark.parametrize("form", ["dense", "band"])
def test_compiled_bricks_equal_the_numpy_ones_bit_for_bit(form, monkeypatch):
    """numba is a runtime requirement (requirements.txt), so the compiled bricks are built here;
    the grid reaches its borders (clipped halos) and the band leaves far nodes inside bricks."""
    from engine.compiled import kernels

    assert kernels("udf_grid_kernels") is not None
    dense = A.sample_grid(A.torus((0.3, 0, 0), 0.55, 0.2), [-1] * 3, [1] * 3, 45, exact=False)
    h = dense.spacing
    udf = dense.slab(0, dense.shape[0])
    idx = np.argwhere(udf < 2.5 * h)
    grids = {}
    for path in ("compiled", "numpy"):
        if path == "numpy":
            monkeypatch.setenv("UDF_RECON_KERNELS", "numpy")
        grid = dense if form == "dense" else UDFGrid.from_band(
            idx, udf[tuple(idx.T)], dense.shape, dense.origin, h, far_value=2.5 * h)
        if form == "dense":
            grid = A.sample_grid(A.torus((0.3, 0, 0), 0.55, 0.2), [-1] * 3, [1] * 3, 45,
                                 exact=False)
        bricks = grid.prepare(3 * h)
        grids[path] = grid.brick_arrays()
        assert bricks > 0
    (table, coef), (want_table, want_coef) = (grids[p][:2] for p in ("compiled", "numpy"))
    assert np.array_equal(table, want_table)
    assert np.abs(coef).max() > 0 and np.array_equal(coef, want_coef)
