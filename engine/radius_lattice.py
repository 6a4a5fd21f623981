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

The blend cannot follow the selector where its radius changes within a few nodes: midway
between two sheets a few spacings apart (a car's floor panel over its underbody), whose nodes
lie about as far from both, the selector picks a ball two to three times wider than at the
nodes beside them, wide enough to see both sheets, while the blend of the lattice's radii
around them, all near one sheet or the other, is as small as theirs; the backbone, given a
small ball holding the fringes of both sheets, puts a false minimum there, and the mesh
wrinkles between the sheets. Such a node is on a *ridge* of the distance to the nearest point:
a neighbour's nearest point lies the other way (their offsets to them more than 120 degrees
apart, :data:`RIDGE_COS`), both at least a spacing off (:data:`RIDGE_MIN_NODES`: two nodes
across one surface lie within a spacing of it together). :func:`ridge_nodes` finds them: at
resolution 256, 5 % of the network's nodes on the owl, 7-9 % on the benchmark's first garment
and room, 12-17 % on its first car (clean and sparse), whose closed parts nest and touch. The
policy runs at each of them too, and a ridge node takes its own radius where that is wider
than the blend. (Where it is narrower, the blend stays: on a sparse scan many ridge nodes lie
in the holes between its points, on the surface, and the blend's smoother radii there gave
the benchmark's sparse cars a mesh as good or slightly better.)

The lattice is anchored at a fixed node (a tiled reconstruction's shared anchor), so tiles that
overlap give their shared nodes the same radii; the ridge test reads a node's neighbours and
their nearest points, which every tile that holds the node in its core sees alike.
"""

from typing import Optional, Tuple

import numpy as np

from .cpu_threads import map_in_threads
from .progress import CancelFn, check_cancel

# The lattice is at most R / LATTICE_NODES_PER_R apart.
LATTICE_NODES_PER_R = 4
# Lattice positions per call of the policy (as the field's batches).
LATTICE_BATCH = 8192
# Neighbouring nodes whose offsets to their nearest points have a cosine under this are on
# either side of a ridge of the nearest-point distance ...
RIDGE_COS = -0.5
# ... when both lie at least this many spacings from their nearest points.
RIDGE_MIN_NODES = 1.0


def lattice_step(parent_radius: float, spacing: float) -> int:
    """Nodes between two lattice positions along an axis: a power of two, at least 1."""
    ratio = parent_radius / (LATTICE_NODES_PER_R * spacing)
    step = 1
    while 2 * step <= ratio:
        step *= 2
    return step


def lattice_radii(policy, nodes: np.ndarray, lattice_origin: np.ndarray, spacing: float,
                  step: int, threads: int = 1, cancel: Optional[CancelFn] = None,
                  own: Optional[np.ndarray] = None) -> Tuple[np.ndarray, dict]:
    """Radii at grid nodes, blended from the policy's radii at the corners of their lattice
    cells; an ``own`` node takes the policy's radius at its own position where that is wider.

    Parameters
    ----------
    policy : callable ``positions (P, 3) -> (P,) radii``, the radius policy at given positions
    nodes : (Q, 3) int64, the nodes' indices counted from ``lattice_origin`` (any sign)
    lattice_origin : (3,) float64, the position of node (0, 0, 0) (a lattice position)
    spacing : the grid spacing h
    step : see :func:`lattice_step`
    threads : CPU threads over the batches of lattice positions (the answers do not depend on it)
    own : (Q,) bool, optional: the nodes whose own radius is asked too (:func:`ridge_nodes`)

    Returns
    -------
    radii : (Q,) float64
    stats : ``lattice_step``, ``lattice_positions`` (where the policy ran for the blends),
        ``lattice_own_nodes`` (where it ran for the ``own`` nodes)
    """
    nodes = np.asarray(nodes, dtype=np.int64)
    own = np.zeros(len(nodes), bool) if own is None else np.asarray(own, dtype=bool)
    own_rows = np.flatnonzero(own)
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
    positions = np.concatenate([positions, lattice_origin + nodes[own_rows] * spacing])

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
    radii[own_rows] = np.maximum(radii[own_rows], values[len(unique):])
    return radii, {"lattice_step": step, "lattice_positions": int(len(unique)),
                   "lattice_own_nodes": int(len(own_rows))}


def ridge_nodes(nodes: np.ndarray, offsets: np.ndarray, spacing: float) -> np.ndarray:
    """Which grid nodes lie on a ridge of the distance to the nearest point (see the module's
    text): a neighbour along an axis, among ``nodes``, whose offset to its nearest point makes a
    cosine under :data:`RIDGE_COS` with the node's, both offsets at least
    :data:`RIDGE_MIN_NODES` spacings long.

    Parameters
    ----------
    nodes : (Q, 3) int64 grid indices (any sign, distinct)
    offsets : (Q, 3) float, each node's position minus its nearest point's
    spacing : the grid spacing

    Returns
    -------
    (Q,) bool
    """
    nodes = np.asarray(nodes, dtype=np.int64)
    ridge = np.zeros(len(nodes), bool)
    if len(nodes) < 2:
        return ridge
    offsets = np.asarray(offsets, dtype=np.float64)
    length = np.sqrt(np.einsum("ij,ij->i", offsets, offsets))
    far = length >= RIDGE_MIN_NODES * spacing
    low = nodes.min(axis=0) - 1
    span = tuple(nodes.max(axis=0) - low + 2)
    keys = np.ravel_multi_index(tuple((nodes - low).T), span)
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    for stride in (span[1] * span[2], span[2], 1):  # the next node along x, y, z
        at = np.searchsorted(sorted_keys, keys + stride)
        found = np.flatnonzero(sorted_keys[np.minimum(at, len(keys) - 1)] == keys + stride)
        other = order[at[found]]
        both = far[found] & far[other]
        a, b = found[both], other[both]
        across = (np.einsum("ij,ij->i", offsets[a], offsets[b])
                  < RIDGE_COS * length[a] * length[b])
        ridge[a[across]] = True
        ridge[b[across]] = True
    return ridge
