"""Split the optimised double cover into one layer, component by component.

After the optimisation both sides of every cover piece lie on the surface S. Per piece:

* ``CLOSED_PAIR``: the piece's faces have their twins (a face on top of them with the opposite
  normal) in another piece and vice versa: the two shells of a closed surface. The shell with
  the larger signed volume (the outer one, normals outward) is kept; no max-flow is run.
* ``SPLIT``: the twins are in the piece itself (an open sheet folded at its rim). A min-cut on
  the dual graph (PyMaxflow) separates a seed region from the region under its twin; the cut is
  cheap across the sharp folds along S's boundary (capacity ``1 + 1000 ((1 + cos t) / 2)^4``
  times the edge length, ``t`` the angle between face normals) and dear across flat areas.
  Accepted when balanced, along folds only, and leaving no twins on one side; one side is kept.
* ``NOT_ORIENTABLE``: every cut had to cross flat areas or left both layers on one side (a
  Möbius strip, a T-junction): the piece is kept double-layered.
* ``FAILED``: the layers did not meet (too few twins) or no seed pair could be placed; the piece
  is kept as it is.
* ``UNCUT``: cutting was switched off.

Seeds are drawn from a numpy Generator seeded by the caller; at most ``MAX_ATTEMPTS`` seed pairs
are tried per piece.
"""

from dataclasses import dataclass
from enum import Enum
from typing import List, Optional

import numpy as np

from ..progress import CancelFn, ProgressFn, check_cancel, no_progress
from . import mesh_ops

MAX_ATTEMPTS = 8
SEED_FRACTION = 0.02  # each seed region holds this fraction of the piece's faces
BALANCE = 0.2  # | |P0| - |P1| | <= BALANCE * (|P0| + |P1|)
TWIN_RADIUS = 0.75  # voxels between a face centroid and its twin's
SAMPLES = 2000  # faces sampled per piece for the twin statistics


class Status(str, Enum):
    """What happened to one piece of the double cover."""

    SPLIT = "SPLIT"
    CLOSED_PAIR = "CLOSED_PAIR"
    NOT_ORIENTABLE = "NOT_ORIENTABLE"
    FAILED = "FAILED"
    UNCUT = "UNCUT"


@dataclass
class ComponentRecord:
    """One piece of the cover: status, faces kept in the output, faces in the cover, details."""

    status: Status
    faces: int
    cover_faces: int
    detail: str = ""


class _Twins:
    """Finds, for a face, the nearest face on the other layer (opposite normal, < radius)."""

    def __init__(self, centroids, normals, radius):
        from scipy.spatial import cKDTree

        self.tree = cKDTree(centroids)
        self.centroids, self.normals, self.radius = centroids, normals, radius

    def __call__(self, query: np.ndarray) -> np.ndarray:
        """Twin face index per queried face, -1 when none."""
        if len(query) == 0:
            return np.zeros(0, dtype=np.int64)
        k = min(32, len(self.centroids))
        _, idx = self.tree.query(self.centroids[query], k=k, distance_upper_bound=self.radius)
        idx = idx.reshape(len(query), k)
        valid = idx < len(self.centroids)
        safe = np.where(valid, idx, 0)
        dots = np.einsum("qkc,qc->qk", self.normals[safe], self.normals[query])
        ok = valid & (dots < -0.5)
        first = np.argmax(ok, axis=1)
        found = ok[np.arange(len(query)), first]
        return np.where(found, safe[np.arange(len(query)), first], -1)


def _region(graph, start: int, size: int) -> np.ndarray:
    """The first ``size`` faces of a breadth-first search from ``start``."""
    from scipy.sparse.csgraph import breadth_first_order

    order = breadth_first_order(graph, start, directed=False, return_predecessors=False)
    return order[:size]


def _min_cut(n_faces, pairs, capacity, source, sink):
    """Boykov-Kolmogorov min-cut; returns True for the faces on the sink side."""
    import maxflow

    graph = maxflow.Graph[float](n_faces, len(pairs))
    nodes = graph.add_nodes(n_faces)
    graph.add_edges(nodes[pairs[:, 0]], nodes[pairs[:, 1]], capacity, capacity)
    big = float(capacity.sum()) + 1.0
    src = np.zeros(n_faces)
    snk = np.zeros(n_faces)
    src[source] = big
    snk[sink] = big
    graph.add_grid_tedges(nodes, src, snk)
    graph.maxflow()
    return graph.get_grid_segments(nodes)


def _peel_lips(keep, pairs, cos, faces, largest_share=0.9):
    """Drop kept faces folded back against the kept sheet (slivers of the rim's fold).

    The kept faces are split along sharp folds (``cos < -0.5``); the largest resulting patch
    stays. The other patches that touch the edge of the kept set go (lips along the rim), when
    all the others together hold less than ``1 - largest_share`` of the kept faces; enclosed
    patches stay so no hole opens. ``faces`` (m, 3) are the piece's faces. Returns the new mask.
    """
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components

    idx = np.nonzero(keep)[0]
    position = np.full(len(keep), -1, dtype=np.int64)
    position[idx] = np.arange(len(idx))
    smooth = keep[pairs[:, 0]] & keep[pairs[:, 1]] & (cos >= -0.5)
    a, b = position[pairs[smooth, 0]], position[pairs[smooth, 1]]
    graph = sparse.coo_matrix((np.ones(len(a)), (a, b)), shape=(len(idx), len(idx)))
    count, labels = connected_components(graph, directed=False)
    if count < 2:
        return keep
    sizes = np.bincount(labels)
    main = int(np.argmax(sizes))
    if sizes[main] < largest_share * len(idx):
        return keep
    # only patches touching the edge of the kept set (a vertex shared with a dropped face) are
    # lips; enclosed crumples stay, so no hole opens
    dropped_vertex = np.zeros(int(faces.max()) + 1, bool)
    dropped_vertex[faces[~keep].reshape(-1)] = True
    on_rim = np.zeros(count, bool)
    on_rim[labels[dropped_vertex[faces[idx]].any(axis=1)]] = True
    drop = on_rim & (np.arange(count) != main)
    out = keep.copy()
    out[idx[drop[labels]]] = False
    return out


def _split_piece(faces_idx, faces, pairs, capacity, cos, edge_len, twins, rng):
    """Try seed pairs on one piece; returns (keep mask over faces_idx or None, status, detail)."""
    from scipy import sparse

    m = len(faces_idx)
    flat = cos > 0.0
    size = max(1, int(SEED_FRACTION * m))
    # seed regions grow within one layer: across flat (non-fold) edges only
    sheet = sparse.coo_matrix((np.ones(int(flat.sum())), (pairs[flat, 0], pairs[flat, 1])),
                              shape=(m, m)).tocsr()
    candidates = rng.permutation(m)[:4 * MAX_ATTEMPTS]
    cand_twins = twins(faces_idx[candidates])
    position = np.full(int(faces_idx.max()) + 1, -1, dtype=np.int64)
    position[faces_idx] = np.arange(m)
    reasons = []
    attempts = 0
    for f, t in zip(candidates, cand_twins):
        if attempts >= MAX_ATTEMPTS:
            break
        if t < 0 or t >= len(position) or position[t] < 0:
            continue
        attempts += 1
        a = _region(sheet, int(f), size)
        b = _region(sheet, int(position[t]), size)
        if np.intersect1d(a, b).size:
            reasons.append((False, "seed regions overlap"))
            continue
        sink = _min_cut(m, pairs, capacity, a, b)
        n1 = int(sink.sum())
        n0 = m - n1
        cut = sink[pairs[:, 0]] != sink[pairs[:, 1]]
        cut_len = float(edge_len[cut].sum())
        flat_len = float(edge_len[cut & flat].sum())
        sample = rng.permutation(m)[:SAMPLES]
        st = twins(faces_idx[sample])
        has = (st >= 0) & (st < len(position))
        has[has] = position[st[has]] >= 0
        same = float(np.mean(sink[sample[has]] == sink[position[st[has]]])) if has.any() else 0.0
        problems = []
        if flat_len > max(3.0, 0.05 * cut_len):
            problems.append(f"cut crosses {flat_len:.0f} voxels of flat surface")
        if same > 0.05:
            problems.append(f"{100 * same:.0f}% of the faces keep their twin on one side")
        topological = bool(problems)
        if abs(n0 - n1) > BALANCE * m:
            problems.append(f"unbalanced cut {n0}/{n1}")
        if not problems:
            keep = _peel_lips(~sink if n0 >= n1 else sink, pairs, cos, faces)
            return keep, Status.SPLIT, f"cut length {cut_len:.0f} voxels"
        reasons.append((topological, ", ".join(problems)))
    text = "; ".join(r for _, r in reasons[:3]) or "no seed pair found"
    if reasons and sum(t for t, _ in reasons) * 2 > len(reasons):
        return None, Status.NOT_ORIENTABLE, text
    return None, Status.FAILED, text


def split_cover(vertices: np.ndarray, faces: np.ndarray, spacing: float, cut: bool = True,
                seed: int = 0, progress: Optional[ProgressFn] = None,
                cancel: Optional[CancelFn] = None):
    """Choose the faces of the optimised cover that make one layer.

    Parameters
    ----------
    vertices : (n, 3) float64, world units; faces : (m, 3) int64, the optimised cover.
    spacing : float
        Voxel size (world units): the scale of the twin search and of the cut lengths.
    cut : bool
        False keeps every face (status ``UNCUT``).
    seed : int
        Seeds the choice of seed faces.

    Returns
    -------
    keep : (m,) bool, faces of the output; records : list of ComponentRecord, largest first.
    """
    progress = progress or no_progress
    rng = np.random.default_rng(seed)
    m = len(faces)
    topo = mesh_ops.edge_topology(faces)
    pairs, edge_ids = mesh_ops.dual_edges(faces, topo)
    count, labels = mesh_ops.face_components(m, pairs)
    sizes = np.bincount(labels, minlength=count)
    order = np.argsort(-sizes, kind="stable")
    if not cut:
        return np.ones(m, bool), [ComponentRecord(Status.UNCUT, int(sizes[c]), int(sizes[c]))
                                  for c in order]
    x = vertices / spacing
    normals, _ = mesh_ops.face_normals(x, faces)
    cents = x[faces].mean(axis=1)
    twins = _Twins(cents, normals, TWIN_RADIUS)
    cos = np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]])
    edge_len = np.linalg.norm(x[topo.edges[edge_ids, 0]] - x[topo.edges[edge_ids, 1]], axis=1)
    capacity = edge_len * (1.0 + 1000.0 * ((1.0 + cos) / 2.0) ** 4) + 1e-9
    pair_label = labels[pairs[:, 0]]
    pair_order = np.argsort(pair_label, kind="stable")
    pair_start = np.searchsorted(pair_label[pair_order], np.arange(count + 1))
    face_order = np.argsort(labels, kind="stable")
    face_start = np.searchsorted(labels[face_order], np.arange(count + 1))

    # where do each piece's twins live?
    partner = np.full(count, -1, dtype=np.int64)
    twinned = np.zeros(count)
    for c in order:
        members = face_order[face_start[c]:face_start[c + 1]]
        sample = members[rng.permutation(len(members))[:SAMPLES]]
        t = twins(sample)
        found = t >= 0
        twinned[c] = found.mean()
        if found.any():
            where = np.bincount(labels[t[found]], minlength=count)
            best = int(np.argmax(where))
            if where[best] >= 0.7 * found.sum():
                partner[c] = best
    keep = np.zeros(m, bool)
    records: List[ComponentRecord] = []
    done = np.zeros(count, bool)
    for step, c in enumerate(order):
        check_cancel(cancel)
        progress(step / max(count, 1), f"splitting piece {step + 1} of {count}")
        if done[c]:
            continue
        done[c] = True
        members = face_order[face_start[c]:face_start[c + 1]]
        p = partner[c]
        if twinned[c] < 0.5:
            keep[members] = True
            records.append(ComponentRecord(Status.FAILED, len(members), len(members),
                                           "the two layers did not meet"))
        elif p >= 0 and p != c and partner[p] == c and not done[p]:
            done[p] = True
            other = face_order[face_start[p]:face_start[p + 1]]
            vol_c = mesh_ops.signed_volume(x, faces[members])
            vol_p = mesh_ops.signed_volume(x, faces[other])
            kept = members if vol_c >= vol_p else other
            keep[kept] = True
            records.append(ComponentRecord(Status.CLOSED_PAIR, len(kept),
                                           len(members) + len(other)))
        elif p == c:
            sel = pair_order[pair_start[c]:pair_start[c + 1]]
            position = np.empty(m, dtype=np.int64)
            position[members] = np.arange(len(members))
            local_pairs = position[pairs[sel]]
            mask, status, detail = _split_piece(members, faces[members], local_pairs,
                                                capacity[sel], cos[sel], edge_len[sel], twins,
                                                rng)
            if mask is None:
                keep[members] = True
                records.append(ComponentRecord(status, len(members), len(members), detail))
            else:
                keep[members[mask]] = True
                records.append(ComponentRecord(status, int(mask.sum()), len(members), detail))
        else:
            keep[members] = True
            records.append(ComponentRecord(Status.FAILED, len(members), len(members),
                                           "its twin faces lie in several pieces"))
    return keep, records
