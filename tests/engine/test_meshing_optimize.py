"""The CPU optimisation of the cover: the same vertices on any number of threads, and the compiled
passes (numba) agree with the numpy ones."""

import numpy as np
import pytest

from engine.meshing.marching import double_cover
from engine.meshing.optimize import compiled_kernels, optimize_cover
from lab import analytic

SHAPES = pytest.mark.parametrize("shape", [analytic.sphere(radius=0.6),
                                           analytic.disk(radius=0.6)], ids=["sphere", "disk"])


def _cover(shape):
    field = analytic.sample_grid(shape, (-1, -1, -1), (1, 1, 1), 48, exact=False)
    vertices, faces, iso, _, _ = double_cover(field)
    field.prepare(iso + 3 * field.spacing)
    return field, vertices, faces


@SHAPES
@pytest.mark.parametrize("compiled", [False, True], ids=["numpy", "compiled"])
def test_threads_change_nothing_in_the_result(shape, compiled):
    field, vertices, faces = _cover(shape)
    one, one_stats = optimize_cover(vertices, faces, field, 120, 4.0, 0.05, 0.75, threads=1,
                                    compiled=compiled)
    assert one_stats.kernels == ("compiled" if compiled else "numpy")
    moved = np.linalg.norm(one - vertices, axis=1).mean() / field.spacing
    assert moved > 0.1  # both stages ran and moved the cover
    assert one_stats.mean_distance < 0.05  # voxels: onto the zero set
    for threads in (2, 3):
        split, split_stats = optimize_cover(vertices, faces, field, 120, 4.0, 0.05, 0.75,
                                            threads=threads, compiled=compiled)
        np.testing.assert_array_equal(split, one)
        assert split_stats == one_stats


@SHAPES
def test_compiled_passes_move_the_cover_as_the_numpy_ones(shape):
    """numba is a runtime requirement (requirements.txt), so the compiled passes run here."""
    assert compiled_kernels() is not None
    field, vertices, faces = _cover(shape)
    want, want_stats = optimize_cover(vertices, faces, field, 120, 4.0, 0.05, 0.75,
                                      compiled=False)
    got, got_stats = optimize_cover(vertices, faces, field, 120, 4.0, 0.05, 0.75)
    assert (want_stats.kernels, got_stats.kernels) == ("numpy", "compiled")
    assert got_stats.iterations == want_stats.iterations
    apart = np.linalg.norm(got - want, axis=1) / field.spacing  # voxels
    assert apart.mean() < 1e-6 and apart.max() < 1e-4
    assert abs(got_stats.mean_distance - want_stats.mean_distance) < 1e-6


def test_the_numpy_passes_can_be_forced(monkeypatch):
    monkeypatch.setenv("UDF_RECON_KERNELS", "numpy")
    assert compiled_kernels() is None
    field, vertices, faces = _cover(analytic.disk(radius=0.6))
    _, stats = optimize_cover(vertices, faces, field, 8, 4.0, 0.05, 0.75)
    assert stats.kernels == "numpy"
