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
    distinct, copy_of = _distinct_rows(points)
    check_cancel(cancel)
    flagged = np.zeros(len(distinct), dtype=bool)
    for round_ in range(ROUNDS):
        kept = np.flatnonzero(~flagged)
        if len(kept) <= NEIGHBOURS + 1:
            break
        span = (1.0 - _SORT_SHARE - _SURFACE_SHARE) / ROUNDS
        isolated = _isolated(distinct[kept] if round_ else distinct, ratio,
                             sub_progress(progress, _SORT_SHARE + round_ * span,
                                          _SORT_SHARE + (round_ + 1) * span), cancel,
                             f"pass {round_ + 1} of at most {ROUNDS}")
        if not isolated.any():
            break
        flagged[kept[isolated]] = True
    if flagged.any() and np.count_nonzero(~flagged) >= FLAT_NEIGHBOURS:
        on_surface = _on_the_surface(distinct, flagged,
                                     sub_progress(progress, 1.0 - _SURFACE_SHARE, 1.0), cancel)
        flagged[on_surface] = False
    progress(1.0, f"finding outliers: {int(np.count_nonzero(flagged)):,} isolated positions")
    return flagged[copy_of.reshape(-1)]


def _distinct_rows(points: np.ndarray):
    """``np.unique(points, axis=0, return_inverse=True)``, the same rows in the same order.

    Sorted on x alone first (a fraction of the time of sorting whole rows, which would hold up
    a cancel for seconds on millions of points); only runs of equal x are sorted on y and z.
    """
    order = np.argsort(points[:, 0], kind="stable")
    ordered = points[order]
    tie = ordered[1:, 0] == ordered[:-1, 0]
    if tie.any():
        in_run = np.zeros(len(points), dtype=bool)
        in_run[1:] |= tie
        in_run[:-1] |= tie
        runs = np.flatnonzero(in_run)  # runs of distinct x, each contiguous, x ascending
        members = order[runs]
        order[runs] = members[np.lexsort((points[members, 2], points[members, 1],
                                          points[members, 0]))]
        ordered = points[order]
    new = np.ones(len(points), dtype=bool)
    np.any(ordered[1:] != ordered[:-1], axis=1, out=new[1:])
    copy_of = np.empty(len(points), dtype=np.int64)
    copy_of[order] = np.cumsum(new) - 1
    return (ordered if new.all() else ordered[new]), copy_of


def _isolated(points: np.ndarray, ratio: float, progress: ProgressFn = no_progress,
              cancel: Optional[CancelFn] = None, label: str = "") -> np.ndarray:
    """One pass of the spacing test on distinct points: (M, 3) -> (M,) bool."""
    from scipy.spatial import cKDTree

    tree = cKDTree(points)
    check_cancel(cancel)
    neighbours = min(NEIGHBOURS, len(points) - 1)
    chunks = -(-len(points) // _CHUNK)
    steps, done = 2 * chunks, 0

    def step():
        nonlocal done
        done += 1
        check_cancel(cancel)
        progress(done / steps, f"finding outliers ({label}): {100.0 * done / steps:.0f} %")

    spacing = np.empty(len(points))
    for start in range(0, len(points), _CHUNK):
        block = points[start:start + _CHUNK]
        distances, _ = tree.query(block, k=neighbours + 1, workers=query_threads())
        spacing[start:start + len(block)] = distances[:, 1:].mean(axis=1)
        step()
    # the context: the nearest points of a sample (the points are distinct and sorted on x)
    every = max(1, min(CONTEXT_STEP, len(points) // (4 * CONTEXT)))
    sample_tree = tree if every == 1 else cKDTree(points[::every])
    sample_spacing = spacing[::every]
    context = min(CONTEXT // every, len(sample_spacing) - 1)
    isolated = np.empty(len(points), dtype=bool)
    for start in range(0, len(points), _CHUNK):
        block = points[start:start + _CHUNK]
        distance, nearest = sample_tree.query(block, k=context + 1, workers=query_threads())
        itself = distance[:, :1] == 0  # a sampled point is not its own context
        nearest = np.where(itself, nearest[:, 1:], nearest[:, :-1])
        typical = np.median(sample_spacing[nearest], axis=1)
        isolated[start:start + len(block)] = spacing[start:start + len(block)] > ratio * typical
        step()
    return isolated


def _on_the_surface(points: np.ndarray, flagged: np.ndarray, progress: ProgressFn = no_progress,
                    cancel: Optional[CancelFn] = None) -> np.ndarray:
    """Indices of the flagged points that are surface after all (see the module's text)."""
    from scipy.spatial import cKDTree

    suspects = np.flatnonzero(flagged)
    unflagged = points[~flagged]
    everything = cKDTree(points)
    check_cancel(cancel)
    surface = cKDTree(unflagged)
    check_cancel(cancel)
    on_surface = np.empty(len(suspects), dtype=bool)
    for start in range(0, len(suspects), _CHUNK):
        block = points[suspects[start:start + _CHUNK]]
        _, around = everything.query(block, k=FLAT_NEIGHBOURS + 1, workers=query_threads())  # itself included
        flat = _smallest_share(_covariance_eigen(points[around])[0]) < FLATNESS
        _, beside = surface.query(block, k=FLAT_NEIGHBOURS, workers=query_threads())
        eigenvalues, eigenvectors = _covariance_eigen(unflagged[beside])
        centre = unflagged[beside].mean(axis=1)
        off = np.abs(np.einsum("ni,ni->n", block - centre, eigenvectors[:, :, 0]))
        spread = np.sqrt(eigenvalues[:, 1] + eigenvalues[:, 2])
        on_surface[start:start + len(block)] = flat & (off < OFF_PLANE * spread)
        check_cancel(cancel)
        done = min(start + _CHUNK, len(suspects)) / len(suspects)
        progress(done, f"finding outliers (sparing surface points): {100.0 * done:.0f} %")
    return suspects[on_surface]


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
