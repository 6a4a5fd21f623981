"""The covering-map optimisation of :mod:`.optimize` in torch, for a CUDA GPU.

Same energy, schedule, VectorAdam steps and stopping rule as :func:`.optimize.optimize_cover`,
step for step; the field's closest-point bricks and the mesh operators move to the device once
and every iteration stays there (one small transfer per convergence check). float64 like the
numpy version, apart from the field's float32 interpolation coefficients (as in numpy), so both
give the same vertices up to rounding. torch is imported only when this module is used.
"""

from typing import Optional

import numpy as np

from ..progress import CancelFn, ProgressFn, check_cancel, no_progress
from . import mesh_ops
from ..udf_grid import BRICK, UDFGrid
from .optimize import (BETA1, BETA2, EPS, ITERATIONS, LAPLACIAN_WEIGHT, LR, NORMAL_START,
                       StallCheck, distance_summary, final_stats, learning_rate)

_CELLS = BRICK ** 3


class _DeviceField:
    """``UDFGrid.closest_index`` on the device: trilinear V from the grid's prepared bricks."""

    def __init__(self, field: UDFGrid, device):
        import torch

        if field._bricks is None:
            field.prepare(4.0 * field.spacing + max(field.min_value, 0.0))
        table, cells, nbricks = field._bricks
        self.table = torch.from_numpy(table).to(device)
        self.cells = torch.from_numpy(cells).to(device)  # (bricks * 64, 3, 8) float32
        self.nbricks = [int(b) for b in nbricks]
        self.top = torch.tensor(field.shape, dtype=torch.int32, device=device) - 2
        self.empty_slot = cells.shape[0] // _CELLS - 1  # the last brick holds zeros

    def closest_index(self, g):
        """Distance (P,) and V (P, 3) in voxels at index coordinates g (P, 3) float64;
        distance ``inf`` outside the prepared bricks."""
        import torch

        cell = torch.minimum(g.to(torch.int32), self.top).clamp_min_(0)  # trunc, as numpy
        t = (g - cell).clamp_(0.0, 1.0).float()
        brick = torch.div(cell, BRICK, rounding_mode="floor")
        local = cell - brick * BRICK
        key = (brick[:, 0] * self.nbricks[1] + brick[:, 1]) * self.nbricks[2] + brick[:, 2]
        slot = self.table[key.long()]
        inside = slot >= 0
        slot = torch.where(inside, slot, torch.full_like(slot, self.empty_slot))
        row = slot.long() * _CELLS + ((local[:, 0] * BRICK + local[:, 1]) * BRICK
                                      + local[:, 2]).long()
        coef = self.cells[row]  # (P, 3, 8)
        tx, ty, tz = t.unbind(1)
        txy = tx * ty
        terms = torch.stack([torch.ones_like(tx), tz, ty, ty * tz, tx, tx * tz, txy, txy * tz],
                            dim=1)
        vec = torch.einsum("nck,nk->nc", coef, terms).double()
        dist = torch.sqrt((vec * vec).sum(dim=1))
        dist = torch.where(inside, dist, torch.full_like(dist, float("inf")))
        return dist, vec


def _sparse(matrix, device):
    """A scipy sparse matrix as a torch CSR tensor (float64) on ``device``."""
    import warnings

    import torch

    csr = matrix.tocsr()
    with warnings.catch_warnings():  # "sparse CSR support is in beta": matmul is all we use
        warnings.simplefilter("ignore", UserWarning)
        return torch.sparse_csr_tensor(torch.from_numpy(csr.indptr.astype(np.int64)),
                                       torch.from_numpy(csr.indices.astype(np.int64)),
                                       torch.from_numpy(csr.data.astype(np.float64)),
                                       size=csr.shape, device=device, check_invariants=True)


def _unit(vectors, lengths):
    return vectors / lengths.clamp_min(1e-12)[:, None]


def _face_normals(g, faces):
    import torch

    a, b, c = g[faces[:, 0]], g[faces[:, 1]], g[faces[:, 2]]
    cross = torch.linalg.cross(b - a, c - a)
    norm = torch.linalg.norm(cross, dim=1)
    return cross / norm.clamp_min(1e-300)[:, None], 0.5 * norm


def optimize_cover_torch(vertices: np.ndarray, faces: np.ndarray, field: UDFGrid,
                         iterations: int = ITERATIONS,
                         laplacian_weight: float = LAPLACIAN_WEIGHT, lr: float = LR,
                         normal_start: float = NORMAL_START,
                         progress: Optional[ProgressFn] = None,
                         cancel: Optional[CancelFn] = None, edges: Optional[np.ndarray] = None,
                         early_stop: bool = True, device: str = "cuda"):
    """:func:`.optimize.optimize_cover` on a torch device; same parameters and results.

    ``field`` must be a grid (no exact callable: analytic fields stay in numpy).
    """
    import torch

    if field.exact is not None:
        raise ValueError("the torch optimisation reads grid fields only")
    progress = progress or no_progress
    n, m = len(vertices), len(faces)
    if edges is None:
        edges = mesh_ops.edge_topology(faces).edges
    lap_np = mesh_ops.uniform_laplacian(n, edges)
    cen_np = mesh_ops.centroid_matrix(n, faces)
    lap, lap_t = _sparse(lap_np, device), _sparse(lap_np.T, device)
    cen, cen_t = _sparse(cen_np, device), _sparse(cen_np.T, device)
    inc = _sparse(mesh_ops.incidence_matrix(n, faces), device)
    query = _DeviceField(field, device)
    faces_t = torch.from_numpy(np.asarray(faces, dtype=np.int64)).to(device)
    g = torch.from_numpy(field.world_to_index(vertices)).to(device)
    ratio = n / max(m, 1)
    stage2 = int(round(normal_start * iterations))
    quiet = max(stage2, iterations // 2)
    beta1, beta2, eps = BETA1, BETA2, EPS
    mom = torch.zeros_like(g)
    vel = torch.zeros(n, dtype=g.dtype, device=device)
    weight = torch.ones((n, 1), dtype=g.dtype, device=device)
    n0 = c0 = None
    ran = 0
    stall = StallCheck(quiet, early_stop)
    for it in range(iterations):
        if ran % 4 == 0:
            check_cancel(cancel)
            progress(it / max(iterations, 1), f"optimising the cover ({it}/{iterations})")
        cents = cen @ g
        dv, vv = query.closest_index(g)
        dc, vc = query.closest_index(cents)
        if stall.due(it) and stall.stalled(distance_summary(dv.cpu().numpy(),
                                                                dc.cpu().numpy())):
            break
        grad = _unit(vv, dv)
        face_grad = _unit(vc, dc)
        if it < stage2:
            if ran % 8 == 0:
                _, area = _face_normals(g, faces_t)
                s = torch.sqrt((inc @ area[:, None])[:, 0].clamp_min(1e-12))
                weight = (s.max() / s)[:, None]
            wd = (lap @ g - g) * weight
            grad = grad + 2.0 * laplacian_weight * (lap_t @ wd - wd)
        else:
            if n0 is None:
                n0, _ = _face_normals(g, faces_t)
                c0 = cents.clone()
            a = cents - c0
            a = a - n0 * (a * n0).sum(dim=1, keepdim=True)
            face_grad = face_grad + 0.5 * _unit(a, torch.sqrt((a * a).sum(dim=1)))
        grad = grad + ratio * (cen_t @ face_grad)
        ran += 1
        mom.mul_(beta1).add_(grad, alpha=1 - beta1)
        vel.mul_(beta2).add_((grad * grad).sum(dim=1), alpha=1 - beta2)
        denom = torch.sqrt(vel / (1 - beta2 ** ran)) + eps
        step = learning_rate(it, iterations, lr) / (1 - beta1 ** ran)
        g -= step * (mom / denom[:, None])
    dv, _ = query.closest_index(g)
    dc, _ = query.closest_index(cen @ g)
    stats = final_stats(ran, dv.cpu().numpy(), dc.cpu().numpy())
    stats.kernels = "torch"
    return field.index_to_world(g.cpu().numpy()), stats
