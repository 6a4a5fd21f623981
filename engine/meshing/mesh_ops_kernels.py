"""Compiled mesh operations (numba), when numba is there (see :mod:`engine.compiled`).

:func:`edge_topology` gives what :func:`.mesh_ops.edge_topology` gives, array for array, without
sorting all face sides: the sides are bucketed by their smaller vertex (a counting sort), and each
bucket, a vertex's few edges, is ordered by the larger one. :func:`facing_candidates` gives what
:func:`.layers._candidates` gives after its neighbour search (the pairs that face apart, with
depth and lateral offset), in one pass over the neighbour lists instead of a dozen array passes
over all of them. :func:`vertex_components` gives what :func:`.mesh_ops.vertex_components`
gives, by a union-find over the vertices instead of a sparse graph of the faces' edges, and
:func:`pair_components` the corners' fans of :func:`.mesh_ops.vertex_fans` the same way.
"""

import numba
import numpy as np


@numba.njit(nogil=True, cache=True, inline="always")
def _side(faces, s):
    """Face side ``s`` (``3 * face + corner``): its smaller and larger vertex."""
    f, k = s // 3, s % 3
    a, b = faces[f, k], faces[f, (k + 1) % 3]
    return min(a, b), max(a, b)


@numba.njit(nogil=True, cache=True)
def edge_topology(faces, n):
    """Unique edges (E, 2) sorted (as ``np.unique`` of ``lo * n + hi``), the edge of every face
    side (m * 3,) and how many sides use each edge (E,), for faces (m, 3) int64 over n
    vertices. Beside the outputs it holds two numbers per side (its larger vertex, its place
    in the order): the edges are stored once they are counted."""
    sides = 3 * faces.shape[0]
    start = np.zeros(n + 1, np.int64)
    high = np.empty(sides, np.int64)
    for s in range(sides):
        lo, high[s] = _side(faces, s)
        start[lo + 1] += 1
    for v in range(n):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    order = np.empty(sides, np.int64)
    for s in range(sides):  # by smaller vertex, then by side (stable)
        lo, hi = _side(faces, s)
        order[fill[lo]] = s
        fill[lo] += 1
    inverse = np.empty(sides, np.int64)
    unique = 0
    for v in range(n):
        a, b = start[v], start[v + 1]
        for i in range(a + 1, b):  # insertion sort of the bucket by larger vertex
            s = order[i]
            j = i - 1
            while j >= a and high[order[j]] > high[s]:
                order[j + 1] = order[j]
                j -= 1
            order[j + 1] = s
        previous = -1
        for i in range(a, b):
            s = order[i]
            if high[s] != previous:
                previous = high[s]
                unique += 1
            inverse[s] = unique - 1
    edges = np.empty((unique, 2), np.int64)
    counts = np.zeros(unique, np.int64)
    for s in range(sides):
        e = inverse[s]
        edges[e, 0], edges[e, 1] = _side(faces, s)
        counts[e] += 1
    return edges, inverse, counts


@numba.njit(nogil=True, cache=True, inline="always")
def _apart(normals, f, g, opposite_cos):
    """Whether faces f and g face apart (their normals' cosine below ``opposite_cos``)."""
    return (normals[f, 0] * normals[g, 0] + normals[f, 1] * normals[g, 1]
            + normals[f, 2] * normals[g, 2]) < opposite_cos


@numba.njit(nogil=True, cache=True)
def facing_candidates(neighbours, query, cents, normals, opposite_cos):
    """The pairs (face ``query[i]``, neighbour) of ``neighbours`` (Q, k) (``len(cents)``: none)
    whose normals face apart (cosine below ``opposite_cos``), in row order, with the neighbour's
    depth along the face's normal and its distance from the face's normal line."""
    m = cents.shape[0]
    total = 0
    for i in range(neighbours.shape[0]):
        f = query[i]
        for j in range(neighbours.shape[1]):
            g = neighbours[i, j]
            if g < m and _apart(normals, f, g, opposite_cos):
                total += 1
    face = np.empty(total, np.int64)
    other = np.empty(total, np.int64)
    depth = np.empty(total)
    lateral = np.empty(total)
    p = 0
    for i in range(neighbours.shape[0]):
        f = query[i]
        for j in range(neighbours.shape[1]):
            g = neighbours[i, j]
            if g < m and _apart(normals, f, g, opposite_cos):
                ox = cents[g, 0] - cents[f, 0]
                oy = cents[g, 1] - cents[f, 1]
                oz = cents[g, 2] - cents[f, 2]
                d = ox * normals[f, 0] + oy * normals[f, 1] + oz * normals[f, 2]
                ox -= d * normals[f, 0]
                oy -= d * normals[f, 1]
                oz -= d * normals[f, 2]
                face[p], other[p], depth[p] = f, g, d
                lateral[p] = np.sqrt(ox * ox + oy * oy + oz * oz)
                p += 1
    return face, other, depth, lateral


@numba.njit(nogil=True, cache=True)
def _root(parent, x):
    while parent[x] != x:
        parent[x] = parent[parent[x]]  # path halving
        x = parent[x]
    return x


@numba.njit(nogil=True, cache=True)
def _union_faces(n, faces):
    """Union-find over the vertices of ``faces``: each vertex's parent, a component's root
    being its lowest vertex (a union always keeps the lower root)."""
    parent = np.arange(n)
    for i in range(faces.shape[0]):
        for j in range(2):
            a = _root(parent, faces[i, j])
            b = _root(parent, faces[i, j + 1])
            if a < b:
                parent[b] = a
            elif b < a:
                parent[a] = b
    return parent


@numba.njit(nogil=True, cache=True)
def component_count(n, faces):
    """How many connected components of faces sharing a vertex (no labels: 9 bytes per
    vertex)."""
    parent = _union_faces(n, faces)
    root = np.zeros(n, dtype=np.bool_)
    for i in range(faces.shape[0]):
        root[_root(parent, faces[i, 0])] = True
    return int(root.sum())


@numba.njit(nogil=True, cache=True)
def pair_components(n, a, b):
    """Connected components of ``n`` nodes joined by the pairs ``(a[i], b[i])``: each node's
    label, numbered in the order of each component's lowest node (as scipy's
    ``connected_components`` numbers them)."""
    parent = np.arange(n)
    for i in range(a.shape[0]):
        x = _root(parent, a[i])
        y = _root(parent, b[i])
        if x < y:
            parent[y] = x
        elif y < x:
            parent[x] = y
    # a node's parent is a lower node (or itself, at a root): in ascending order, each parent
    # already holds its component's number when its children are reached
    count = 0
    for v in range(n):
        up = parent[v]
        if up == v:
            parent[v] = count
            count += 1
        else:
            parent[v] = parent[up]
    return parent


@numba.njit(nogil=True, cache=True)
def vertex_components(n, faces):
    """Connected components of faces (m, 3) sharing a vertex among ``n`` vertices: their count
    and each face's label, the components numbered in the order of their lowest vertex (as
    scipy's ``connected_components`` numbers them). A union always keeps the lower root, so a
    component's root is its lowest vertex."""
    parent = _union_faces(n, faces)
    labels = np.empty(faces.shape[0], dtype=np.int64)
    used = np.zeros(n, dtype=np.bool_)
    for i in range(faces.shape[0]):
        labels[i] = _root(parent, faces[i, 0])
        used[labels[i]] = True
    count = 0
    for v in range(n):  # parent now maps each used root to its component's number
        if used[v]:
            parent[v] = count
            count += 1
    for i in range(faces.shape[0]):
        labels[i] = parent[labels[i]]
    return count, labels
