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

Each iteration runs as passes over row ranges of the vertices and faces, one range per CPU
thread (:class:`_Cover`); the vertices come out the same, bit for bit, on any number of threads.
"""

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Optional

import numpy as np

from ..compiled import kernels as load_kernels
from ..cpu_threads import cpu_threads
from ..progress import CancelFn, ProgressFn, check_cancel, no_progress
from ..udf_grid import CellCache
from . import mesh_ops

STALL_CHECK = 10  # iterations between two convergence checks of the low-step phases
STALL_MEAN = 1e-3  # voxels: the mean vertex / centroid distance improved less than this
STALL_MAX = 1e-2  # voxels: and the largest one improved less than this
SPLIT_VERTICES = 32768  # covers with fewer vertices run on one thread
BETA1, BETA2, EPS = 0.9, 0.999, 1e-8  # VectorAdam
# The defaults of the optimisation (and of MeshingSettings): iterations of both stages, stage 1's
# smoothing weight (voxel units), peak step (voxels per iteration), start of stage 2 (fraction)
ITERATIONS, LAPLACIAN_WEIGHT, LR, NORMAL_START = 200, 4.0, 0.05, 0.75


@dataclass
class OptimizeStats:
    """Iterations run and the final vertex / centroid distances, in voxels."""

    iterations: int
    mean_distance: float
    max_distance: float
    mean_centroid_distance: float
    kernels: str = "numpy"  # or "compiled" (numba loops), "torch" (optimize_torch)


def learning_rate(it: int, total: int, lr: float) -> float:
    """Warm-up over ``total / 16`` iterations, cosine decay to 0, x0.1 from half-way (voxels)."""
    warm = max(1, total // 16)
    rate = lr * min(1.0, (it + 1) / warm) * 0.5 * (1.0 + np.cos(np.pi * it / total))
    return rate * (0.1 if it >= total // 2 else 1.0)


def compiled_kernels():
    """The compiled passes (:mod:`.optimize_kernels`), or None (see
    :func:`engine.compiled.kernels`)."""
    return load_kernels("meshing.optimize_kernels")


def _unit_inplace(vectors: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    vectors /= np.maximum(lengths, 1e-12)[:, None]
    return vectors


def _ranges(count: int, parts: int):
    bounds = np.linspace(0, count, parts + 1).astype(int)
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]


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


class _Cover:
    """The optimisation's state, and its passes over row ranges of the vertices and faces.

    Every row of every pass depends only on arrays that an earlier pass finished (the sparse
    operators are sliced by rows, which keeps each row's sum in the same order), so the ranges
    can run on separate threads (numpy and scipy.sparse release the GIL) and the result is the
    same, bit for bit, whatever the number of ranges.
    """

    def __init__(self, g: np.ndarray, faces: np.ndarray, edges: np.ndarray, field,
                 laplacian_weight: float, parts: int):
        n, m = len(g), len(faces)
        self.g, self.faces, self.field = g, faces, field
        self.lam2 = 2.0 * laplacian_weight
        self.ratio = n / max(m, 1)
        self.vrows, self.frows = _ranges(n, parts), _ranges(m, parts)
        lap = mesh_ops.uniform_laplacian(n, edges)
        cen = mesh_ops.centroid_matrix(n, faces)
        self.inc = mesh_ops.incidence_matrix(n, faces)
        self.operators(lap, lap.T.tocsr(), cen, cen.T.tocsr())
        self.cents, self.face_grad = np.empty((m, 3)), np.empty((m, 3))
        self.dv, self.dc = np.empty(n), np.empty(m)
        self.grad, self.wd = np.empty_like(g), np.empty_like(g)
        self.mom, self.vel = np.zeros_like(g), np.zeros(n)
        self.weight = np.ones((n, 1))
        self.area = np.empty(m)
        # each range's centroids and vertices keep their cells from one iteration to the next
        self.face_cells = [CellCache() for _ in self.frows]
        self.vertex_cells = [CellCache() for _ in self.vrows]
        self.n0 = self.c0 = None  # stage 2's frozen normals and centroids
        self.capture = False  # the next face pass records c0

    def operators(self, lap, lap_t, cen, cen_t) -> None:
        """Keep the sparse operators, sliced by the rows of each range."""
        self.lap = [lap[r] for r in self.vrows]
        self.lap_t = [lap_t[r] for r in self.vrows]
        self.cen = [cen[r] for r in self.frows]
        self.cen_t = [cen_t[r] for r in self.vrows]

    def face_pass(self, k: int, stage1: bool, areas: bool) -> None:
        """Centroids, their distances and gradients (+ stage 2's sliding term); face areas."""
        r = self.frows[k]
        cents = self.cents[r]
        cents[:] = self.cen[k] @ self.g
        self.dc[r], vc = self.field.closest_index(cents, self.face_cells[k])
        grad = _unit_inplace(vc, self.dc[r])
        if stage1:
            if areas:
                self.area[r] = mesh_ops.face_normals(self.g, self.faces[r])[1]
        else:
            if self.capture:
                self.c0[r] = cents
            n0 = self.n0[r]
            a = cents - self.c0[r]
            a -= n0 * np.einsum("ij,ij->i", a, n0)[:, None]
            a = _unit_inplace(a, np.sqrt(np.einsum("ij,ij->i", a, a)))
            a *= 0.5
            grad += a
        self.face_grad[r] = grad

    def vertex_pass(self, k: int, stage1: bool) -> None:
        """Vertex distances and gradients; stage 1's weighted umbrella vectors."""
        r = self.vrows[k]
        self.dv[r], vv = self.field.closest_index(self.g[r], self.vertex_cells[k])
        self.grad[r] = _unit_inplace(vv, self.dv[r])
        if stage1:
            wd = self.lap[k] @ self.g
            wd -= self.g[r]
            wd *= self.weight[r]
            self.wd[r] = wd

    def step_pass(self, k: int, stage1: bool, rate: float, ran: int) -> None:
        """The full gradient of the vertices in range ``k`` and their VectorAdam step."""
        r = self.vrows[k]
        grad = self.grad[r]
        if stage1:
            lw = self.lap_t[k] @ self.wd
            lw -= self.wd[r]
            lw *= self.lam2
            grad += lw
        fg = self.cen_t[k] @ self.face_grad
        fg *= self.ratio
        grad += fg
        mom, vel = self.mom[r], self.vel[r]
        mom *= BETA1
        mom += (1 - BETA1) * grad
        vel *= BETA2
        vel += (1 - BETA2) * np.einsum("ij,ij->i", grad, grad)
        denom = np.sqrt(vel / (1 - BETA2 ** ran))
        denom += EPS
        step = mom / denom[:, None]
        step *= rate / (1 - BETA1 ** ran)
        self.g[r] -= step

    def update_weights(self) -> None:
        """``w_v = max(s) / s_v``, ``s_v = sqrt(vertex area)``, from the face pass's areas."""
        s = np.sqrt(np.maximum(self.inc @ self.area, 1e-12))
        self.weight = (s.max() / s)[:, None]

    def start_stage2(self) -> None:
        """Freeze the face normals now; the next face pass freezes the centroids."""
        self.n0, _ = mesh_ops.face_normals(self.g, self.faces)
        self.c0 = np.empty_like(self.cents)
        self.capture = True


class _CompiledCover(_Cover):
    """The same passes as :class:`_Cover` in compiled loops (:mod:`.optimize_kernels`)."""

    def __init__(self, kernels, *args):
        self.kernels = kernels
        super().__init__(*args)
        self.grid = self.field.brick_arrays()
        self.none = np.zeros((0, 3))  # n0 / c0 before stage 2

    def operators(self, lap, lap_t, cen, cen_t) -> None:
        """Keep the whole operators as CSR arrays (the kernels read the rows of their range)."""
        def arrays(matrix):
            return matrix.indptr.astype(np.int64), matrix.indices.astype(np.int64), matrix.data

        self.lap, self.lap_t, self.cen_t = arrays(lap), arrays(lap_t), arrays(cen_t)

    def face_pass(self, k: int, stage1: bool, areas: bool) -> None:
        r = self.frows[k]
        n0 = self.none if self.n0 is None else self.n0
        c0 = self.none if self.c0 is None else self.c0
        self.kernels.face_rows(r.start, r.stop, self.g, self.faces, self.grid, self.cents,
                               self.dc, self.face_grad, not stage1, self.capture, n0, c0,
                               stage1 and areas, self.area)

    def vertex_pass(self, k: int, stage1: bool) -> None:
        r = self.vrows[k]
        self.kernels.vertex_rows(r.start, r.stop, self.g, self.grid, self.dv, self.grad, stage1,
                                 self.lap, self.weight[:, 0], self.wd)

    def step_pass(self, k: int, stage1: bool, rate: float, ran: int) -> None:
        r = self.vrows[k]
        self.kernels.step_rows(r.start, r.stop, self.g, self.grad, stage1, self.lap_t, self.wd,
                               self.lam2, self.cen_t, self.face_grad, self.ratio, self.mom,
                               self.vel, rate, 1 - BETA1 ** ran, 1 - BETA2 ** ran, BETA1, BETA2,
                               EPS)


def optimize_cover(vertices: np.ndarray, faces: np.ndarray, field,
                   iterations: int = ITERATIONS, laplacian_weight: float = LAPLACIAN_WEIGHT,
                   lr: float = LR, normal_start: float = NORMAL_START,
                   progress: Optional[ProgressFn] = None,
                   cancel: Optional[CancelFn] = None, edges: Optional[np.ndarray] = None,
                   early_stop: bool = True, threads: Optional[int] = None,
                   compiled: bool = True):
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
    threads : int, optional
        CPU threads; by default :func:`~engine.cpu_threads.cpu_threads` for covers of at least
        ``SPLIT_VERTICES`` vertices, else one. The result does not depend on it.
    compiled : bool
        Run the passes as compiled loops (:mod:`.optimize_kernels`) when numba is available and
        the field is a grid (not an exact distance); False always runs the numpy passes.

    Returns
    -------
    vertices : (n, 3) float64 world units; stats : OptimizeStats (``iterations`` counts the
    iterations actually run).
    """
    progress = progress or no_progress
    if threads is None:
        threads = cpu_threads() if len(vertices) >= SPLIT_VERTICES else 1
    parts = max(1, min(int(threads), len(vertices), len(faces)))
    if edges is None:
        edges = mesh_ops.edge_topology(faces).edges
    kernels = compiled_kernels() if compiled and field.exact is None else None
    args = (field.world_to_index(vertices), faces, edges, field, laplacian_weight, parts)
    cover = _Cover(*args) if kernels is None else _CompiledCover(kernels, *args)
    stage2 = int(round(normal_start * iterations))
    quiet = max(stage2, iterations // 2)  # stage 2 with the small step: may stop early
    stall = StallCheck(quiet, early_stop)
    pool = ThreadPoolExecutor(parts) if parts > 1 else None

    def run(task, *args):
        if pool is None:
            task(0, *args)
        else:
            for _ in pool.map(lambda k: task(k, *args), range(parts)):
                pass

    ran = 0
    try:
        for it in range(iterations):
            if ran % 4 == 0:
                check_cancel(cancel)
                progress(it / max(iterations, 1), f"optimising the cover ({it}/{iterations})")
            stage1 = it < stage2
            areas = stage1 and ran % 8 == 0  # area weights change slowly
            if not stage1 and cover.n0 is None:
                cover.start_stage2()
            run(cover.face_pass, stage1, areas)
            cover.capture = False
            if areas:
                cover.update_weights()
            run(cover.vertex_pass, stage1)
            if stall.due(it) and stall.stalled(distance_summary(cover.dv, cover.dc)):
                break
            ran += 1
            run(cover.step_pass, stage1, learning_rate(it, iterations, lr), ran)
        run(cover.face_pass, True, False)
        run(cover.vertex_pass, False)
    finally:
        if pool is not None:
            pool.shutdown()
    stats = final_stats(ran, cover.dv, cover.dc)
    stats.kernels = "numpy" if kernels is None else "compiled"
    return field.index_to_world(cover.g), stats
