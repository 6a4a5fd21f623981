"""An experiment, not part of the mesher: join a sheet's open edge to the sheet it runs into.

Where one sheet meets another (a shelf on a wall, a fin on a plate, a car's cabin crossing its
body), the kept layer of the first ends a voxel or so short of the second: the double cover
turned round the corner there, and the corner belongs to the layer that was dropped. The mesh
then has a slot along the junction and the two sheets are separate pieces, where the surface
has a non-manifold edge.

:func:`join_junctions` closes the slot. For each boundary vertex whose outward direction along
its sheet (:func:`.layers._rim`) runs into another kept sheet within :data:`JOIN_AHEAD` voxels
(one facing along that direction: not the other side of a thin part), the vertex of that
sheet's face nearest the crossing point is its *target*. Each boundary edge whose two vertices
have targets gets a fan of new faces from its edge down to the path between the targets
(through at most :data:`PATH_EDGES` edges of the other sheet): a strip that carries the sheet
on to the one it meets and shares the path's edges with it (three faces on each: the junction).
The path's vertices slide along their sheet onto the plane of the sheet that meets it (at most
:data:`SLIDE`), so the strip carries that sheet straight on; the new faces are wound as their
sheet's boundary runs. New faces with a face turned against them within a voxel (a strip that
folded over on a ragged boundary) are dropped.

What it does to the first clean test shape of each domain at 256 (``python -m lab.junction_join
garments``, ``cars``): the pieces go from 19 to 2 (garment) and from 138 to 38 (car), CD, F1 and
the double-layered share stay within 0.002 (CD x 10^2, F1) and 0.2 points, but the open boundary
does not shrink: on these ragged boundaries few boundary edges have both vertices' targets a
short, forward path apart, so the strips bridge the slot in places rather than close it. That is
why the mesher does not run it (docs/meshing.md, "Where the open boundary lies").
"""

from collections import deque

import numpy as np

from engine.meshing import mesh_ops

JOIN_AHEAD = 2.0  # voxels: the farthest a sheet ahead of a boundary vertex is joined
JOIN_COS = 0.7  # the sheet ahead faces along the outward direction at least this much
CROSS_REACH = 1.0  # voxels: the crossing point lies this close to the face's centroid
PATH_EDGES = 3  # targets of a boundary edge's two vertices at most this many edges apart
FACING_COS = -0.5  # a new face with a face this far turned against it nearby is dropped
SLIDE = 0.5  # voxels, and share of its shortest edge: the farthest a path vertex slides


def join_junctions(vertices: np.ndarray, faces: np.ndarray, spacing: float):
    """Faces with the slots along junctions closed (see the module docstring).

    Parameters
    ----------
    vertices : (n, 3) float64, world units; faces : (m, 3) int64.
    spacing : voxel size, world units.

    Returns
    -------
    vertices : (n, 3) float64, world units, the paths' vertices slid onto the junction;
    faces : (m + k, 3) int64, the given faces then the new ones; joined : boundary edges joined.
    """
    from scipy.spatial import cKDTree

    from engine.meshing.layers import _rim

    faces = np.asarray(faces, dtype=np.int64)
    topo = mesh_ops.edge_topology(faces)
    if len(faces) < 2 or not (topo.counts == 1).any():
        return vertices, faces, 0
    x = vertices / spacing
    rim = _rim(x, faces, topo)
    normals, _ = mesh_ops.face_normals(x, faces)
    cents = x[faces].mean(axis=1)
    target = _targets(x, faces, normals, cents, cKDTree(cents), rim)
    f, k = np.nonzero(topo.counts[topo.face_edges] == 1)
    a, b = faces[f, k], faces[f, (k + 1) % 3]  # each boundary edge as its face runs it
    both = (target[a] >= 0) & (target[b] >= 0)
    if not both.any():
        return vertices, faces, 0
    adjacency = mesh_ops.uniform_laplacian(len(x), topo.edges)  # its pattern: the neighbours
    neighbours = adjacency.indptr, adjacency.indices
    row = np.full(len(x), -1, np.int64)
    row[rim.vertices] = np.arange(len(rim.vertices))
    new, firsts, paths = [], [], []
    for va, vb in zip(a[both], b[both]):
        path = _path(neighbours, target[va], target[vb])
        if path is None or va in path or vb in path:
            continue
        steps = np.diff(x[path], axis=0) @ (x[vb] - x[va])
        if (steps < 0).any():  # the path turns back: its fan would fold over itself
            continue
        firsts.append(len(new))
        new.append((vb, va, path[0]))
        new.extend((vb, path[i], path[i + 1]) for i in range(len(path) - 1))
        paths.append((va, vb, path))
    if not new:
        return vertices, faces, 0
    added = np.asarray(new, dtype=np.int64)
    moved = _onto_junction(x, faces, normals, rim.normal[row[[p[0] for p in paths]]], paths)
    kept = ~_facing_others(moved, faces, added)
    joined = int(kept[firsts].sum())  # the boundary edge's own new face stayed
    return moved * spacing, np.concatenate([faces, added[kept]]), joined


def _facing_others(x, faces, added) -> np.ndarray:
    """New faces with a face turned against them (``cos < FACING_COS``) within a voxel: a strip
    that folded over, or lies along the sheet it was meant to meet."""
    from scipy.spatial import cKDTree

    every = np.concatenate([faces, added])
    normals, _ = mesh_ops.face_normals(x, every)
    cents = x[every].mean(axis=1)
    first = len(faces)
    near = cKDTree(cents).query_ball_point(cents[first:], 1.0)
    bad = np.zeros(len(added), bool)
    for i, others in enumerate(near):
        others = np.asarray(others, dtype=np.int64)
        bad[i] = (normals[others] @ normals[first + i] < FACING_COS).any()
    return bad


def _onto_junction(x, faces, normals, sheet_normal, paths) -> np.ndarray:
    """The paths' vertices moved along their own sheet onto the plane of the sheet that runs
    into it (through its boundary vertices, ``sheet_normal`` per path), so that the new faces
    carry that sheet straight on; at most ``SLIDE`` of a voxel and of their shortest edge."""
    n = len(x)
    own = np.zeros((n, 3))
    np.add.at(own, faces.reshape(-1), np.repeat(normals, 3, axis=0))
    own /= np.maximum(np.linalg.norm(own, axis=1), 1e-12)[:, None]
    move = np.zeros((n, 3))
    count = np.zeros(n)
    for (va, vb, path), normal in zip(paths, sheet_normal):
        centre = 0.5 * (x[va] + x[vb])
        for w in path:
            across = normal - (normal @ own[w]) * own[w]  # in the path's own sheet
            along = across @ normal
            if along < 0.5:
                continue
            move[w] -= ((x[w] - centre) @ normal / along) * across
            count[w] += 1
    touched = count > 0
    move[touched] /= count[touched, None]
    edges = mesh_ops.edge_topology(faces).edges
    length = np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1)
    shortest = np.full(n, np.inf)
    np.minimum.at(shortest, edges[:, 0], length)
    np.minimum.at(shortest, edges[:, 1], length)
    size = np.linalg.norm(move, axis=1)
    limit = np.minimum(SLIDE, SLIDE * shortest)
    move *= np.minimum(1.0, limit / np.maximum(size, 1e-12))[:, None]
    return x + move


def _targets(x, faces, normals, cents, tree, rim) -> np.ndarray:
    """Per mesh vertex, the vertex of the sheet ahead that it joins (-1: none)."""
    target = np.full(len(x), -1, np.int64)
    rows = np.nonzero(rim.valid)[0]
    if not len(rows):
        return target
    start, out = x[rim.vertices[rows]], rim.out[rows]
    best = np.full(len(rows), np.inf)
    hit = np.full(len(rows), -1, np.int64)
    for step in np.arange(0.5, JOIN_AHEAD + 0.5, 0.5):
        near = tree.query_ball_point(start + step * out, CROSS_REACH + 0.5)
        for i, candidates in enumerate(near):
            if not candidates:
                continue
            g = np.asarray(candidates, dtype=np.int64)
            facing = np.einsum("ij,j->i", normals[g], out[i])
            g, facing = g[np.abs(facing) > JOIN_COS], facing[np.abs(facing) > JOIN_COS]
            if not len(g):
                continue
            # where the outward ray crosses each face's plane, and how close to its centroid
            t = np.einsum("ij,ij->i", cents[g] - start[i], normals[g]) / facing
            cross = start[i] + t[:, None] * out[i]
            off = np.linalg.norm(cross - cents[g], axis=1)
            ok = (t > 0) & (t <= JOIN_AHEAD) & (off < CROSS_REACH) & (t < best[i])
            ok &= ~(faces[g] == rim.vertices[rows[i]]).any(axis=1)
            if ok.any():
                j = np.argmin(np.where(ok, t, np.inf))
                best[i], hit[i] = t[j], g[j]
    found = hit >= 0
    rows, hit, best = rows[found], hit[found], best[found]
    cross = x[rim.vertices[rows]] + best[:, None] * rim.out[rows]
    corners = faces[hit]
    nearest = np.argmin(np.linalg.norm(x[corners] - cross[:, None], axis=2), axis=1)
    target[rim.vertices[rows]] = corners[np.arange(len(rows)), nearest]
    return target


def _path(neighbours, source: int, goal: int):
    """The vertices of a shortest path from ``source`` to ``goal`` along the edges, at most
    ``PATH_EDGES`` edges long (lowest vertex first on ties), or None."""
    if source == goal:
        return [source]
    pointers, indices = neighbours
    previous = {source: -1}
    queue = deque([(source, 0)])
    while queue:
        vertex, depth = queue.popleft()
        if depth == PATH_EDGES:
            continue
        for other in np.sort(indices[pointers[vertex]:pointers[vertex + 1]]):
            other = int(other)
            if other in previous:
                continue
            previous[other] = vertex
            if other == goal:
                path = [goal]
                while previous[path[-1]] != -1:
                    path.append(previous[path[-1]])
                return path[::-1]
            queue.append((other, depth + 1))
    return None


def main():
    from lab.experiment import report, reconstructed_test_shape

    truth, mesh, spacing = reconstructed_test_shape("The junction join on a benchmark test shape.")
    vertices, faces, joined = join_junctions(mesh.vertices, mesh.faces, spacing)
    print(f"{joined} boundary edges joined")
    report("mesh", mesh.vertices, mesh.faces, truth, spacing)
    report("joined", vertices, faces, truth, spacing)


if __name__ == "__main__":
    main()
