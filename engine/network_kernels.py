"""The numpy networks' max pools, and the backbone's per-point steps between its matrix
products, as compiled loops (numba), when numba is there (see :mod:`engine.compiled`).

A pool reads each per-point feature once, keeping the running maximum of a patch's channels in
registers, where numpy's halving (:func:`.backbone.max_over_points`) streams the activations
through memory once per halving step; the backbone's bias adds, residual add, ReLUs and pools
after a product run in one pass over its output instead of one numpy call each
(:class:`.backbone.NumpyBackbone`). The same float32 operations in the same order, so the
results are the same bit for bit: the maximum is exact, each sum is rounded as numpy rounds it,
and a ReLU gives ``x`` where ``x > 0`` or NaN, else +0, as ``np.maximum(x, zeros)`` does.
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


@numba.njit("float32[:, ::1](float32[:, :, ::1], float32[::1], float32[:, :, ::1])", nogil=True,
            cache=True)
def bias_pool_relu(h, bias, relu_out):
    """``h += bias`` in place; ``relu_out = max(h, 0)``; returns the max pool of ``h`` (B, C).
    ``h`` and ``relu_out`` (B, N, C); the backbone's first layer after its product."""
    patches, points, channels = h.shape
    out = np.empty((patches, channels), dtype=np.float32)
    for i in range(patches):
        best = out[i]
        for j in range(points):
            row, relu_row = h[i, j], relu_out[i, j]
            for k in range(channels):
                value = row[k] + bias[k]
                row[k] = value
                relu_row[k] = value if value > 0 or value != value else np.float32(0)
                if j == 0 or value > best[k] or value != value:
                    best[k] = value
    return out


@numba.njit("void(float32[:, :, ::1], float32[:, ::1])", nogil=True, cache=True)
def add_patch_relu(u, per_patch):
    """``u = max(u + per_patch[:, None, :], 0)`` in place; ``u`` (B, N, C), ``per_patch`` (B, C)."""
    patches, points, channels = u.shape
    for i in range(patches):
        add = per_patch[i]
        for j in range(points):
            row = u[i, j]
            for k in range(channels):
                value = row[k] + add[k]
                row[k] = value if value > 0 or value != value else np.float32(0)


@numba.njit("float32[:, ::1](float32[:, :, ::1], float32[::1], float32[:, :, ::1])", nogil=True,
            cache=True)
def bias_residual_pool(h, bias, residual):
    """``h = (h + bias) + residual`` in place (each sum rounded as numpy's two in-place adds);
    returns the max pool of ``h`` (B, C)."""
    patches, points, channels = h.shape
    out = np.empty((patches, channels), dtype=np.float32)
    for i in range(patches):
        best = out[i]
        for j in range(points):
            row, skip = h[i, j], residual[i, j]
            for k in range(channels):
                value = row[k] + bias[k]
                value = value + skip[k]
                row[k] = value
                if j == 0 or value > best[k] or value != value:
                    best[k] = value
    return out
