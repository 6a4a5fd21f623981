"""The junction join (an experiment outside the mesher) on analytic fields at 64^3."""

from functools import lru_cache

import numpy as np

from engine.meshing import extract_surface, mesh_ops
from engine.metrics import double_layer_share
from lab import analytic as A
from lab.junction_join import join_junctions

H = 1.0 / 64


@lru_cache(maxsize=None)
def meshed(name):
    shape = {"t_junction": A.t_junction(0.3, 0.3), "disk": A.disk((0, 0, 0), 0.3)}[name]
    mesh = extract_surface(A.sample_grid(shape, [-0.5] * 3, [0.5] * 3, 64, exact=False)).mesh
    return mesh.vertices, mesh.faces


def junction_boundary(vertices, faces):
    """Open boundary length within 3 voxels of the T-junction's line (the z axis)."""
    topo = mesh_ops.edge_topology(faces)
    edges = topo.edges[topo.counts == 1]
    middle = (vertices[edges[:, 0]] + vertices[edges[:, 1]]) / 2
    near = np.hypot(middle[:, 0], middle[:, 1]) < 3 * H
    return np.linalg.norm(vertices[edges[near, 0]] - vertices[edges[near, 1]], axis=1).sum()


def test_the_fin_of_a_t_junction_is_joined_to_its_wall():
    v, f = meshed("t_junction")
    assert mesh_ops.vertex_components(len(v), f)[0] == 2  # the slot the mesher leaves
    v2, f2, joined = join_junctions(v, f, H)
    assert joined > 20 and len(f2) > len(f)
    assert mesh_ops.vertex_components(len(v2), f2)[0] == 1
    topo = mesh_ops.edge_topology(f2)
    junction = v2[topo.edges[topo.counts > 2]].mean(axis=1)
    assert len(junction) > 20 and np.hypot(junction[:, 0], junction[:, 1]).max() < 1.5 * H
    assert junction_boundary(v2, f2) < 0.8 * junction_boundary(v, f)
    assert double_layer_share(v2, f2, H) < 0.005
    area = mesh_ops.face_normals(v, f)[1].sum()
    assert abs(mesh_ops.face_normals(v2, f2)[1].sum() / area - 1) < 0.02
    assert np.abs(v2 - v).max() <= 0.5 * H + 1e-12  # the wall's vertices slide half a voxel at most


def test_a_free_rim_is_left_open():
    v, f = meshed("disk")
    v2, f2, joined = join_junctions(v, f, H)
    assert joined == 0 and len(f2) == len(f) and np.array_equal(v2, v)
