"""Vectorised triangle-mesh operations (numpy + scipy.sparse): no trimesh, no open3d.

Conventions: vertices ``X`` (n, 3) float64, faces ``F`` (m, 3) int64; an edge is a sorted vertex
pair; the dual graph joins two faces that share an edge used by exactly two faces.
"""

from dataclasses import dataclass

import numpy as np

from ..compiled import kernels as load_kernels


@dataclass
class EdgeTopology:
    """Edges of a triangle mesh.

    edges: (E, 2) int64 sorted vertex pairs; face_edges: (m, 3) int64, the id of the edge
    (F[:, k], F[:, (k + 1) % 3]); counts: (E,) int64, how many faces use each edge.
    """

    edges: np.ndarray
    face_edges: np.ndarray
    counts: np.ndarray


def edge_topology(faces: np.ndarray) -> EdgeTopology:
    """Unique edges, the edge of every face side, and how many faces use each edge."""
    faces = np.asarray(faces, dtype=np.int64)
    compiled = load_kernels("meshing.mesh_ops_kernels")
    if compiled is not None and faces.size:
        edges, inverse, counts = compiled.edge_topology(np.ascontiguousarray(faces),
                                                        int(faces.max()) + 1)
        return EdgeTopology(edges, inverse.reshape(-1, 3), counts)
    sides = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    sides.sort(axis=1)
    n = int(faces.max()) + 1 if faces.size else 0
    keys = sides[:, 0] * n + sides[:, 1]
    uniq, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    edges = np.stack([uniq // max(n, 1), uniq % max(n, 1)], axis=1)
    return EdgeTopology(edges, inverse.reshape(-1, 3), counts)


def dual_edges(faces: np.ndarray, topo: EdgeTopology = None):
    """Pairs of faces that share an edge used by exactly two faces.

    Returns
    -------
    pairs : (K, 2) int64 face indices; edge_ids : (K,) int64 the shared edge.
    """
    topo = topo or edge_topology(faces)
    side_edge = topo.face_edges.reshape(-1)
    manifold = topo.counts[side_edge] == 2
    sides = np.nonzero(manifold)[0]
    order = np.argsort(side_edge[sides], kind="stable")
    sides = sides[order].reshape(-1, 2)
    return sides // 3, side_edge[sides[:, 0]]


NORMALS_CHUNK = 1 << 18
"""Faces :func:`face_normals` works on at once: its temporaries follow this, not the mesh."""


def face_normals(vertices: np.ndarray, faces: np.ndarray):
    """Unit face normals (m, 3) and face areas (m,), same units as the vertices squared."""
    dtype = np.result_type(vertices.dtype, np.float32)
    normals = np.empty((len(faces), 3), dtype)
    area = np.empty(len(faces), dtype)
    for start in range(0, len(faces), NORMALS_CHUNK):
        part = faces[start:start + NORMALS_CHUNK]
        a, b, c = (vertices[part[:, k]] for k in range(3))
        cross = np.cross(b - a, c - a)
        norm = np.linalg.norm(cross, axis=1)
        normals[start:start + len(part)] = cross / np.maximum(norm, 1e-300)[:, None]
        area[start:start + len(part)] = 0.5 * norm
    return normals, area


def centroid_matrix(n: int, faces: np.ndarray):
    """CSR (m, n) operator with entries 1/3: ``C @ X`` gives the face centroids."""
    from scipy import sparse

    m = faces.shape[0]
    rows = np.repeat(np.arange(m), 3)
    return sparse.csr_matrix((np.full(3 * m, 1.0 / 3.0), (rows, faces.reshape(-1))), shape=(m, n))


def incidence_matrix(n: int, faces: np.ndarray):
    """CSR (n, m) vertex-face incidence (ones): ``A @ face_values`` sums over incident faces."""
    from scipy import sparse

    m = faces.shape[0]
    cols = np.repeat(np.arange(m), 3)
    return sparse.csr_matrix((np.ones(3 * m), (faces.reshape(-1), cols)), shape=(n, m))


def uniform_laplacian(n: int, edges: np.ndarray):
    """Row-stochastic umbrella operator W (CSR n x n): ``(W @ X)_i`` = mean of i's neighbours."""
    from scipy import sparse

    rows = np.concatenate([edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 1], edges[:, 0]])
    deg = np.bincount(rows, minlength=n).astype(np.float64)
    w = 1.0 / np.maximum(deg[rows], 1.0)
    return sparse.csr_matrix((w, (rows, cols)), shape=(n, n))


def face_components(n_faces: int, pairs: np.ndarray):
    """Connected components of the dual graph: (count, labels (m,) int)."""
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components

    graph = sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                              shape=(n_faces, n_faces))
    return connected_components(graph, directed=False)


def vertex_components(n: int, faces: np.ndarray):
    """Connected components of faces sharing a vertex: (count, face labels (m,) int), the
    components numbered in the order of their lowest vertex."""
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components

    compiled = load_kernels("meshing.mesh_ops_kernels")
    if compiled is not None:  # a union-find: 17 bytes per vertex and 8 per face
        faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
        return compiled.vertex_components(n, faces)
    # a sparse graph with int32 indices (it holds about 60 bytes per face)
    faces = np.asarray(faces).reshape(-1, 3)
    index = np.int32 if n < 2 ** 31 else np.int64
    rows = np.concatenate([faces[:, 0], faces[:, 1]]).astype(index, copy=False)
    cols = np.concatenate([faces[:, 1], faces[:, 2]]).astype(index, copy=False)
    graph = sparse.csr_matrix((np.ones(len(rows), bool), (rows, cols)), shape=(n, n))
    del rows, cols
    _, labels = connected_components(graph, directed=False)  # in order of the lowest vertex
    del graph
    used, face_labels = np.unique(labels[faces[:, 0]], return_inverse=True)
    return len(used), face_labels


def component_count(n: int, faces: np.ndarray) -> int:
    """How many connected components of faces sharing a vertex: :func:`vertex_components`'
    count, without its per-face labels (a whole output mesh's pieces, counted in little
    memory)."""
    if not len(faces):
        return 0
    compiled = load_kernels("meshing.mesh_ops_kernels")
    if compiled is not None:
        faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
        return int(compiled.component_count(n, faces))
    return int(vertex_components(n, faces)[0])


def boundary_loops(faces: np.ndarray, topo: EdgeTopology = None) -> int:
    """Number of boundary loops: connected pieces of the edges used by exactly one face."""
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components

    topo = topo or edge_topology(faces)
    bnd = topo.edges[topo.counts == 1]
    if len(bnd) == 0:
        return 0
    verts, inv = np.unique(bnd, return_inverse=True)
    inv = inv.reshape(-1, 2)
    graph = sparse.coo_matrix((np.ones(len(inv)), (inv[:, 0], inv[:, 1])),
                              shape=(len(verts), len(verts)))
    return int(connected_components(graph, directed=False)[0])


def vertex_fans(n: int, faces: np.ndarray, topo: EdgeTopology = None):
    """Label every face corner with its fan: corners of one vertex joined across shared edges.

    Returns
    -------
    labels : (m, 3) int, fan id of each corner; fans_per_vertex : (n,) int (0 when unused).
    A vertex with more than one fan is non-manifold (e.g. a bow-tie).
    """
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components

    m = faces.shape[0]
    topo = topo or edge_topology(faces)
    pairs, _ = dual_edges(faces, topo)
    # corners on both ends of each shared edge: corner ids 3f + k
    f1, f2 = pairs[:, 0], pairs[:, 1]
    rows, cols = [], []
    for k1 in range(3):
        for k2 in range(3):
            same = faces[f1, k1] == faces[f2, k2]
            rows.append((3 * f1 + k1)[same])
            cols.append((3 * f2 + k2)[same])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    compiled = load_kernels("meshing.mesh_ops_kernels")
    if compiled is not None:  # a union-find: the same labels, without a sparse graph
        labels = compiled.pair_components(3 * m, rows.astype(np.int64, copy=False),
                                          cols.astype(np.int64, copy=False))
    else:
        graph = sparse.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(3 * m, 3 * m))
        _, labels = connected_components(graph, directed=False)
    labels = labels.reshape(m, 3)
    fan_vertex = np.zeros(labels.max() + 1 if m else 0, dtype=np.int64)
    fan_vertex[labels.reshape(-1)] = faces.reshape(-1)
    fans = np.bincount(fan_vertex, minlength=n) if m else np.zeros(n, np.int64)
    return labels, fans


def split_nonmanifold_vertices(vertices: np.ndarray, faces: np.ndarray, only=None,
                               compact: bool = True):
    """Give every fan of a non-manifold vertex (a bow-tie) its own copy of the vertex.

    Vertices on an edge shared by more than two faces (a junction where a shelf meets a wall)
    stay joined: the junction is part of the surface. ``only`` (n,) bool: split these vertices
    alone (the others' fans may be incomplete). With ``compact`` False the vertices keep their
    indices, the copies come after them and unused vertices stay.

    Returns new (vertices, faces); manifold meshes come back unchanged (as copies).
    """
    topo = edge_topology(faces)
    labels, fans = vertex_fans(len(vertices), faces, topo)
    junction = np.zeros(len(vertices), bool)
    junction[topo.edges[topo.counts > 2].reshape(-1)] = True
    if only is not None:
        junction |= ~only  # left joined, like a junction
    fans[junction] = 1
    if not np.any(fans > 1):
        return vertices.copy(), faces.copy()
    fan_ids, first = np.unique(labels.reshape(-1), return_index=True)
    fan_vertex = faces.reshape(-1)[first]
    # keep the original index for the first fan of each vertex, append copies for the rest
    order = np.lexsort((fan_ids, fan_vertex))
    is_first = np.ones(len(order), bool)
    is_first[1:] = fan_vertex[order][1:] != fan_vertex[order][:-1]
    new_index = np.empty(len(fan_ids), dtype=np.int64)
    new_index[order[is_first]] = fan_vertex[order][is_first]
    extra = order[~is_first]
    new_index[extra] = len(vertices) + np.arange(len(extra))
    out_vertices = np.concatenate([vertices, vertices[fan_vertex[extra]]])
    at_junction = junction[fan_vertex]
    new_index[at_junction] = fan_vertex[at_junction]
    lookup = np.empty(labels.max() + 1, dtype=np.int64)
    lookup[fan_ids] = new_index
    out_faces = lookup[labels]
    if compact:
        out_vertices, out_faces, _ = remove_unreferenced(out_vertices, out_faces)
    return out_vertices, out_faces


def remove_unreferenced(vertices: np.ndarray, faces: np.ndarray):
    """Drop vertices no face uses; returns (vertices, faces, kept vertex indices)."""
    used = np.unique(faces.reshape(-1))
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[faces], used


def euler_characteristic(faces: np.ndarray) -> int:
    """V - E + F over the vertices that faces use."""
    topo = edge_topology(faces)
    return int(len(np.unique(faces)) - len(topo.edges) + len(faces))


def orientation_consistent(faces: np.ndarray) -> bool:
    """True when no directed edge is used twice (neighbouring faces agree on orientation)."""
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    n = int(faces.max()) + 1
    keys = directed[:, 0] * n + directed[:, 1]
    return len(np.unique(keys)) == len(keys)


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Signed volume enclosed by a closed mesh (positive when normals point outward)."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)
