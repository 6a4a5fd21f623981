"""Isolated points (scanner outliers) found before reconstruction, so no surface grows round them.

A point on a surface has neighbours about as close as its neighbours' neighbours do; a stray
point floating off the surface does not. So each point's *spacing* (mean distance to its
:data:`NEIGHBOURS` nearest distinct points) is compared with the median spacing of its
:data:`CONTEXT` nearest points: a point whose spacing is more than ``ratio`` times that median is
flagged. The test is local, so a scan whose density falls off with distance (a far wall, a
grazing floor) keeps its sparse parts; it is scale-free, so it works in any units. Outliers
that float in small clusters shield one another in the first pass, so the test is repeated on
the points that are left, :data:`ROUNDS` times at most. The median is read from a sample of
the cloud, every :data:`CONTEXT_STEP`-th point in the order of x: its ``CONTEXT / CONTEXT_STEP``
points nearest a point span the same neighbourhood as the ``CONTEXT`` nearest of the whole
cloud, for a fraction of the neighbour search. On the first two test shapes of each benchmark
domain in the ``outliers`` condition it finds the same strays to within 4 of 3 657 and flags
2-6 % more points near the surface than the whole cloud's context did, in about a fifth of the
time.

The sparse, ragged edge of a scan also fails the spacing test, yet it is surface: its
neighbourhood is flat and it lies in the plane of the unflagged points next to it. So a flagged
point whose neighbourhood (with itself) is flat (:data:`FLATNESS`) and which lies within
:data:`OFF_PLANE` in-plane spreads of the plane through its :data:`FLAT_NEIGHBOURS` nearest
unflagged points is kept. A stray hovering over a dense surface has a flat neighbourhood too (a
needle: one far point over a small disc), but it lies far off that plane.

Measured on the benchmark's ``outliers`` condition (10 % of the points thrown off the surface),
ratio 2.5 finds 99-99.6 % of the points that lie farther than 0.03 (unit frame) from the
surface of the first two rooms (69-89 % with a context of 64 points, whose median the strays in
a room's empty middle set themselves), and drops 76-147 of their 45 000 surface points (108
and 43 with the 64-point context, 188 and 84 with 256 but no surface test). On the clean,
sparse and noisy scans of those rooms it flags 0.1-0.3 %: edge points the surface test does
not spare. Hence the ``auto`` policy (:data:`AUTO_SHARE`). docs/benchmarks.md has the effect on
the meshes.
"""

from typing import Optional

import numpy as np

from .cpu_threads import query_threads
from .progress import CancelFn, ProgressFn, check_cancel, no_progress, sub_progress
from .settings import DEFAULT_OUTLIER_RATIO

NEIGHBOURS = 8
"""Nearest distinct points whose mean distance is a point's spacing."""

CONTEXT = 256
"""Nearest points whose median spacing a point's spacing is compared with. Large enough that in
a room full of strays the surface's points, not the strays, set the median."""

CONTEXT_STEP = 8
"""The context's median is read from every ``CONTEXT_STEP``-th point (clouds of fewer than
``4 * CONTEXT * CONTEXT_STEP`` points use a denser sample, the smallest every point)."""

ROUNDS = 3
"""Most passes of the test; each pass looks only at the points the previous ones kept."""

FLAT_NEIGHBOURS = 16
"""Nearest points whose spread, with the point's own position, decides whether it is flat."""

FLATNESS = 0.03
"""Smallest over summed eigenvalue of that spread's covariance below which a neighbourhood is
flat (a plane gives 0, points scattered evenly in space 1/3). On the first two clean rooms the
flagged edge points have a median of 0.005-0.012; the strays 0.12."""

OFF_PLANE = 1.0
"""Distance from the plane of the nearest unflagged points, over their in-plane spread (root of
the two larger covariance eigenvalues), below which a flagged point with a flat neighbourhood
is surface."""

AUTO_SHARE = 0.01
"""In ``auto``, the share of outliers from which they are dropped: a few isolated points cost a
mesh little, while any test sometimes mistakes surface for outliers. The clean benchmark scans
give at most 0.3 %, the ``outliers`` condition 8-10 %."""

AUTO_SHRINK = 2.0
"""In ``auto``, outliers fewer than :data:`AUTO_SHARE` are dropped all the same when dropping
them shrinks the bounding box's longest side more than this many times: a few far strays
(50 points 100 m round a 1 cm object) set the unit frame, so every radius and voxel would be
sized to them and the object lost. Surface mistaken for outliers lies on the surface, inside
the box of the rest, and shrinks it hardly at all (1.0 on the benchmark's clean scans)."""

_CHUNK = 20_000
"""Points per neighbour query, so memory stays bounded for clouds of millions of points; also
how often progress is reported and a cancel checked (about half a second a chunk on two cores)."""

SLAB_POINTS = 1_000_000
"""Most candidates a neighbour search puts in one k-d tree: larger clouds are searched slab by
slab (:func:`_nearest_blocks`), so that this stage's memory follows the slab, not the cloud."""
_SORT_SHARE = 0.05
"""Share of the stage's progress for sorting the points (finding copies)."""

_SURFACE_SHARE = 0.1
"""Share of the stage's progress for sparing the flagged points that are surface."""


def find_outliers(points: np.ndarray, ratio: float = DEFAULT_OUTLIER_RATIO,
                  progress: Optional[ProgressFn] = None,
                  cancel: Optional[CancelFn] = None) -> np.ndarray:
    """Which points are isolated from the surface the others describe.

    Parameters
    ----------
    points : (N, 3) float array, any units (finite; duplicates allowed)
    ratio : a point is flagged when its spacing exceeds ``ratio`` times the median spacing
        of its :data:`CONTEXT` nearest points (and is an outlier when its neighbourhood is not
        flat); 0 finds none.
    progress : ``progress(fraction, message)``, told the fraction of this stage done, once per
        :data:`_CHUNK` points of each neighbour query
    cancel : ``cancel() -> bool``, asked as often; :class:`~.errors.Cancelled` is raised when
        it says stop

    Returns
    -------
    (N,) bool
        True for outliers. Copies of one position share one answer.
    """
    progress = progress or no_progress
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if ratio <= 0 or len(points) == 0:
        return np.zeros(len(points), dtype=bool)
    check_cancel(cancel)
    progress(0.0, "finding outliers: sorting the points")
    rows, copy_of = _distinct_rows(points)  # the distinct positions, in sorted order
    check_cancel(cancel)
    flagged = np.zeros(len(rows), dtype=bool)
    for round_ in range(ROUNDS):
        alive = rows[~flagged]
        if len(alive) <= NEIGHBOURS + 1:
            break
        span = (1.0 - _SORT_SHARE - _SURFACE_SHARE) / ROUNDS
        isolated = _isolated(points, alive, ratio,
                             sub_progress(progress, _SORT_SHARE + round_ * span,
                                          _SORT_SHARE + (round_ + 1) * span), cancel,
                             f"pass {round_ + 1} of at most {ROUNDS}")
        del alive
        if not isolated.any():
            break
        flagged[~flagged] = isolated
    if flagged.any() and np.count_nonzero(~flagged) >= FLAT_NEIGHBOURS:
        flagged[flagged] = ~_on_the_surface(points, rows, flagged,
                                            sub_progress(progress, 1.0 - _SURFACE_SHARE, 1.0),
                                            cancel)
    progress(1.0, f"finding outliers: {int(np.count_nonzero(flagged)):,} isolated positions")
    return flagged[copy_of]


def _index_type(count: int):
    """The smallest integer type that numbers ``count`` items (int32 or int64)."""
    return np.int32 if count < 2 ** 31 else np.int64


def _distinct_rows(points: np.ndarray):
    """The distinct positions: ``rows``, the index of one point at each, in the order of
    ``np.unique(points, axis=0)`` (so ``points[rows]`` is its first result), and ``copy_of``,
    each point's position in ``rows`` (its inverse), without copying the points.

    Sorted on x alone first (a fraction of the time of sorting whole rows, which would hold up
    a cancel for seconds on millions of points); only runs of equal x are sorted on y and z.
    """
    index = _index_type(len(points))
    order = np.argsort(points[:, 0], kind="stable").astype(index)
    x = points[order, 0]
    tie = x[1:] == x[:-1]
    del x
    if tie.any():
        in_run = np.zeros(len(points), dtype=bool)
        in_run[1:] |= tie
        in_run[:-1] |= tie
        runs = np.flatnonzero(in_run)  # runs of equal x, each contiguous, x ascending
        members = order[runs]
        order[runs] = members[np.lexsort((points[members, 2], points[members, 1],
                                          points[members, 0]))]
    new = np.ones(len(points), dtype=bool)
    if tie.any():  # only a tie in x can be a copy
        for start in range(1, len(points), _CHUNK * 50):
            at = order[start - 1:start + _CHUNK * 50]
            np.any(points[at[1:]] != points[at[:-1]], axis=1, out=new[start:start + len(at) - 1])
    copy_of = np.empty(len(points), dtype=index)
    copy_of[order] = np.cumsum(new, dtype=index) - 1
    return (order if new.all() else order[new]), copy_of


class _Steps:
    """Counts the points a pass has done; each call reports the share and polls ``cancel``."""

    def __init__(self, steps: int, label: str, progress: ProgressFn,
                 cancel: Optional[CancelFn]):
        self.steps, self.label, self.progress, self.cancel = steps, label, progress, cancel
        self.done = 0

    def __call__(self, count: int) -> None:
        self.done += count
        check_cancel(self.cancel)
        share = self.done / self.steps
        self.progress(share, f"{self.label}: {100.0 * share:.0f} %")


def _isolated(points: np.ndarray, alive: np.ndarray, ratio: float,
              progress: ProgressFn = no_progress, cancel: Optional[CancelFn] = None,
              label: str = "") -> np.ndarray:
    """One pass of the spacing test on the distinct points ``points[alive]`` (``alive``:
    indices, in sorted order): (len(alive),) bool."""
    neighbours = min(NEIGHBOURS, len(alive) - 1)
    step = _Steps(2 * len(alive), f"finding outliers ({label})", progress, cancel)
    spacing = np.empty(len(alive))
    for which, distances, _ in _nearest_blocks(points, alive, alive, neighbours + 1, cancel):
        spacing[which] = distances[:, 1:].mean(axis=1)
        step(len(which))
    # the context: the nearest points of a sample (the points are distinct and sorted on x)
    every = max(1, min(CONTEXT_STEP, len(alive) // (4 * CONTEXT)))
    sample_spacing = spacing[::every]
    context = min(CONTEXT // every, len(sample_spacing) - 1)
    isolated = np.empty(len(alive), dtype=bool)
    for which, distance, nearest in _nearest_blocks(points, alive[::every], alive,
                                                    context + 1, cancel):
        itself = distance[:, :1] == 0  # a sampled point is not its own context
        nearest = np.where(itself, nearest[:, 1:], nearest[:, :-1])
        typical = np.median(sample_spacing[nearest], axis=1)
        isolated[which] = spacing[which] > ratio * typical
        step(len(which))
    return isolated


def _on_the_surface(points: np.ndarray, rows: np.ndarray, flagged: np.ndarray,
                    progress: ProgressFn = no_progress,
                    cancel: Optional[CancelFn] = None) -> np.ndarray:
    """Of the flagged distinct points (``points[rows[flagged]]``), which are surface after all
    (see the module's text): (flagged.sum(),) bool."""
    suspects = rows[flagged]
    unflagged = rows[~flagged]
    step = _Steps(2 * len(suspects), "finding outliers (sparing surface points)", progress,
                  cancel)
    flat = np.empty(len(suspects), dtype=bool)
    for which, _, around in _nearest_blocks(points, rows, suspects, FLAT_NEIGHBOURS + 1,
                                            cancel):  # itself included
        flat[which] = _smallest_share(_covariance_eigen(points[rows[around]])[0]) < FLATNESS
        step(len(which))
    on_surface = np.empty(len(suspects), dtype=bool)
    for which, _, beside in _nearest_blocks(points, unflagged, suspects, FLAT_NEIGHBOURS,
                                            cancel):
        group = points[unflagged[beside]]
        eigenvalues, eigenvectors = _covariance_eigen(group)
        off = np.abs(np.einsum("ni,ni->n", points[suspects[which]] - group.mean(axis=1),
                               eigenvectors[:, :, 0]))
        spread = np.sqrt(eigenvalues[:, 1] + eigenvalues[:, 2])
        on_surface[which] = off < OFF_PLANE * spread
        step(len(which))
    return flat & on_surface


def _nearest_blocks(points: np.ndarray, among: np.ndarray, asked: np.ndarray, k: int,
                    cancel: Optional[CancelFn] = None):
    """The ``k`` nearest of ``points[among]`` to each of ``points[asked]`` (``among``, ``asked``:
    indices), as blocks of at most :data:`_CHUNK` asked points: yields ``(which, distances,
    nearest)``, the blocks' positions in ``asked``, their distances (ascending) and their
    neighbours' positions in ``among``, every asked point once, in no fixed order.

    Up to :data:`SLAB_POINTS` candidates one k-d tree holds them all. More are cut into slabs
    of that many along the cloud's longest side, each searched with a tree over its own
    candidates; an asked point whose k-th distance reaches past the slab's ends (a nearer
    neighbour might lie beyond) is asked again of a tree over the slab widened on both sides
    by the largest such distance. So memory follows the slab, not the cloud, and the
    neighbours are the one tree's (equally distant ones aside).
    """
    from scipy.spatial import cKDTree

    if len(among) <= SLAB_POINTS:
        tree = cKDTree(points[among])
        for start in range(0, len(asked), _CHUNK):
            which = np.arange(start, min(start + _CHUNK, len(asked)))
            distances, nearest = tree.query(points[asked[which]], k=k, workers=query_threads())
            yield which, distances.reshape(len(which), -1), nearest.reshape(len(which), -1)
        return
    axis = int(np.argmax(points.max(axis=0) - points.min(axis=0)))
    order = np.argsort(points[among, axis], kind="stable").astype(_index_type(len(among)))
    coordinate = points[among[order], axis]  # the candidates' along the axis, ascending
    asked_at = points[asked, axis]
    ends = coordinate[0], coordinate[-1]
    for first in range(0, len(among), SLAB_POINTS):
        low = coordinate[first] if first else -np.inf
        high = coordinate[first + SLAB_POINTS] if first + SLAB_POINTS < len(among) else np.inf
        waiting = np.flatnonzero((asked_at >= low) & (asked_at < high))
        margin = 0.0
        while len(waiting):
            check_cancel(cancel)
            window = np.sort(order[np.searchsorted(coordinate, low - margin, side="left"):
                                   np.searchsorted(coordinate, high + margin, side="right")])
            tree = cKDTree(points[among[window]])
            reach_low = -np.inf if low - margin <= ends[0] else low - margin
            reach_high = np.inf if high + margin >= ends[1] else high + margin
            short = []
            for start in range(0, len(waiting), _CHUNK):
                which = waiting[start:start + _CHUNK]
                at = asked_at[which]
                distances, nearest = tree.query(points[asked[which]], k=k,
                                                workers=query_threads())
                distances = distances.reshape(len(which), -1)
                nearest = nearest.reshape(len(which), -1)
                inside = distances[:, -1] <= np.minimum(at - reach_low, reach_high - at)
                short.append(np.column_stack([which[~inside], distances[~inside, -1]]))
                if inside.any():
                    yield which[inside], distances[inside], window[nearest[inside]]
            del tree, window
            short = np.concatenate(short)
            waiting = short[:, 0].astype(np.int64)
            if len(waiting):  # the margin these points need: their k-th distance at most
                margin = max(margin, float(short[:, 1].max()) * (1 + 1e-9))


def _covariance_eigen(groups: np.ndarray):
    """Eigenvalues (ascending) and eigenvectors of each (K, 3) group's covariance."""
    spread = groups - groups.mean(axis=1, keepdims=True)
    return np.linalg.eigh(np.einsum("nki,nkj->nij", spread, spread) / groups.shape[1])


def _smallest_share(eigenvalues: np.ndarray) -> np.ndarray:
    """Smallest eigenvalue over their sum (0 for a plane, 1/3 for an even scatter)."""
    return eigenvalues[:, 0] / np.maximum(eigenvalues.sum(axis=1), 1e-300)


def box_shrink(points: np.ndarray, outlier: np.ndarray) -> float:
    """How many times the bounding box's longest side shrinks when the outliers are dropped.

    Parameters
    ----------
    points : (N, 3) float array
    outlier : (N,) bool, as :func:`find_outliers` returns

    Returns
    -------
    float
        Longest side with every point over longest side without the outliers (>= 1); 1 when
        none or all are outliers, inf when the points left all lie at one position.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    outlier = np.asarray(outlier, dtype=bool).reshape(-1)
    if not outlier.any() or outlier.all():
        return 1.0
    kept = points[~outlier]
    before = float(np.max(points.max(axis=0) - points.min(axis=0)))
    after = float(np.max(kept.max(axis=0) - kept.min(axis=0)))
    return float("inf") if after == 0.0 else before / after
