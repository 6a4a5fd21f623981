"""The covering-map optimisation: move the cover's vertices onto the zero set, keeping its faces.

Two stages (DCUDF, Hou et al. 2023), written with analytic gradients in voxel units:

* stage 1: ``E1 = sum_v d(x_v) + (n/m) sum_f d(c_f) + lam * sum_v w_v |(W - I) X|_v^2``
  (``c_f`` face centroids, ``W`` the umbrella operator, ``w_v = max(s) / s_v`` with
  ``s_v = sqrt(vertex area)``: compressed regions and the pancake rim are smoothed more);
* stage 2: the smoothing is dropped, normals ``n0`` and centroids ``c0`` frozen, and
  ``E2 = sum_v d(x_v) + (n/m) sum_f [d(c_f) + 0.5 |(c_f - c0_f) x n0_f|]`` lets faces slide only
  along their frozen normal (detail without smoothing bias).

``grad d = V / |V|`` from the closest-point field. Steps are VectorAdam's (Ling et al. 2022): one
second moment per vertex (the squared norm of its gradient), so each vertex moves at most about
``lr`` voxels per iteration whatever the scale of the energy.
"""

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Optional

import numpy as np

from ..progress import CancelFn, ProgressFn, check_cancel, no_progress
from . import mesh_ops

STALL_CHECK = 10  # iterations between two convergence checks of the low-step phases
STALL_MEAN = 1e-3  # voxels: the mean vertex / centroid distance improved less than this
STALL_MAX = 1e-2  # voxels: and the largest one improved less than this
CHUNK = 65536  # points per chunk of a threaded field query


@dataclass
class OptimizeStats:
    """Iterations run and the final vertex / centroid distances, in voxels."""

    iterations: int
    mean_distance: float
    max_distance: float
    mean_centroid_distance: float


def learning_rate(it: int, total: int, lr: float) -> float:
    """Warm-up over ``total / 16`` iterations, cosine decay to 0, x0.1 from half-way (voxels)."""
    warm = max(1, total // 16)
    rate = lr * min(1.0, (it + 1) / warm) * 0.5 * (1.0 + np.cos(np.pi * it / total))
    return rate * (0.1 if it >= total // 2 else 1.0)


def _unit_inplace(vectors: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    vectors /= np.maximum(lengths, 1e-12)[:, None]
    return vectors


class _FieldQuery:
    """``field.closest_index`` on many points, split over two threads when there are enough.

    The points are independent, so the split changes nothing in the results (numpy releases the
    GIL in the gathers and arithmetic of the grid interpolation).
    """

    def __init__(self, field, points: int):
        threads = min(2, os.cpu_count() or 1)
        self.field = field
        self.pool = ThreadPoolExecutor(threads) if threads > 1 and points >= 2 * CHUNK else None

    def __call__(self, points: np.ndarray):
        if self.pool is None or len(points) < 2 * CHUNK:
            return self.field.closest_index(points)
        bounds = np.linspace(0, len(points), 3).astype(int)
        parts = list(self.pool.map(self.field.closest_index,
                                   [points[a:b] for a, b in zip(bounds[:-1], bounds[1:])]))
        return (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]))

    def close(self):
        if self.pool is not None:
            self.pool.shutdown()


class StallCheck:
    """The early stop of stage 2: from iteration ``quiet`` on, every ``STALL_CHECK`` iterations,
    stop once the mean and max vertex and centroid distances improve by less than ``STALL_MEAN``
    / ``STALL_MAX`` voxels since the last check."""

    def __init__(self, quiet: int, enabled: bool):
        self.quiet = quiet
        self.enabled = enabled
        self.reference = None  # distance summary at the last check

    def due(self, it: int) -> bool:
        return self.enabled and it >= self.quiet and (it - self.quiet) % STALL_CHECK == 0

    def stalled(self, summary: np.ndarray) -> bool:
        """``summary``: mean and max vertex, mean and max centroid distance (see
        :func:`distance_summary`), taken at an iteration where :meth:`due` holds."""
        previous, self.reference = self.reference, summary
        if previous is None:
            return False
        gain = previous - summary
        return gain[0::2].max() < STALL_MEAN and gain[1::2].max() < STALL_MAX


def final_stats(ran: int, dv: np.ndarray, dc: np.ndarray) -> OptimizeStats:
    """The stats of a finished optimisation from its last vertex / centroid distances."""
    summary = distance_summary(dv, dc)
    return OptimizeStats(ran, float(summary[0]), float(summary[1]), float(summary[2]))


def distance_summary(dv: np.ndarray, dc: np.ndarray) -> np.ndarray:
    """Mean and max of the finite vertex and centroid distances (voxels)."""
    out = np.zeros(4)
    for k, d in enumerate((dv, dc)):
        finite = d[np.isfinite(d)]
        if finite.size:
            out[2 * k], out[2 * k + 1] = finite.mean(), finite.max()
    return out


def optimize_cover(vertices: np.ndarray, faces: np.ndarray, field, iterations: int = 400,
                   laplacian_weight: float = 16.0, lr: float = 0.05,
                   normal_start: float = 0.75, progress: Optional[ProgressFn] = None,
                   cancel: Optional[CancelFn] = None, edges: Optional[np.ndarray] = None,
                   early_stop: bool = True):
    """Pull a double cover onto the zero set of ``field``.

    Parameters
    ----------
    vertices : (n, 3) float64
        Cover vertices, world units.
    faces : (m, 3) int64
        Cover faces (kept fixed).
    field : UDFGrid
        Distance source (``closest_index``).
    iterations : int
        Total iterations of both stages (the schedule's length).
    laplacian_weight : float
        ``lam`` in voxel units (DCUDF's weight times the voxel size: 2000 at 256^3 over
        [-1, 1] is about 16).
    lr : float
        Peak step, voxels per iteration.
    normal_start : float
        Fraction of the iterations after which stage 2 starts.
    edges : (E, 2) int64, optional
        The cover's unique edges, when already known.
    early_stop : bool
        In stage 2 (once the step is x0.1 too), check every ``STALL_CHECK`` iterations whether
        the mean and max vertex and centroid distances still improve (by ``STALL_MEAN`` /
        ``STALL_MAX`` voxels) and stop when they stall. (Stopping stage 1 early the same way
        leaves thicker folds at open rims: its smoothing still works after the distances stall.)

    Returns
    -------
    vertices : (n, 3) float64 world units; stats : OptimizeStats (``iterations`` counts the
    iterations actually run).
    """
    progress = progress or no_progress
    n, m = len(vertices), len(faces)
    g = field.world_to_index(vertices)
    if edges is None:
        edges = mesh_ops.edge_topology(faces).edges
    lap = mesh_ops.uniform_laplacian(n, edges)
    lap_t = lap.T.tocsr()
    cen = mesh_ops.centroid_matrix(n, faces)
    cen_t = cen.T.tocsr()
    inc = mesh_ops.incidence_matrix(n, faces)
    ratio = n / max(m, 1)
    stage2 = int(round(normal_start * iterations))
    quiet = max(stage2, iterations // 2)  # stage 2 with the small step: may stop early
    beta1, beta2, eps = 0.9, 0.999, 1e-8
    mom = np.zeros_like(g)
    vel = np.zeros(n)
    weight = np.ones((n, 1))
    step = np.empty_like(g)
    n0 = c0 = None
    query = _FieldQuery(field, n + m)
    ran = 0
    stall = StallCheck(quiet, early_stop)
    try:
        for it in range(iterations):
            if ran % 4 == 0:
                check_cancel(cancel)
                progress(it / max(iterations, 1), f"optimising the cover ({it}/{iterations})")
            cents = cen @ g
            dv, vv = query(g)
            dc, vc = query(cents)
            if stall.due(it) and stall.stalled(distance_summary(dv, dc)):
                break
            grad = _unit_inplace(vv, dv)
            face_grad = _unit_inplace(vc, dc)
            if it < stage2:
                if ran % 8 == 0:  # area weights change slowly
                    _, area = mesh_ops.face_normals(g, faces)
                    s = np.sqrt(np.maximum(inc @ area, 1e-12))
                    weight = (s.max() / s)[:, None]
                wd = lap @ g
                wd -= g
                wd *= weight
                lw = lap_t @ wd
                lw -= wd
                lw *= 2.0 * laplacian_weight
                grad += lw
            else:
                if n0 is None:
                    n0, _ = mesh_ops.face_normals(g, faces)
                    c0 = cents.copy()
                a = cents - c0
                a -= n0 * np.einsum("ij,ij->i", a, n0)[:, None]
                a = _unit_inplace(a, np.sqrt(np.einsum("ij,ij->i", a, a)))
                a *= 0.5
                face_grad += a
            fg = cen_t @ face_grad
            fg *= ratio
            grad += fg
            ran += 1
            # VectorAdam, in place
            mom *= beta1
            mom += (1 - beta1) * grad
            vel *= beta2
            vel += (1 - beta2) * np.einsum("ij,ij->i", grad, grad)
            denom = np.sqrt(vel / (1 - beta2 ** ran))
            denom += eps
            np.divide(mom, denom[:, None], out=step)
            step *= learning_rate(it, iterations, lr) / (1 - beta1 ** ran)
            g -= step
        dv, _ = query(g)
        dc, _ = query(cen @ g)
    finally:
        query.close()
    return field.index_to_world(g), final_stats(ran, dv, dc)
