"""The gap fill's edge test (:func:`.gap_fill._point_planes`) as one compiled loop (numba), when
numba is there (see :mod:`engine.compiled`).

Per point: the directions of its neighbours within reach in its tangent plane, sorted, and the
widest angle between two consecutive ones. The same arithmetic as the numpy code (the offsets,
the two dot products summed in the same order, ``atan2``), without its (points x neighbours x 3)
intermediates, so the same points come out as edge points.
"""

import math

import numba
import numpy as np


@numba.njit(nogil=True, cache=True, error_model="numpy")
def edge_points(points, index, near, distance, tangent_u, tangent_v, reach, widest):
    """Whether each of the points ``index`` (G,) is an edge point: fewer than 3 of its neighbours
    ``near`` (G, K + 1), the first being itself, lie within ``reach`` (``distance`` (G, K + 1)),
    or their directions in the plane of ``tangent_u`` and ``tangent_v`` (G, 3) leave an angle
    wider than ``widest`` (radians)."""
    count, k = near.shape[0], near.shape[1] - 1
    out = np.empty(count, dtype=np.bool_)
    angles = np.empty(k)
    for g in range(count):
        p = index[g]
        found = 0
        for j in range(1, k + 1):
            if distance[g, j] > reach:
                continue
            q = near[g, j]
            ox = points[q, 0] - points[p, 0]
            oy = points[q, 1] - points[p, 1]
            oz = points[q, 2] - points[p, 2]
            along_v = ox * tangent_v[g, 0] + oy * tangent_v[g, 1] + oz * tangent_v[g, 2]
            along_u = ox * tangent_u[g, 0] + oy * tangent_u[g, 1] + oz * tangent_u[g, 2]
            angle = math.atan2(along_v, along_u)
            at = found  # insertion into the sorted angles
            while at > 0 and angles[at - 1] > angle:
                angles[at] = angles[at - 1]
                at -= 1
            angles[at] = angle
            found += 1
        if found < 3:
            out[g] = True
            continue
        gap = angles[0] + 2.0 * math.pi - angles[found - 1]
        for j in range(1, found):
            gap = max(gap, angles[j] - angles[j - 1])
        out[g] = gap > widest
    return out
