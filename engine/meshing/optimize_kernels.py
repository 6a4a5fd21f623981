"""The covering-map optimisation's three passes as compiled loops (numba), when numba is there.

The numpy passes of :class:`.optimize._Cover` stream every intermediate through memory: a
centroid product, a cell lookup, an 8-term interpolation, a normalisation, each a full pass over
the cover. Here each row of a pass is one loop body that reads its few inputs once. The energy,
the steps and the schedule are those of the numpy passes, row for row; the sums run in another
order and the interpolation accumulates in float64, so the vertices agree with the numpy path to
rounding, not bit for bit. Like the numpy passes, each row depends only on arrays an earlier pass
finished, so row ranges run on separate threads (the kernels release the GIL) and the result is
the same, bit for bit, on any number of threads.

numba is optional: importing this module fails without it (or when it refuses this numpy or
Python), and :func:`engine.compiled.kernels` then returns None and the numpy passes run.
Compiled code is cached beside this file (or in numba's per-user cache when that
folder is read-only), so only the first run on a machine pays for the compilation.
"""

import numba
import numpy as np

def jit(function=None, **options):
    """numba's njit, releasing the GIL and cached on disk."""
    options = dict(nogil=True, cache=True, error_model="numpy", **options)
    return numba.njit(**options) if function is None else numba.njit(function, **options)


@jit(inline="always")
def _channel(coef, row, c, tx, ty, tz, tyz, txz, txy, txyz):
    """One channel of the trilinear polynomial (float32 terms, summed in float64)."""
    return (np.float64(coef[row, c, 0]) + np.float64(coef[row, c, 1] * tz)
            + np.float64(coef[row, c, 2] * ty) + np.float64(coef[row, c, 3] * tyz)
            + np.float64(coef[row, c, 4] * tx) + np.float64(coef[row, c, 5] * txz)
            + np.float64(coef[row, c, 6] * txy) + np.float64(coef[row, c, 7] * txyz))


@jit(inline="always")
def closest(x, y, z, table, coef, nb1, nb2, nx, ny, nz):
    """Trilinear closest-point vector V (voxels) at index coordinates and |V|; inf and a
    zero vector outside the prepared bricks (as ``UDFGrid.closest_index``)."""
    i = min(max(np.int64(x), 0), nx - 2)  # truncation, as numpy's astype(int32)
    j = min(max(np.int64(y), 0), ny - 2)
    k = min(max(np.int64(z), 0), nz - 2)
    slot = table[((i >> 2) * nb1 + (j >> 2)) * nb2 + (k >> 2)]  # BRICK = 4
    if slot < 0:
        return np.inf, 0.0, 0.0, 0.0
    row = slot * 64 + ((i & 3) * 4 + (j & 3)) * 4 + (k & 3)
    tx = min(max(np.float32(x - i), np.float32(0.0)), np.float32(1.0))
    ty = min(max(np.float32(y - j), np.float32(0.0)), np.float32(1.0))
    tz = min(max(np.float32(z - k), np.float32(0.0)), np.float32(1.0))
    tyz = ty * tz
    txz = tx * tz
    txy = tx * ty
    txyz = txy * tz
    vx = _channel(coef, row, 0, tx, ty, tz, tyz, txz, txy, txyz)
    vy = _channel(coef, row, 1, tx, ty, tz, tyz, txz, txy, txyz)
    vz = _channel(coef, row, 2, tx, ty, tz, tyz, txz, txy, txyz)
    return np.sqrt(vx * vx + vy * vy + vz * vz), vx, vy, vz


@jit
def face_rows(a, b, g, faces, grid, cents, dc, face_grad, stage2, capture, n0, c0, areas, area):
    """Centroids, their distances and gradients, and stage 2's sliding term, faces a:b; with
    ``areas``, the faces' areas too."""
    table, coef, nb1, nb2, nx, ny, nz = grid
    third = 1.0 / 3.0
    for f in range(a, b):
        p, q, r = faces[f, 0], faces[f, 1], faces[f, 2]
        if areas:
            ux, uy, uz = g[q, 0] - g[p, 0], g[q, 1] - g[p, 1], g[q, 2] - g[p, 2]
            wx, wy, wz = g[r, 0] - g[p, 0], g[r, 1] - g[p, 1], g[r, 2] - g[p, 2]
            cx, cy, cz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
            area[f] = 0.5 * np.sqrt(cx * cx + cy * cy + cz * cz)
        for c in range(3):
            cents[f, c] = g[p, c] * third + g[q, c] * third + g[r, c] * third
        d, vx, vy, vz = closest(cents[f, 0], cents[f, 1], cents[f, 2],
                                table, coef, nb1, nb2, nx, ny, nz)
        dc[f] = d
        m = max(d, 1e-12)
        gx, gy, gz = vx / m, vy / m, vz / m
        if stage2:
            if capture:
                for c in range(3):
                    c0[f, c] = cents[f, c]
            ax = cents[f, 0] - c0[f, 0]
            ay = cents[f, 1] - c0[f, 1]
            az = cents[f, 2] - c0[f, 2]
            dot = ax * n0[f, 0] + ay * n0[f, 1] + az * n0[f, 2]
            ax -= n0[f, 0] * dot
            ay -= n0[f, 1] * dot
            az -= n0[f, 2] * dot
            s = 0.5 / max(np.sqrt(ax * ax + ay * ay + az * az), 1e-12)
            gx += ax * s
            gy += ay * s
            gz += az * s
        face_grad[f, 0] = gx
        face_grad[f, 1] = gy
        face_grad[f, 2] = gz


@jit
def vertex_rows(a, b, g, grid, dv, grad, stage1, lap, weight, wd):
    """Vertex distances and gradients; stage 1's weighted umbrella vectors, vertices a:b."""
    table, coef, nb1, nb2, nx, ny, nz = grid
    ptr, idx, val = lap
    for v in range(a, b):
        d, vx, vy, vz = closest(g[v, 0], g[v, 1], g[v, 2], table, coef, nb1, nb2, nx, ny, nz)
        dv[v] = d
        m = max(d, 1e-12)
        grad[v, 0] = vx / m
        grad[v, 1] = vy / m
        grad[v, 2] = vz / m
        if stage1:
            sx = sy = sz = 0.0
            for e in range(ptr[v], ptr[v + 1]):
                w, j = val[e], idx[e]
                sx += w * g[j, 0]
                sy += w * g[j, 1]
                sz += w * g[j, 2]
            wd[v, 0] = (sx - g[v, 0]) * weight[v]
            wd[v, 1] = (sy - g[v, 1]) * weight[v]
            wd[v, 2] = (sz - g[v, 2]) * weight[v]


@jit
def step_rows(a, b, g, grad, stage1, lap_t, wd, lam2, cen_t, face_grad, ratio,
              mom, vel, rate, bias1, bias2, beta1, beta2, eps):
    """The full gradient of vertices a:b and their VectorAdam step."""
    lptr, lidx, lval = lap_t
    cptr, cidx, cval = cen_t
    for v in range(a, b):
        fx, fy, fz = grad[v, 0], grad[v, 1], grad[v, 2]
        if stage1:
            sx = sy = sz = 0.0
            for e in range(lptr[v], lptr[v + 1]):
                w, j = lval[e], lidx[e]
                sx += w * wd[j, 0]
                sy += w * wd[j, 1]
                sz += w * wd[j, 2]
            fx += (sx - wd[v, 0]) * lam2
            fy += (sy - wd[v, 1]) * lam2
            fz += (sz - wd[v, 2]) * lam2
        sx = sy = sz = 0.0
        for e in range(cptr[v], cptr[v + 1]):
            w, f = cval[e], cidx[e]
            sx += w * face_grad[f, 0]
            sy += w * face_grad[f, 1]
            sz += w * face_grad[f, 2]
        fx += sx * ratio
        fy += sy * ratio
        fz += sz * ratio
        vel[v] = vel[v] * beta2 + (1.0 - beta2) * (fx * fx + fy * fy + fz * fz)
        scale = rate / bias1 / (np.sqrt(vel[v] / bias2) + eps)
        mom[v, 0] = mom[v, 0] * beta1 + (1.0 - beta1) * fx
        mom[v, 1] = mom[v, 1] * beta1 + (1.0 - beta1) * fy
        mom[v, 2] = mom[v, 2] * beta1 + (1.0 - beta1) * fz
        g[v, 0] -= mom[v, 0] * scale
        g[v, 1] -= mom[v, 1] * scale
        g[v, 2] -= mom[v, 2] * scale
