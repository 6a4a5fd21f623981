"""Local patches: the input points inside a ball around each query, as the backbone reads them.

The patch contract is shared by training and inference: for a query q and radius r, take the
(up to) ``max_points`` nearest input points within distance r (inclusive), express them as
``rel = (p - q) / r``, sort them by distance ascending, pad with zero rows and mark the real rows
in ``mask``. A query with no point in its ball has ``counts == 0`` (a "far" query).
"""

from typing import Iterator, NamedTuple, Tuple, Union

import numpy as np

from .cpu_threads import query_threads

MAX_POINTS = 64
# Queries per k-d tree call: bounds memory at about chunk * max_points * 16 bytes of neighbours.
QUERY_CHUNK = 16384
# Above this share of filled slots a patch batch is gathered whole (every slot, padding zeroed
# after), below it point by point: the same values either way, whichever is faster.
DENSE_GATHER_FILL = 0.5


class Neighbours(NamedTuple):
    """Each query's nearest input points within a ball, nearest first (see
    :func:`nearest_within`)."""

    distance: np.ndarray  # (Q, K) float64, inf after the last point in the ball
    index: np.ndarray     # (Q, K) int64, len(points) after the last point in the ball


def nearest_within(tree, queries: np.ndarray, radius: Union[float, np.ndarray],
                   max_points: int) -> Neighbours:
    """The (up to) ``max_points`` nearest input points within ``radius`` of each query.

    Parameters
    ----------
    tree : scipy.spatial.cKDTree
    queries : (Q, 3) float array
    radius : float or (Q,) float array, > 0
    max_points : int

    Returns
    -------
    Neighbours
        ``distance`` (Q, max_points) float64, nearest first, ``inf`` after the last point in
        the ball; ``index`` (Q, max_points) int64, ``len(points)`` after the last point.
    """
    queries = np.asarray(queries, dtype=np.float64).reshape(-1, 3)
    radii = np.broadcast_to(np.asarray(radius, dtype=np.float64), (len(queries),))
    if len(queries) and not np.all(radii > 0):
        raise ValueError("patch radii must be > 0")
    # cKDTree takes one upper bound per call: query at the largest radius (nudged up because
    # the bound is strict) and drop what lies beyond each row's own radius.
    bound = float(np.nextafter(radii.max(), np.inf)) if len(queries) else 1.0
    distance, index = tree.query(queries, k=max_points, distance_upper_bound=bound, workers=query_threads())
    distance = distance.reshape(len(queries), max_points)
    index = index.reshape(len(queries), max_points)
    beyond = distance > radii[:, None]
    distance[beyond] = np.inf
    index[beyond] = tree.n
    return Neighbours(distance, index)


def patches_from_neighbours(points: np.ndarray, queries: np.ndarray, neighbours: Neighbours,
                            radius: Union[float, np.ndarray], max_points: int = MAX_POINTS,
                            ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The patches of radius ``radius`` cut from neighbour lists of a ball at least as large.

    The points within r of q are a prefix of q's nearest-first list within any R >= r, so
    the patch of r is the first up to ``max_points`` entries closer than r, provided the list
    holds at least ``max_points`` entries (or all points within R). The field uses this to read
    the backbone's patch out of the selector's parent ball without a second k-d query.

    Returns ``rel, mask, counts`` as :func:`gather_patches`.
    """
    queries = np.asarray(queries, dtype=np.float64).reshape(-1, 3)
    radii = np.broadcast_to(np.asarray(radius, dtype=np.float64), (len(queries),))
    if len(queries) and not np.all(radii > 0):
        raise ValueError("patch radii must be > 0")
    if neighbours.distance.shape[1] < max_points:
        raise ValueError("the neighbour lists are shorter than the patch")
    inside = neighbours.distance[:, :max_points] <= radii[:, None]
    if inside.mean() > DENSE_GATHER_FILL:  # full balls: one gather of every slot is faster
        index = np.where(inside, neighbours.index[:, :max_points], 0)
        rel = ((points[index] - queries[:, None, :]) / radii[:, None, None]).astype(np.float32)
        rel[~inside] = 0.0
    else:  # only the real points: most balls hold far fewer
        rows, columns = np.nonzero(inside)
        rel = np.zeros((len(queries), max_points, 3), dtype=np.float32)
        rel[rows, columns] = ((points[neighbours.index[rows, columns]] - queries[rows])
                              / radii[rows, None])
    return rel, inside, inside.sum(axis=1).astype(np.int64)


def gather_patches(tree, points: np.ndarray, queries: np.ndarray,
                   radius: Union[float, np.ndarray], max_points: int = MAX_POINTS,
                   ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The nearest input points within ``radius`` of each query, relative and scaled.

    Parameters
    ----------
    tree : scipy.spatial.cKDTree
        Built over ``points``.
    points : (N, 3) float array
        The input points the tree was built on (unit frame).
    queries : (Q, 3) float array
        Query positions (unit frame).
    radius : float or (Q,) float array
        Ball radius, one for all queries or one per query (unit frame, > 0).
    max_points : int
        Patch size: at most this many nearest points are kept.

    Returns
    -------
    rel : (Q, max_points, 3) float32
        ``(p - q) / r`` of the kept points, nearest first; zero rows after the last real point.
    mask : (Q, max_points) bool
        True on real points; the True entries of a row form a prefix.
    counts : (Q,) int64
        Number of real points per query (0 for a far query).
    """
    queries = np.asarray(queries, dtype=np.float64).reshape(-1, 3)
    count = queries.shape[0]
    radii = np.broadcast_to(np.asarray(radius, dtype=np.float64), (count,))
    rel = np.zeros((count, max_points, 3), dtype=np.float32)
    mask = np.zeros((count, max_points), dtype=bool)
    for start in range(0, count, QUERY_CHUNK):
        stop = min(start + QUERY_CHUNK, count)
        q, r = queries[start:stop], radii[start:stop]
        neighbours = nearest_within(tree, q, r, max_points)
        rel[start:stop], mask[start:stop], _ = patches_from_neighbours(points, q, neighbours, r,
                                                                       max_points)
    counts = mask.sum(axis=1).astype(np.int64)
    return rel, mask, counts


def groups_by_count(counts: np.ndarray, group_size: int,
                    min_width: int = 1) -> Iterator[Tuple[np.ndarray, int]]:
    """Patches in order of point count, ``group_size`` at a time, each with the columns worth
    computing: ``(indices, width)``, width = the group's largest count, at least ``min_width``.

    Padding columns never change a masked network's output but cost as much as points; cutting
    each group to its own width skips most of them.
    """
    order = np.argsort(counts, kind="stable")
    for start in range(0, len(order), group_size):
        group = order[start:start + group_size]
        yield group, max(int(counts[group].max()), min_width)
