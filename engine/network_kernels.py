"""The numpy networks' max pools as one compiled loop (numba), when numba is there (see
:mod:`engine.compiled`).

A pool reads each per-point feature once, keeping the running maximum of a patch's channels in
registers, where numpy's halving (:func:`.backbone.max_over_points`) streams the activations
through memory once per halving step. The maximum is exact, so the result is the same; NaN
propagates as in ``np.maximum``.
"""

import numba
import numpy as np


@numba.njit("float32[:, ::1](float32[:, :, ::1])", nogil=True, cache=True)
def max_over_points(x):
    """(B, N, C) float32, C-contiguous -> (B, C): the maximum over axis 1. Compiled for that
    type alone when the module is imported, so no call compiles."""
    patches, points, channels = x.shape
    out = np.empty((patches, channels), dtype=np.float32)
    for i in range(patches):
        best = out[i]
        for k in range(channels):
            best[k] = x[i, 0, k]
        for j in range(1, points):
            row = x[i, j]
            for k in range(channels):
                value = row[k]
                if value > best[k] or value != value:
                    best[k] = value
    return out
