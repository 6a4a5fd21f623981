"""Local patches: the input points inside a ball around each query, as the backbone reads them.

The patch contract is shared by training and inference: for a query q and radius r, take the
(up to) ``max_points`` nearest input points within distance r (inclusive), express them as
``rel = (p - q) / r``, sort them by distance ascending, pad with zero rows and mark the real rows
in ``mask``. A query with no point in its ball has ``counts == 0`` (a "far" query).
"""

from typing import Iterator, Tuple, Union

import numpy as np

MAX_POINTS = 64
# Queries per k-d tree call: bounds memory at about chunk * max_points * 16 bytes of neighbours.
QUERY_CHUNK = 16384


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
    if count and not np.all(radii > 0):
        raise ValueError("patch radii must be > 0")
    rel = np.zeros((count, max_points, 3), dtype=np.float32)
    mask = np.zeros((count, max_points), dtype=bool)
    for start in range(0, count, QUERY_CHUNK):
        stop = min(start + QUERY_CHUNK, count)
        q, r = queries[start:stop], radii[start:stop]
        # cKDTree takes one upper bound per call: query at the chunk's largest radius (nudged up
        # because the bound is strict) and cut each row at its own radius afterwards.
        bound = float(np.nextafter(r.max(), np.inf))
        dist, index = tree.query(q, k=max_points, distance_upper_bound=bound, workers=-1)
        dist = dist.reshape(len(q), max_points)
        index = index.reshape(len(q), max_points)
        inside = dist <= r[:, None]
        index = np.where(inside, index, 0)  # missing neighbours come back as index N
        chunk_rel = (points[index] - q[:, None, :]) / r[:, None, None]
        chunk_rel[~inside] = 0.0
        rel[start:stop] = chunk_rel
        mask[start:stop] = inside
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
