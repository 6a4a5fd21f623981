"""The closest-point field's bricks (:meth:`.udf_grid.UDFGrid.prepare`) as one compiled loop
(numba), when numba is there (see :mod:`engine.compiled`).

Per brick: the distances of its (BRICK + 3)^3 nodes (a one-node halo for the central
differences; a sparse band is searched once per row of nodes and walked along it), V = 1/2
grad(d^2) at its (BRICK + 1)^3 nodes, and each cell's 8 trilinear coefficients per channel. The
same arithmetic as the numpy code, in the same precision and order, so the bricks are the same.
"""

import numba
import numpy as np

BRICK = 4
_HALO = BRICK + 3  # nodes per side with the halo
_NODES = BRICK + 1


@numba.njit(nogil=True, cache=True, error_model="numpy")
def bricks(corners, dims, band_flat, band_values, dense, far, spacing):
    """Coefficients (B + 1, BRICK, BRICK, BRICK, 3, 8) float32 of the bricks whose first nodes
    are ``corners`` (B, 3); the last brick stays zero. ``dense``: the grid's distances
    (nx, ny, nz) float32, or an empty array for a sparse band (``band_flat`` sorted flat node
    indices, ``band_values`` their distances, ``far`` elsewhere)."""
    nx, ny, nz = dims[0], dims[1], dims[2]
    count = corners.shape[0]
    out = np.zeros((count + 1, BRICK, BRICK, BRICK, 3, 8), dtype=np.float32)
    d2 = np.empty((_HALO, _HALO, _HALO))
    v = np.empty((_NODES, _NODES, _NODES, 3), dtype=np.float32)
    index = np.empty((3, _HALO), dtype=np.int64)
    limit = np.array([nx - 1, ny - 1, nz - 1])
    size = band_flat.shape[0]
    for b in range(count):
        for a in range(3):
            for s in range(_HALO):
                index[a, s] = min(max(corners[b, a] + s - 1, 0), limit[a])
        for i in range(_HALO):
            for j in range(_HALO):
                row = (index[0, i] * ny + index[1, j]) * nz
                if dense.size:
                    for k in range(_HALO):
                        value = np.float64(dense[index[0, i], index[1, j], index[2, k]])
                        d2[i, j, k] = (value / spacing) ** 2
                    continue
                # first band entry not below the row's first node, then walk along the row
                lo, hi = 0, size
                target = row + index[2, 0]
                while lo < hi:
                    mid = (lo + hi) >> 1
                    if band_flat[mid] < target:
                        lo = mid + 1
                    else:
                        hi = mid
                for k in range(_HALO):
                    target = row + index[2, k]
                    while lo < size and band_flat[lo] < target:
                        lo += 1
                    value = far
                    if lo < size and band_flat[lo] == target:
                        value = band_values[lo]
                    d2[i, j, k] = (np.float64(value) / spacing) ** 2
        for i in range(_NODES):
            for j in range(_NODES):
                for k in range(_NODES):
                    step = max(np.float64(index[0, i + 2] - index[0, i]), 1e-30)
                    v[i, j, k, 0] = 0.5 * (d2[i + 2, j + 1, k + 1] - d2[i, j + 1, k + 1]) / step
                    step = max(np.float64(index[1, j + 2] - index[1, j]), 1e-30)
                    v[i, j, k, 1] = 0.5 * (d2[i + 1, j + 2, k + 1] - d2[i + 1, j, k + 1]) / step
                    step = max(np.float64(index[2, k + 2] - index[2, k]), 1e-30)
                    v[i, j, k, 2] = 0.5 * (d2[i + 1, j + 1, k + 2] - d2[i + 1, j + 1, k]) / step
        for i in range(BRICK):
            for j in range(BRICK):
                for k in range(BRICK):
                    for c in range(3):
                        v0, v1 = v[i, j, k, c], v[i, j, k + 1, c]
                        v2, v3 = v[i, j + 1, k, c], v[i, j + 1, k + 1, c]
                        v4, v5 = v[i + 1, j, k, c], v[i + 1, j, k + 1, c]
                        v6, v7 = v[i + 1, j + 1, k, c], v[i + 1, j + 1, k + 1, c]
                        cell = out[b, i, j, k, c]
                        cell[0] = v0
                        cell[1] = v1 - v0
                        cell[2] = v2 - v0
                        cell[3] = v3 - v2 - v1 + v0
                        cell[4] = v4 - v0
                        cell[5] = v5 - v4 - v1 + v0
                        cell[6] = v6 - v4 - v2 + v0
                        cell[7] = v7 - v6 - v5 + v4 - v3 + v2 + v1 - v0
    return out
