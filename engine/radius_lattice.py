"""The radius policy on a coarser lattice of the grid, interpolated at the band's nodes.

The curvature estimate and the selector read each query's parent ball of radius R. Where R
spans many grid spacings, neighbouring nodes read nearly the same ball, and their radii differ
little: the selector's R = 0.072 is 18 spacings at resolution 256. So the policy runs on every
``step``-th node along each axis (``step`` the largest power of two at most
``R / (LATTICE_NODES_PER_R * h)``: lattice positions R/8 to R/4 apart), and each band node
takes the trilinear blend of the radii at the corners of its lattice cell. The policy then runs
on about a fifth as many positions as there are band nodes at step 2 and a twenty-fifth at step
4; where R is under ``2 * LATTICE_NODES_PER_R`` spacings the step is 1 and every node gets its
own radius.

The selector's radii differ from node to node (by 2-9 % on average between a node's own and
the blend at step 2 or 4), but the backbone's error is flat near the chosen radius: on the
first test room (noisy), garment (clean) and car (sparse) at 256, the field's mean error at the
nodes within 2 spacings of the true surface moves by -0.6 % to +0.4 % (``docs/performance.md``).

The lattice is anchored at a fixed node (a tiled reconstruction's shared anchor), so tiles that
overlap give their shared nodes the same radii.
"""

from typing import Optional, Tuple

import numpy as np

from .cpu_threads import map_in_threads
from .progress import CancelFn, check_cancel

# The lattice is at most R / LATTICE_NODES_PER_R apart.
LATTICE_NODES_PER_R = 4
# Lattice positions per call of the policy (as the field's batches).
LATTICE_BATCH = 8192


def lattice_step(parent_radius: float, spacing: float) -> int:
    """Nodes between two lattice positions along an axis: a power of two, at least 1."""
    ratio = parent_radius / (LATTICE_NODES_PER_R * spacing)
    step = 1
    while 2 * step <= ratio:
        step *= 2
    return step


def lattice_radii(policy, nodes: np.ndarray, lattice_origin: np.ndarray, spacing: float,
                  step: int, threads: int = 1, cancel: Optional[CancelFn] = None,
                  ) -> Tuple[np.ndarray, dict]:
    """Radii at grid nodes, blended from the policy's radii at the corners of their lattice
    cells.

    Parameters
    ----------
    policy : callable ``positions (P, 3) -> (P,) radii``, the radius policy at given positions
    nodes : (Q, 3) int64, the nodes' indices counted from ``lattice_origin`` (any sign)
    lattice_origin : (3,) float64, the position of node (0, 0, 0) (a lattice position)
    spacing : the grid spacing h
    step : see :func:`lattice_step`
    threads : CPU threads over the batches of lattice positions (the answers do not depend on it)

    Returns
    -------
    radii : (Q,) float64
    stats : ``lattice_step``, ``lattice_positions`` (where the policy ran)
    """
    nodes = np.asarray(nodes, dtype=np.int64)
    base, offset = np.divmod(nodes, step)
    fraction = offset / step
    # the corners with a weight: the cell's upper corner along an axis only where the node is
    # not on the lattice plane of that axis
    corners, weights = [], []
    for corner in np.ndindex(2, 2, 2):
        corner = np.array(corner)
        weight = np.prod(np.where(corner, fraction, 1.0 - fraction), axis=1)
        used = weight > 0
        corners.append((base[used] + corner, np.flatnonzero(used)))
        weights.append(weight[used])
    every = np.concatenate([c for c, _ in corners])
    low = every.min(axis=0) if len(every) else np.zeros(3, np.int64)
    span = (every.max(axis=0) - low + 1) if len(every) else np.ones(3, np.int64)
    keys = np.ravel_multi_index(tuple((every - low).T), tuple(span))  # one int64 per corner
    unique, inverse = np.unique(keys, return_inverse=True)
    inverse = inverse.reshape(-1)
    positions = lattice_origin + (np.column_stack(np.unravel_index(unique, tuple(span))) + low
                                  ) * (step * spacing)

    def one_batch(start: int) -> np.ndarray:
        check_cancel(cancel)
        return policy(positions[start:start + LATTICE_BATCH])

    values = np.concatenate(list(map_in_threads(
        one_batch, range(0, len(positions), LATTICE_BATCH), threads)) or [np.zeros(0)])
    radii = np.zeros(len(nodes), dtype=np.float64)
    start = 0
    for (_, rows), weight in zip(corners, weights):
        radii[rows] += weight * values[inverse[start:start + len(rows)]]
        start += len(rows)
    return radii, {"lattice_step": step, "lattice_positions": int(len(unique))}
