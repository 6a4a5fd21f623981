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

from dataclasses import dataclass
from typing import Optional

import numpy as np

from ..progress import CancelFn, ProgressFn, check_cancel, no_progress
from . import mesh_ops


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


def _unit(vectors: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    return vectors / np.maximum(lengths, 1e-12)[:, None]


def optimize_cover(vertices: np.ndarray, faces: np.ndarray, field, iterations: int = 400,
                   laplacian_weight: float = 16.0, lr: float = 0.05,
                   normal_start: float = 0.75, progress: Optional[ProgressFn] = None,
                   cancel: Optional[CancelFn] = None, edges: Optional[np.ndarray] = None):
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
        Total iterations of both stages.
    laplacian_weight : float
        ``lam`` in voxel units (DCUDF's weight times the voxel size: 2000 at 256^3 over
        [-1, 1] is about 16).
    lr : float
        Peak step, voxels per iteration.
    normal_start : float
        Fraction of the iterations after which stage 2 starts.
    edges : (E, 2) int64, optional
        The cover's unique edges, when already known.

    Returns
    -------
    vertices : (n, 3) float64 world units; stats : OptimizeStats.
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
    beta1, beta2, eps = 0.9, 0.999, 1e-8
    mom = np.zeros_like(g)
    vel = np.zeros(n)
    weight = np.ones(n)
    n0 = c0 = None
    for it in range(iterations):
        if it % 4 == 0:
            check_cancel(cancel)
            progress(it / max(iterations, 1), f"optimising the cover ({it}/{iterations})")
        cents = cen @ g
        dv, vv = field.closest_index(g)
        dc, vc = field.closest_index(cents)
        grad = _unit(vv, dv)
        face_grad = _unit(vc, dc)
        if it < stage2:
            if it % 8 == 0:  # area weights change slowly
                _, area = mesh_ops.face_normals(g, faces)
                s = np.sqrt(np.maximum(inc @ area, 1e-12))
                weight = (s.max() / s)[:, None]
            wd = weight * (lap @ g - g)
            grad += 2.0 * laplacian_weight * (lap_t @ wd - wd)
        else:
            if n0 is None:
                n0, _ = mesh_ops.face_normals(g, faces)
                c0 = cents.copy()
            a = cents - c0
            a -= n0 * np.einsum("ij,ij->i", a, n0)[:, None]
            face_grad += 0.5 * _unit(a, np.linalg.norm(a, axis=1))
        grad += ratio * (cen_t @ face_grad)
        t = it + 1
        mom = beta1 * mom + (1 - beta1) * grad
        vel = beta2 * vel + (1 - beta2) * np.einsum("ij,ij->i", grad, grad)
        step = (mom / (1 - beta1 ** t)) / (np.sqrt(vel / (1 - beta2 ** t)) + eps)[:, None]
        g -= learning_rate(it, iterations, lr) * step
    dv, _ = field.closest_index(g)
    dc, _ = field.closest_index(cen @ g)
    finite = np.isfinite(dv)
    stats = OptimizeStats(iterations, float(dv[finite].mean()) if finite.any() else 0.0,
                          float(dv[finite].max()) if finite.any() else 0.0,
                          float(dc[np.isfinite(dc)].mean()) if np.isfinite(dc).any() else 0.0)
    return field.index_to_world(g), stats
