"""The CPU optimisation of the cover gives the same vertices on any number of threads."""

import numpy as np
import pytest

from engine.meshing.marching import double_cover
from engine.meshing.optimize import optimize_cover
from lab import analytic


@pytest.mark.parametrize("shape", [analytic.sphere(radius=0.6), analytic.disk(radius=0.6)],
                         ids=["sphere", "disk"])
def test_threads_change_nothing_in_the_result(shape):
    field = analytic.sample_grid(shape, (-1, -1, -1), (1, 1, 1), 48, exact=False)
    vertices, faces, iso, _, _ = double_cover(field)
    field.prepare(iso + 3 * field.spacing)
    one, one_stats = optimize_cover(vertices, faces, field, 120, 4.0, 0.05, 0.75, threads=1)
    moved = np.linalg.norm(one - vertices, axis=1).mean() / field.spacing
    assert moved > 0.1  # both stages ran and moved the cover
    assert one_stats.mean_distance < 0.05  # voxels: onto the zero set
    for threads in (2, 3):
        split, split_stats = optimize_cover(vertices, faces, field, 120, 4.0, 0.05, 0.75,
                                            threads=threads)
        np.testing.assert_array_equal(split, one)
        assert split_stats == one_stats
