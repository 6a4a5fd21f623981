"""Keep one layer of the optimised double cover, everywhere.

After the optimisation both layers of the cover lie on the surface S, facing opposite ways: every
face of one layer has a *twin* of the other layer on top of it. One face of every twin pair has to
go, and neighbouring faces should make the same choice. That is a labelling with two kinds of
constraints on the faces:

* twins get **opposite** labels (one kept, one dropped);
* faces that share an edge get the **same** label, the more firmly the flatter the join.

On an orientable sheet the constraints agree. Where they cannot all hold (a Möbius strip, a
T-junction where three half-sheets meet, a shelf touching a wall, touching parts) the weakest
ones give way. The labelling is the parity along a minimum spanning forest of the constraint
graph (Kruskal on a signed graph): twin constraints first, then shared edges from flat to
folded, so the choice switches layers across creases and folds, and across a flat area only
where the topology leaves no other way. The min-cut of DCUDF, one balanced bipartition per
piece, refuses those pieces and keeps both layers; this does not.

Per tree, the label whose faces had the larger area *before* the optimisation is kept: the outer
shell of a closed surface (its cover's outer layer is the larger), either side of an open sheet.
Where the choice switches layers the kept faces end in a *seam*: a boundary lying on the other
kept sheet, less than a voxel from it. Seams are left as they are (welding them onto the other
sheet turned faces over and measured as more double area than it closed). Rims, the boundaries
beyond which the field rises, are moved out to where the field puts the surface's rim, the
crowded rows of faces behind them stretched out in order (:func:`extend_rims`).

Where the two layers of one sheet stalled more than a voxel apart, the kept one moves halfway to
the dropped one, where the surface lies (:func:`_centre_stalled`).

Kept faces that still face each other within a voxel, turned less than twins (both layers
stalled a little off the surface and tilted, faces turned at a junction, two sheets crossing),
lose one face of each pair where the field shows one sheet between them
(:func:`drop_facing_pairs`).

Twins are matched geometrically (the two layers' triangulations differ): an opposite-facing face
(normals more than about 150 degrees apart: a crease face at a junction is no twin) whose centroid lies within ``TWIN_LATERAL`` voxels of the
face's normal line, on top of it or behind it (up to twice the iso-value: layers that did not
fully meet). A pair that is not coincident is accepted only when the field has no bump between
them: two distinct sheets a little apart (a thin part) have ``d > 0`` midway, the two layers of
one sheet have the sheet between them. Past a voxel apart the pair must also show that its
layers stalled: one stands off the surface, or the field dips between them (the low slab a
sparse or noisy scan gives, whose two sides the layers stop at).
"""

from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np

from ..compiled import kernels as load_kernels
from ..cpu_threads import query_threads
from ..progress import CancelFn, check_cancel
from . import mesh_ops

OPPOSITE_COS = -0.85  # twins' normals are more than about 150 degrees apart
TWIN_LATERAL = 0.8  # voxels from the face's normal line
COINCIDENT = 0.25  # voxels along the normal: closer pairs need no field test
BUMP = 0.25  # a field bump of this share of the pair's distance (or 0.05 voxel) parts two sheets
STANDOFF = 0.3  # ... and, past a voxel apart, one must stand off the surface by this share of it
VALLEY = 0.05  # ... or the field must dip this far (voxels) below both between them
VALLEY_SAMPLES = (0.2, 0.35, 0.65, 0.8)  # where between them, besides the middle, it looks
_NEIGHBOURS = 12


@dataclass
class LayerReport:
    """What the layer choice did.

    twins: faces with a twin; trees: independent choices (pieces of the constraint forest);
    double_pairs: twin pairs that still keep both faces; centred: vertices moved towards the
    middle of a slab their layers stalled across (:func:`_centre_stalled`).
    """

    twins: int
    trees: int
    double_pairs: int
    centred: int = 0


def _candidates(tree, cents, normals, query, probe, k):
    """Opposite-facing faces near ``probe`` points: (face, candidate, depth, lateral) arrays."""
    k = min(k, len(cents))
    _, idx = tree.query(probe, k=k, distance_upper_bound=TWIN_LATERAL + COINCIDENT,
                        workers=query_threads())
    idx = idx.reshape(len(query), k)
    compiled = load_kernels("meshing.mesh_ops_kernels")
    if compiled is not None:
        return compiled.facing_candidates(idx.astype(np.int64), query.astype(np.int64), cents,
                                          normals, OPPOSITE_COS)
    valid = idx < len(cents)
    rows, cols = np.nonzero(valid)
    f, g = query[rows], idx[rows, cols]
    opposite = np.einsum("ij,ij->i", normals[f], normals[g]) < OPPOSITE_COS
    f, g = f[opposite], g[opposite]
    offset = cents[g] - cents[f]
    depth = np.einsum("ij,ij->i", offset, normals[f])  # > 0: g in front of f
    lateral = np.linalg.norm(offset - depth[:, None] * normals[f], axis=1)
    return f, g, depth, lateral


def _one_sheet_between(field, spacing, x_f, x_g):
    """True where two faces apart (voxel coordinates) are the two layers of one sheet.

    The surface lies between the two layers of one sheet: the field has no bump midway (two
    sheets a little apart have ``d > 0`` there). Pairs more than a voxel apart must also show
    that they did not meet: one stands off the surface (at a good part of the gap), or the
    field dips between them below both (``VALLEY``): on a sparse or noisy scan the field stays
    low across a slab a voxel or more thick, its lowest values inside, and both layers stall
    on its two sides. Two converged faces that far apart, with no valley between them, are two
    sheets (a thin part).
    """
    u_f = field.closest(x_f * spacing)[0] / spacing
    u_g = field.closest(x_g * spacing)[0] / spacing
    u_m = field.closest(0.5 * (x_f + x_g) * spacing)[0] / spacing
    gap = np.linalg.norm(x_g - x_f, axis=1)
    high = np.maximum(u_f, u_g)
    no_bump = u_m - high <= np.maximum(BUMP * gap, 0.05)
    one = no_bump & ((gap <= 1.0) | (high >= STANDOFF * gap))
    ask = np.nonzero(no_bump & ~one)[0]
    if len(ask):  # apart, converged: a valley between them, or two sheets?
        low = np.minimum(u_f[ask], u_g[ask])
        dip = u_m[ask] <= low - VALLEY
        for t in VALLEY_SAMPLES:
            inner = (1.0 - t) * x_f[ask] + t * x_g[ask]
            dip |= field.closest(inner * spacing)[0] / spacing <= low - VALLEY
        one[ask] = dip
    return one


def find_twins(cents: np.ndarray, normals: np.ndarray, field, spacing: float,
               max_depth: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Twin pairs of the cover (face indices f < g) and how far apart they are.

    Parameters
    ----------
    cents, normals : (m, 3) face centroids (voxel units) and unit normals.
    field : UDFGrid or None (None: no field test; only coincident pairs are twins).
    spacing : voxel size, world units (to query the field).
    max_depth : voxels; how far behind a face its twin may lie.

    Returns
    -------
    f, g : (P,) int64, ordered by f, then g; gap : (P,) float64 voxels.
    """
    from scipy.spatial import cKDTree

    m = len(cents)
    if m < 2:
        empty = np.zeros(0, np.int64)
        return empty, empty, np.zeros(0)
    tree = cKDTree(cents)
    found_f, found_g, found_gap = [], [], []
    unmatched = np.arange(m)
    depth_probe = 0.0
    while len(unmatched) and depth_probe <= max_depth + 1e-9:
        probe = cents[unmatched] - depth_probe * normals[unmatched]
        f, g, depth, lateral = _candidates(tree, cents, normals, unmatched, probe, _NEIGHBOURS)
        behind = -depth
        near = (lateral < TWIN_LATERAL) & (behind > -COINCIDENT) & (behind < max_depth)
        f, g, behind = f[near], g[near], behind[near]
        test = np.abs(behind) > COINCIDENT
        if field is not None and test.any():
            ok = np.ones(len(f), bool)
            ok[test] = _one_sheet_between(field, spacing, cents[f[test]], cents[g[test]])
            f, g, behind = f[ok], g[ok], behind[ok]
        elif field is None:
            f, g, behind = f[~test], g[~test], behind[~test]
        found_f.append(f)
        found_g.append(g)
        found_gap.append(np.abs(behind))
        matched = np.zeros(m, bool)
        matched[f] = True
        unmatched = unmatched[~matched[unmatched]]
        depth_probe += 1.0
    f = np.concatenate(found_f)
    g = np.concatenate(found_g)
    gap = np.concatenate(found_gap)
    lo, hi = np.minimum(f, g), np.maximum(f, g)
    key = lo * m + hi
    key, first = np.unique(key, return_index=True)
    return lo[first], hi[first], gap[first]


def _is_twin(keys: np.ndarray, twin_keys: np.ndarray) -> np.ndarray:
    """Which of ``keys`` are among ``twin_keys`` (sorted and unique, as :func:`find_twins`
    gives them): a binary search each, no sort of ``keys``."""
    if len(twin_keys) == 0:
        return np.zeros(len(keys), bool)
    at = np.minimum(np.searchsorted(twin_keys, keys), len(twin_keys) - 1)
    return twin_keys[at] == keys


def _parity_forest(m: int, twin_f: np.ndarray, twin_g: np.ndarray, twin_weight: np.ndarray,
                   pairs: np.ndarray, pair_weight: np.ndarray):
    """Minimum spanning forest of the signed graph and each node's parity along it.

    ``twin_f``, ``twin_g``: pairs that get opposite labels (unique, ``f < g``), with weights
    under 0.5; ``pairs`` (P, 2): pairs that get the same label (unique), with weights above 0.5,
    so every twin constraint comes before every shared edge. Where a twin pair also shares an
    edge, the twin constraint stands.

    Returns (parity (m,) bool, tree label (m,) int, tree count).
    """
    from scipy import sparse
    from scipy.sparse.csgraph import breadth_first_order, connected_components
    from scipy.sparse.csgraph import minimum_spanning_tree

    lo, hi = np.minimum(pairs[:, 0], pairs[:, 1]), np.maximum(pairs[:, 0], pairs[:, 1])
    twin = _is_twin(lo.astype(np.int64) * m + hi, twin_f.astype(np.int64) * m + twin_g)
    lo, hi, pair_weight = lo[~twin], hi[~twin], pair_weight[~twin]
    # the sign travels in the weight: opposite constraints weigh under 1.5, the others above
    # (1 is added since the spanning tree reads a weight of 0 as no edge)
    graph = sparse.coo_matrix((np.concatenate([1.0 + twin_weight, 1.0 + pair_weight]),
                               (np.concatenate([twin_f, lo]), np.concatenate([twin_g, hi]))),
                              shape=(m, m)).tocsr()
    forest = minimum_spanning_tree(graph).tocoo()
    count, labels = connected_components(forest, directed=False)
    # a virtual root joined to one face of every tree: one breadth-first search for all
    roots = np.unique(labels, return_index=True)[1]
    rows = np.concatenate([forest.row, np.full(len(roots), m)])
    cols = np.concatenate([forest.col, roots])
    sign = np.concatenate([(forest.data < 1.5).astype(np.int64), np.zeros(len(roots), np.int64)])
    tree = sparse.coo_matrix((sign + 1, (rows, cols)), shape=(m + 1, m + 1)).tocsr()
    tree = tree + tree.T
    order, pred = breadth_first_order(tree, m, directed=False, return_predecessors=True)
    pred = pred[:m].copy()
    flip = np.zeros(m + 1, np.int8)
    child = order[order < m]
    flip[child] = (np.asarray(tree[pred[child], child]).ravel() - 1).astype(np.int8)
    # parity = XOR of the flips on the path to the root, by pointer jumping
    up = np.append(pred, m)
    up[up < 0] = m
    parity = flip.copy()
    while True:
        parent = up[up]
        if np.array_equal(parent, up):
            break
        parity ^= np.where(up < m, parity[up], 0).astype(np.int8)
        up = parent
    parity ^= np.where(up < m, parity[up], 0).astype(np.int8)
    return parity[:m].astype(bool), labels, count


def _broad(mask: np.ndarray, pairs: np.ndarray, m: int, rings: int = 2) -> np.ndarray:
    """The faces of ``mask`` in regions more than ``rings`` faces wide (a morphological opening
    over the faces' edge adjacency): a thin part's untwinned side, not the strip of fold faces
    along a rim."""
    from scipy import sparse

    adj = sparse.coo_matrix((np.ones(2 * len(pairs)), (np.r_[pairs[:, 0], pairs[:, 1]],
                                                       np.r_[pairs[:, 1], pairs[:, 0]])),
                            shape=(m, m)).tocsr()
    core = mask.copy()
    for _ in range(rings):
        core &= (adj @ (~core).astype(np.float64)) == 0
    for _ in range(rings):
        core |= mask & ((adj @ core.astype(np.float64)) > 0)
    return core


def _drop_kept_twins(keep: np.ndarray, twin_f: np.ndarray, twin_g: np.ndarray,
                     pairs: np.ndarray) -> None:
    """Where the forest left both faces of a twin pair kept, drop the one with fewer kept
    neighbours (in place): the pair lies on a seam, and its less attached face is the stray."""
    both = keep[twin_f] & keep[twin_g]
    if not both.any():
        return
    attached = np.bincount(pairs[keep[pairs[:, 1]], 0], minlength=len(keep))
    attached += np.bincount(pairs[keep[pairs[:, 0]], 1], minlength=len(keep))
    f, g = twin_f[both], twin_g[both]
    keep[np.where(attached[f] < attached[g], f, g)] = False


STALLED_GAP = 1.0  # voxels: kept faces whose dropped twin lies farther move halfway to it
CENTRE_SMOOTH = 4  # rounds of averaging those moves over the kept faces' vertices


def _centre_stalled(x: np.ndarray, faces: np.ndarray, keep: np.ndarray, twin_f: np.ndarray,
                    twin_g: np.ndarray, gap: np.ndarray) -> Tuple[np.ndarray, int]:
    """Move the kept layer halfway to the dropped one where the two stalled apart.

    Two layers that stopped more than ``STALLED_GAP`` voxels apart on either side of a low slab
    (a sparse or noisy scan) have the surface between them: the points lie across the slab,
    the field is lowest inside it. Each kept face of such a pair moves along its normal by half
    the depth of its dropped twin; a vertex takes the mean of its kept faces' moves (0 for a face
    with no such twin), averaged ``CENTRE_SMOOTH`` times with its neighbours', so the moved
    region fades into the rest instead of stepping. Voxel units; returns (the moves, the count
    of vertices moved).
    """
    far = gap > STALLED_GAP
    f, g = twin_f[far], twin_g[far]
    one = keep[f] != keep[g]
    kept, dropped = np.where(keep[f], f, g)[one], np.where(keep[f], g, f)[one]
    if len(kept) == 0:
        return None, 0
    normals, _ = mesh_ops.face_normals(x, faces)
    cents = x[faces].mean(axis=1)
    depth = np.einsum("ij,ij->i", cents[dropped] - cents[kept], normals[kept])
    m, n = len(faces), len(x)
    pairs = np.bincount(kept, minlength=m).astype(np.float64)
    face_move = _sum_rows(kept, 0.5 * depth[:, None] * normals[kept], m)
    face_move[pairs > 0] /= pairs[pairs > 0, None]
    corners = mesh_ops.incidence_matrix(n, faces[keep])
    share = np.asarray(corners.sum(axis=1)).ravel()
    move = corners @ face_move[keep]
    move[share > 0] /= share[share > 0, None]
    edges = mesh_ops.edge_topology(faces[keep]).edges
    neighbours = np.bincount(edges.reshape(-1), minlength=n).astype(np.float64)[:, None]
    mean_of_neighbours = mesh_ops.uniform_laplacian(n, edges)
    for _ in range(CENTRE_SMOOTH):  # each vertex and its neighbours, equally weighted
        move = (move + neighbours * (mean_of_neighbours @ move)) / (neighbours + 1.0)
    return move, int((np.abs(move).max(axis=1) > 1e-9).sum())


def choose_layer(start: np.ndarray, vertices: np.ndarray, faces: np.ndarray, spacing: float,
                 field=None, iso: float = 1.0, cancel: Optional[CancelFn] = None,
                 other_side: bool = False):
    """Choose the faces of the optimised cover that make one layer.

    Parameters
    ----------
    start : (n, 3) float64, the cover's vertices before the optimisation (world units).
    vertices : (n, 3) float64, after it; faces : (m, 3) int64.
    spacing : voxel size, world units.
    field : UDFGrid or None, the distance field (tells a thin part from two layers of a sheet).
    iso : the marching-cubes level in voxels (layers that did not meet lie up to 2 iso apart).
    other_side : keep, per tree, the label with the smaller area instead of the larger (a
        tile whose neighbours kept the other side of an open sheet).

    Returns
    -------
    keep : (m,) bool; vertices : (n, 3) float64, world units: the kept layer moved halfway to
    the dropped one where the two stalled apart (:func:`_centre_stalled`); report : LayerReport.
    """
    m = len(faces)
    if m == 0:
        return np.zeros(0, bool), vertices, LayerReport(0, 0, 0)
    x = vertices / spacing
    normals, _ = mesh_ops.face_normals(x, faces)
    _, start_area = mesh_ops.face_normals(start / spacing, faces)
    cents = x[faces].mean(axis=1)
    twin_f, twin_g, gap = find_twins(cents, normals, field, spacing, 2.0 * iso + 0.5)
    check_cancel(cancel)
    pairs, _ = mesh_ops.dual_edges(faces)
    cos = np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]])
    # twins first (closest first), then shared edges from flat (cos 1) to folded (cos -1)
    parity, labels, count = _parity_forest(m, twin_f, twin_g, 0.1 * gap / (1.0 + gap),
                                           pairs, 2.0 - cos)
    check_cancel(cancel)
    area_odd = np.bincount(labels, weights=start_area * parity, minlength=count)
    area_even = np.bincount(labels, weights=start_area * ~parity, minlength=count)
    keep = parity == ((area_odd > area_even) != other_side)[labels]
    _drop_kept_twins(keep, twin_f, twin_g, pairs)
    twinned = np.zeros(m, bool)
    twinned[twin_f] = twinned[twin_g] = True
    keep[_broad(~twinned, pairs, m)] = True  # the only cover of its part (a thin part's side)
    double = keep[twin_f] & keep[twin_g]
    move, centred = _centre_stalled(x, faces, keep, twin_f, twin_g, gap)
    if centred:
        vertices = vertices + move * spacing
    return keep, vertices, LayerReport(int(twinned.sum()), int(count), int(double.sum()),
                                          centred)


FACING_COS = -0.5  # kept faces this far turned against each other read as a double layer
FACING_DISTANCE = 1.0  # voxels between their centroids


def drop_facing_pairs(vertices: np.ndarray, faces: np.ndarray, field, spacing: float):
    """Drop the stray face of every pair of kept faces that face each other on one sheet.

    Twins (normals about 150 degrees apart) are settled by the labelling. What it leaves are
    pairs turned less than that against each other, within ``FACING_DISTANCE`` voxels: both
    layers stalled a little off the surface and tilted, or the faces turned at a junction or
    where two sheets cross. When the field has no bump between the two (they lie on one sheet),
    the face with fewer kept neighbours goes (the field's larger value breaks ties: it stands
    off the surface). Two sheets of a thin part, with the field rising between them, stay.

    Returns (faces, faces dropped).
    """
    from scipy.spatial import cKDTree

    if len(faces) < 2:
        return faces, 0
    x = vertices / spacing
    normals, _ = mesh_ops.face_normals(x, faces)
    cents = x[faces].mean(axis=1)
    k = min(16, len(faces))
    dist, idx = cKDTree(cents).query(cents, k=k, distance_upper_bound=FACING_DISTANCE,
                                     workers=query_threads())
    found = np.isfinite(dist)
    idx = np.where(found, idx, 0)
    cos = np.einsum("ikc,ic->ik", normals[idx], normals)
    f, col = np.nonzero(found & (cos < FACING_COS) & (idx > np.arange(len(faces))[:, None]))
    g = idx[f, col]
    if len(f) == 0:
        return faces, 0
    if field is not None:
        one = _one_sheet_between(field, spacing, cents[f], cents[g])
        f, g = f[one], g[one]
        if len(f) == 0:
            return faces, 0
    pairs, _ = mesh_ops.dual_edges(faces)
    attached = np.bincount(pairs.reshape(-1), minlength=len(faces)).astype(np.float64)
    if field is not None:
        involved = np.unique(np.r_[f, g])
        u, _ = field.closest(cents[involved] * spacing)
        attached[involved] -= np.minimum(u / spacing, 0.5)  # ties: the face off the surface goes
    drop = np.zeros(len(faces), bool)
    drop[np.where(attached[f] < attached[g], f, g)] = True
    return faces[~drop], int(drop.sum())


RIM_PROBE = 2.0  # voxels beyond a rim vertex where the field is asked for the rim
SEAM_PROBE = 3.5  # voxels beyond a boundary vertex where the field is asked if the surface goes on
SEAM_DISTANCE = 0.5  # voxels: a field this low there means it does
CREASE_PROBE = 1.5  # voxels to either side of the rim point where a crease's other face would be
RIM_REACH = 4.0  # voxels along the mesh: the strip behind a boundary vertex that it leads
COHERENT = 0.9  # a strip whose normals, area-weighted, sum to less than this share of its area
#                 is no clean rim (a junction's slot, a Moebius seam): its vertex stays
RIM_FALLOFF = 2.0  # voxels inward (at least; 1.5 times the step) over which a rim step fades
TURN_COS = 0.7  # a rim step may leave a face turned by at most about 45 degrees ...
SLIVER = 0.1  # ... counted when the face's area (voxels^2) times the turn exceeds this
BACKTRACK = 4  # halvings of a step that would turn a face over, before it is dropped
SMOOTH = 2  # rounds of averaging the steps (and their cuts) along the boundary
FILL = 3  # rounds of lending steps to boundary vertices with no direction of their own
RIM_PASSES = 2  # a vertex held back by its neighbours' faces gets a second try

def _opposite_near(x: np.ndarray, faces: np.ndarray, which: np.ndarray) -> np.ndarray:
    """For faces ``which``, True where one and an opposite-facing face within a voxel (centroids)
    are both more than slivers."""
    from scipy.spatial import cKDTree

    normals, area = mesh_ops.face_normals(x, faces)
    cents = x[faces].mean(axis=1)
    k = min(16, len(faces))
    _, idx = cKDTree(cents).query(cents[which], k=k, distance_upper_bound=1.0, workers=query_threads())
    idx = idx.reshape(len(which), k)
    valid = idx < len(faces)
    idx = np.where(valid, idx, 0)
    cos = np.einsum("qkc,qc->qk", normals[idx], normals[which])
    return (valid & (cos < -0.5) & (area[idx] > SLIVER)).any(axis=1) & (area[which] > SLIVER)


def _onto_other_sheet(after: np.ndarray, faces: np.ndarray, moved: np.ndarray) -> np.ndarray:
    """Vertices of ``moved`` whose rim move leaves a face within a voxel of an opposite-facing
    face (two rims of close sheets, a rim over the layer below it, a seam sliding over the
    other sheet): a mask over all vertices (``after``: the moved positions)."""
    is_moved = np.zeros(len(after), bool)
    is_moved[moved] = True
    touched = np.nonzero(is_moved[faces].any(axis=1))[0]
    if len(touched) == 0:
        return is_moved & False
    out = np.zeros(len(after), bool)
    out[faces[touched[_opposite_near(after, faces, touched)]].reshape(-1)] = True
    return out & is_moved


def _sum_rows(index: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """(n, k) sums of the rows of ``values`` (m, k) grouped by ``index`` (m,)."""
    return np.stack([np.bincount(index, weights=values[:, c], minlength=n)
                     for c in range(values.shape[1])], axis=1)


def _unit_rows(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=1), 1e-300)[:, None]


@dataclass
class _Rim:
    """The open boundary and the strips of surface behind it.

    vertices: boundary vertices; links: the boundary's edges, as pairs of rows; out: unit
    outward directions (along the surface, across the boundary); valid: where ``out`` is well
    defined; normal: the strip's mean unit normal per row; strip: for every mesh vertex, the
    row of the boundary vertex nearest along the edges within ``RIM_REACH`` voxels (-1: none);
    coherent: where the strips around face one way (``COHERENT``).
    """

    vertices: np.ndarray
    links: tuple
    out: np.ndarray
    valid: np.ndarray
    normal: np.ndarray
    strip: np.ndarray
    coherent: np.ndarray


def _rim(x: np.ndarray, faces: np.ndarray, topo) -> _Rim:
    """The boundary vertices, their outward directions and the strips behind them.

    Behind a rim the optimisation leaves its last rows of faces crowded into a band a fraction
    of a voxel wide: slivers whose own normals and corners say little. So each boundary vertex
    looks at its *strip*: the vertices nearer to it than to any other boundary vertex, along
    the mesh's edges, within ``RIM_REACH`` voxels (crowded rows are short steps along the edges,
    so the strip reaches past them to faces of full size). Outward is ``t x n``: ``t`` the
    boundary's direction at the vertex (its boundary edges, each run the way its face winds,
    summed with its neighbours' along the boundary: a ragged boundary gives a smooth
    direction), ``n`` the area-weighted normal of the strips of the vertex and its two
    neighbours; it is turned round when it points towards the area-weighted centre of the
    strips two steps along the boundary. A vertex whose boundary edges disagree (a pinch, a
    hairpin) or whose strips do not face one way (``COHERENT``) has no valid direction.
    """
    from scipy import sparse
    from scipy.sparse.csgraph import dijkstra

    n = len(x)
    f, k = np.nonzero(topo.counts[topo.face_edges] == 1)
    a, b = faces[f, k], faces[f, (k + 1) % 3]
    rim, inverse = np.unique(np.r_[a, b], return_inverse=True)
    ia, ib = inverse[:len(a)], inverse[len(a):]
    r = len(rim)

    def along_boundary(values):  # each row plus its neighbours along the boundary
        return values + _sum_rows(ia, values[ib], r) + _sum_rows(ib, values[ia], r)

    along = x[b] - x[a]
    tangent = along_boundary(_sum_rows(ia, along, r) + _sum_rows(ib, along, r))
    length = np.linalg.norm(along, axis=1)[:, None]
    run = along_boundary(_sum_rows(ia, length, r) + _sum_rows(ib, length, r))[:, 0]

    edges = topo.edges
    span = np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1) + 1e-9  # 0 would be no edge
    graph = sparse.csr_matrix((span, (edges[:, 0], edges[:, 1])), shape=(n, n))
    dist, _, nearest = dijkstra(graph, directed=False, indices=rim, limit=RIM_REACH,
                                min_only=True, return_predecessors=True)
    row = np.full(n, -1, np.int64)
    row[rim] = np.arange(r)
    reached = np.isfinite(dist)
    strip = np.full(n, -1, np.int64)
    strip[reached] = row[nearest[reached]]
    # the strip's faces, each counted for the strip of each of its corners
    around = faces[reached[faces].any(axis=1)]
    normals, area = mesh_ops.face_normals(x, around)
    corners = around.reshape(-1)
    owner = strip[corners]
    inside = owner >= 0
    owner = owner[inside]
    weight = np.repeat(area, 3)[inside]
    face_of = np.repeat(np.arange(len(around)), 3)[inside]
    normal = along_boundary(_sum_rows(owner, normals[face_of] * weight[:, None], r))
    total = along_boundary(_sum_rows(owner, weight[:, None], r))[:, 0]
    coherent = np.linalg.norm(normal, axis=1) > COHERENT * total
    # the strips of the vertex and its neighbours two steps along the boundary: where the
    # surface lies seen from the vertex (a strip squeezed between its neighbours' is small)
    centre = along_boundary(along_boundary(_sum_rows(
        owner, np.c_[(x[around].mean(axis=1)[face_of] - x[rim[owner]]) * weight[:, None],
                     weight], r)))
    centre = centre[:, :3] / np.maximum(centre[:, 3:], 1e-300)
    normal = _unit_rows(normal)
    out = np.cross(tangent, normal)
    out *= np.where(np.einsum("ij,ij->i", out, centre) > 0, -1.0, 1.0)[:, None]
    size = np.linalg.norm(out, axis=1)
    # the vertex's boundary edges agree on a direction (not a pinch of two loops or a hairpin)
    valid = (size > 0.25 * run) & coherent
    return _Rim(rim, (ia, ib), out / np.maximum(size, 1e-12)[:, None], valid, normal, strip,
                coherent)


def extend_rims(vertices: np.ndarray, faces: np.ndarray, field, spacing: float):
    """Move the open boundary of the kept mesh out to the surface's rim.

    The cover's fold at a rim is smoothed inward by the optimisation (and a sampled field
    blurs the rim over a voxel), so the kept layer stops a voxel or two short of the rim, its
    last rows of faces crowded together. For each boundary vertex the field is asked at
    ``RIM_PROBE`` voxels beyond it, outward along the surface (:func:`_rim`): from there the
    closest surface point is the rim itself, and the vertex steps out to it when that is
    outward and at most ``RIM_PROBE`` voxels away. The steps are averaged along the boundary
    (``SMOOTH`` rounds), and a vertex with no clear direction of its own between two that step
    borrows theirs. The vertices of its strip follow, less the farther behind it they lie (none
    at ``RIM_FALLOFF`` voxels, or 1.5 times the step): the crowded rows are stretched out in
    order. A vertex does not move where the surface goes on past it: where the field is near
    zero ``SEAM_PROBE`` voxels beyond (a seam, where the layer choice switched), where another
    kept sheet lies just ahead (a junction), where the surface goes on round the rim point
    (a crease: a box's edge), or where its strip is not one coherently facing sheet.

    A step that would turn a face of some size (``SLIVER``) by more than about 45 degrees from
    its strip's normal is halved with its neighbours', up to ``BACKTRACK`` times, then
    dropped; one that leaves a face on an opposite-facing sheet is dropped. ``RIM_PASSES``
    passes give a vertex held back a second try. Slivers a step turned over are removed.

    Returns (new vertices (world units), faces, seam vertex indices).
    """
    none = np.zeros(0, np.int64)
    if len(faces) == 0 or field is None:
        return vertices, faces, none
    topo = mesh_ops.edge_topology(faces)
    if not (topo.counts == 1).any():
        return vertices, faces, none
    x = vertices / spacing
    start = x.copy()
    seams = none
    first = None
    for step in range(RIM_PASSES):
        rim = _rim(x, faces, topo)
        first = first or rim
        probe = x[rim.vertices] + RIM_PROBE * rim.out
        dist, vec = field.closest(probe * spacing)
        target = probe - vec / spacing
        ahead = np.einsum("ij,ij->i", target - x[rim.vertices], rim.out)  # no slide along
        if step == 0:
            seams = rim.vertices[rim.valid & _goes_on(x, faces, rim, target, field, spacing)]
        move = (rim.valid & ~np.isin(rim.vertices, seams) & np.isfinite(dist) & (ahead > 0.05)
                & (ahead < RIM_PROBE))
        if not move.any():
            break
        steps, move = _smooth_steps(rim, np.where(move[:, None], ahead[:, None] * rim.out, 0.0),
                                    move)
        follower, source, weight = _followers(x, rim, steps, move)
        scale = _hold_back(x, faces, rim, steps, follower, source, weight)
        shift = np.zeros_like(x)
        shift[follower] = (weight * scale[source])[:, None] * steps[source]
        length = np.linalg.norm(shift, axis=1)
        moved = np.nonzero(length > 0)[0]
        direction = shift[moved] / length[moved, None]
        x = x + shift
        # back onto the surface across the step (the sheet curves away from a straight step),
        # not along it (near a rim the field's closest points lag behind the rim)
        d, v = field.closest(x[moved] * spacing)
        v /= spacing
        v -= np.einsum("ij,ij->i", v, direction)[:, None] * direction
        near = d / spacing < RIM_PROBE
        x[moved[near]] -= v[near]
    # what a step still turned over is a sliver (larger faces were held back): it goes
    moved = np.nonzero(np.abs(x - start).sum(axis=1) > 0)[0]
    if len(moved):
        which = np.nonzero(np.isin(faces, moved).any(axis=1))[0]
        reference = _strip_normals(first, faces[which])
        normal, _ = mesh_ops.face_normals(x, faces[which])
        faces = np.delete(faces, which[np.einsum("ij,ij->i", normal, reference) < 0], axis=0)
    return x * spacing, faces, seams


def _goes_on(x, faces, rim, target, field, spacing) -> np.ndarray:
    """Per boundary vertex: the surface goes on past it, so it is no rim. Well beyond it (past
    a retracted rim too) the field is near zero (a seam), or another kept sheet lies just ahead
    (a junction), or the surface goes on round the rim point the field gives (a crease)."""
    far, _ = field.closest((x[rim.vertices] + SEAM_PROBE * rim.out) * spacing)
    around = np.minimum(_distance(field, (target + CREASE_PROBE * rim.normal) * spacing),
                        _distance(field, (target - CREASE_PROBE * rim.normal) * spacing))
    return ((far / spacing < SEAM_DISTANCE) | (around / spacing < SEAM_DISTANCE)
            | _sheet_ahead(x, faces, rim.vertices, rim.out))


def _smooth_steps(rim, steps: np.ndarray, move: np.ndarray):
    """Steps averaged along the boundary; a vertex with no direction of its own (a pinch, a
    hairpin of a ragged boundary) on a coherent strip borrows the mean of its two neighbours'
    (``FILL`` rounds). Returns (steps, which vertices step)."""
    ia, ib = rim.links
    r = len(steps)
    free = ~rim.valid & rim.coherent
    for _ in range(FILL):
        have = (np.abs(steps).sum(axis=1) > 0).astype(np.float64)
        total = _sum_rows(ia, np.c_[steps[ib], have[ib]], r) + _sum_rows(
            ib, np.c_[steps[ia], have[ia]], r)
        lend = free & (have == 0) & (total[:, 3] >= 2)
        steps[lend] = total[lend, :3] / total[lend, 3:]
        move = move | lend
    both = move[ia] & move[ib]
    ja, jb = ia[both], ib[both]
    count = 1.0 + np.bincount(ja, minlength=r) + np.bincount(jb, minlength=r)
    for _ in range(SMOOTH):
        steps = (steps + _sum_rows(ja, steps[jb], r) + _sum_rows(jb, steps[ja], r)) / count[:, None]
    return steps, move


def _followers(x: np.ndarray, rim, steps: np.ndarray, move: np.ndarray):
    """The vertices that follow the stepping boundary vertices: those of their strips, by ``1 -
    depth / reach`` of the step, ``depth`` how far behind the boundary vertex they lie across
    the boundary (vertices in one place, crowded rows, move alike; reach: ``RIM_FALLOFF``
    voxels or 1.5 times the step). Returns (vertices, their strip's row, their share)."""
    reach = np.maximum(RIM_FALLOFF, 1.5 * np.linalg.norm(steps, axis=1))
    follower = np.nonzero(rim.strip >= 0)[0]
    source = rim.strip[follower]
    keep = move[source]
    follower, source = follower[keep], source[keep]
    depth = np.einsum("ij,ij->i", x[rim.vertices[source]] - x[follower], rim.out[source])
    weight = 1.0 - np.maximum(depth, 0.0) / reach[source]
    keep = weight > 0
    return follower[keep], source[keep], weight[keep]


def _strip_normals(rim, faces: np.ndarray) -> np.ndarray:
    """Per face, the sum of its corners' strip normals (zero off the strips)."""
    owner = rim.strip[faces]
    return np.where(owner[:, :, None] >= 0, rim.normal[np.maximum(owner, 0)], 0.0).sum(axis=1)


def _hold_back(x, faces, rim, steps, follower, source, weight) -> np.ndarray:
    """How much of its step each strip takes (rows of ``rim``): cut where a face of some size
    would turn by more than about 45 degrees from its strips' normal (halved with the
    neighbours along the boundary, ``BACKTRACK`` times, then zero), and zero where a face
    would end on an opposite-facing sheet."""
    scale = np.ones(len(steps))
    touched = faces[np.isin(faces, follower).any(axis=1)]
    owner = rim.strip[touched]
    reference = _unit_rows(_strip_normals(rim, touched))
    before = np.einsum("ij,ij->i", mesh_ops.face_normals(x, touched)[0], reference)
    ia, ib = rim.links
    checked = False
    for attempt in range(BACKTRACK + 2):
        moved = x.copy()
        moved[follower] += (weight * scale[source])[:, None] * steps[source]
        normal, area = mesh_ops.face_normals(moved, touched)
        after = np.einsum("ij,ij->i", normal, reference)
        # a sliver's normal says nothing: only faces of some size count
        turned = (after < TURN_COS) & (after < before) & (area * (TURN_COS - after) > SLIVER)
        if turned.any():
            culprits = owner[turned].reshape(-1)
            culprits = np.unique(culprits[culprits >= 0])
            scale[culprits] = 0.0 if attempt >= BACKTRACK else 0.5 * scale[culprits]
            for _ in range(SMOOTH):  # the neighbours along the boundary step down too
                low = scale.copy()
                np.minimum.at(low, ia, 0.5 + 0.5 * scale[ib])
                np.minimum.at(low, ib, 0.5 + 0.5 * scale[ia])
                scale = np.minimum(scale, low)
            continue
        if checked:
            break
        harm = _onto_other_sheet(moved, faces, follower)
        scale[np.unique(rim.strip[harm])] = 0.0
        checked = True
    return scale

def _distance(field, points: np.ndarray) -> np.ndarray:
    """The field's distances at world ``points``: trilinear in the grid's node values (the
    closest-point vector field vanishes midway between two sheets; the distances do not)."""
    if field.exact is not None:
        return field.closest(points)[0]
    g = field.world_to_index(points)
    dims = np.array(field.shape)
    cell = np.clip(np.floor(g).astype(np.int64), 0, dims - 2)
    t = np.clip(g - cell, 0.0, 1.0)
    out = np.zeros(len(g))
    for dx, dy, dz in np.ndindex(2, 2, 2):
        node = cell + (dx, dy, dz)
        flat = (node[:, 0] * dims[1] + node[:, 1]) * dims[2] + node[:, 2]
        w = ((t[:, 0] if dx else 1 - t[:, 0]) * (t[:, 1] if dy else 1 - t[:, 1])
             * (t[:, 2] if dz else 1 - t[:, 2]))
        out += w * field.values_at(flat)
    return out


def _sheet_ahead(x: np.ndarray, faces: np.ndarray, rim: np.ndarray, out: np.ndarray):
    """True for boundary vertices with another kept sheet just ahead (a wall that a shelf's edge
    meets): moving them out would push them through it."""
    from scipy.spatial import cKDTree

    tree = cKDTree(x[faces].mean(axis=1))
    hit = np.zeros(len(rim), bool)
    for step in (1.0, 1.5, 2.0):
        d, _ = tree.query(x[rim] + step * out, k=1, distance_upper_bound=0.6, workers=query_threads())
        hit |= np.isfinite(d)
    return hit


PINHOLE_EDGES = 8  # boundary loops this short are holes left by the choice, not rims


def close_pinholes(faces: np.ndarray, max_edges: int = PINHOLE_EDGES, keep_open=None):
    """Close the small holes the layer choice leaves (a face or a few, inside a sheet or notched
    into a rim) with a fan of faces, wound like their neighbours.

    Only simple loops (each vertex on one incoming and one outgoing boundary edge) of at most
    ``max_edges`` edges are closed, and none through a vertex of ``keep_open`` ((n,) bool,
    optional: where the faces given are not all the faces there are). Returns (faces, holes
    closed).
    """
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components

    if len(faces) == 0:
        return faces, 0
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    topo = mesh_ops.edge_topology(faces)
    open_side = topo.counts[topo.face_edges.reshape(-1)] == 1
    edges = directed[open_side]
    if len(edges) == 0:
        return faces, 0
    n = int(faces.max()) + 1
    out_degree = np.bincount(edges[:, 0], minlength=n)
    in_degree = np.bincount(edges[:, 1], minlength=n)
    graph = sparse.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    loop = label[edges[:, 0]]
    size = np.bincount(loop)
    simple = np.ones(len(size), bool)
    bad = (out_degree[edges[:, 0]] != 1) | (in_degree[edges[:, 0]] != 1)
    if keep_open is not None:
        bad |= keep_open[edges[:, 0]]
    simple[loop[bad]] = False
    simple &= ~_whole_rim(faces, np.nonzero(open_side)[0] // 3, loop, size)
    small = np.nonzero(simple & (size <= max_edges) & (size >= 3))[0]
    if len(small) == 0:
        return faces, 0
    following = np.full(n, -1, np.int64)
    following[edges[:, 0]] = edges[:, 1]
    first = {}
    for e, l in zip(edges[:, 0], loop):
        first.setdefault(int(l), int(e))
    added = []
    for l in small:
        ring = [first[int(l)]]
        while len(ring) <= max_edges:
            nxt = int(following[ring[-1]])
            if nxt == ring[0]:
                break
            ring.append(nxt)
        # the loop runs along the neighbours' edges; the patch runs the other way round
        ring = ring[::-1]
        added += [(ring[0], ring[i], ring[i + 1]) for i in range(1, len(ring) - 1)]
    if not added:
        return faces, 0
    return np.concatenate([faces, np.asarray(added, np.int64)]), int(len(small))


def _whole_rim(faces: np.ndarray, edge_face: np.ndarray, loop: np.ndarray, size: np.ndarray):
    """True for the loops that are all the boundary a small piece has: its outer rim, not a hole
    in it. A fan across it would lay a second sheet on the piece (a piece of at most
    PIECE_PER_EDGE faces per rim edge; a closed shell with a pinhole has far more)."""
    _, piece = mesh_ops.vertex_components(int(faces.max()) + 1, faces)
    loop_piece = np.full(len(size), -1, np.int64)
    loop_piece[loop] = piece[edge_face]
    loops_per_piece = np.bincount(loop_piece[size > 0], minlength=piece.max() + 1)
    piece_faces = np.bincount(piece)
    return ((loops_per_piece[loop_piece] == 1)
            & (piece_faces[loop_piece] <= PIECE_PER_EDGE * size))


PIECE_PER_EDGE = 4

LIP_COS = -0.3  # a boundary face turned this far back against its kept neighbour is a lip
LIP_PASSES = 4


def peel_lips(vertices: np.ndarray, faces: np.ndarray, passes: int = LIP_PASSES):
    """Peel the lips off the rims: kept faces of the fold that turn back under the sheet.

    A face on the boundary whose normal is turned back (``cos < LIP_COS``) against a kept face
    it shares an edge with is dropped, ``passes`` times (a lip a few faces deep goes row by
    row). Returns (faces, faces dropped).
    """
    dropped = 0
    for _ in range(passes):
        if len(faces) == 0:
            break
        topo = mesh_ops.edge_topology(faces)
        on_boundary = (topo.counts[topo.face_edges] == 1).any(axis=1)
        pairs, _ = mesh_ops.dual_edges(faces, topo)
        normals, _ = mesh_ops.face_normals(vertices, faces)
        back = np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]]) < LIP_COS
        turned = np.zeros(len(faces), bool)
        turned[pairs[back].reshape(-1)] = True
        lip = turned & on_boundary
        if not lip.any():
            break
        dropped += int(lip.sum())
        faces = faces[~lip]
    return faces, dropped


FLAP_FACES = 20  # edge-connected bits this small hanging off a sheet by a vertex are fold flaps


def drop_flaps(faces: np.ndarray, max_faces: int = FLAP_FACES):
    """Drop the little pieces of the fold that hang off a sheet by a vertex only (bow-ties along
    a rim). A small piece on its own (a small part of the scene) stays.

    Returns (faces, pieces dropped).
    """
    if len(faces) == 0:
        return faces, 0
    pairs, _ = mesh_ops.dual_edges(faces)
    count, label = mesh_ops.face_components(len(faces), pairs)
    size = np.bincount(label, minlength=count)
    small = size[label] <= max_faces
    if not small.any():
        return faces, 0
    # vertices used by the larger pieces
    big_vertex = np.zeros(int(faces.max()) + 1, bool)
    big_vertex[faces[~small].reshape(-1)] = True
    touching = np.zeros(count, bool)
    touching[label[small & big_vertex[faces].any(axis=1)]] = True
    drop = touching[label] & small
    return faces[~drop], int(touching.sum())
