"""Rim smoothing (an experiment outside the mesher) on an analytic disk."""

import numpy as np

from engine.meshing import extract_surface, mesh_ops
from lab import analytic as A
from lab.rim_smoothing import smooth_rims

H = 1.0 / 64


def boundary_length(vertices, faces):
    topo = mesh_ops.edge_topology(faces)
    edges = topo.edges[topo.counts == 1]
    return np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1).sum()


def test_the_ragged_rim_of_a_disk_comes_close_to_its_circle_on_its_plane():
    mesh = extract_surface(A.sample_grid(A.disk((0, 0, 0), 0.3), [-0.5] * 3, [0.5] * 3, 64,
                                         exact=False)).mesh
    v, f = mesh.vertices, mesh.faces
    circle = 2 * np.pi * 0.3
    assert boundary_length(v, f) > 1.15 * circle  # the mesher's rim zigzags
    smoothed = smooth_rims(v, f)
    assert boundary_length(smoothed, f) < 1.08 * circle
    assert np.abs(smoothed[:, 2] - v[:, 2]).max() < 0.05 * H  # along the plane
    far = np.linalg.norm(v[:, :2], axis=1) < 0.3 - 3 * H
    assert np.array_equal(smoothed[far], v[far])  # the inside stays
    before, _ = mesh_ops.face_normals(v, f)
    after, area = mesh_ops.face_normals(smoothed, f)
    turned = np.einsum("ij,ij->i", before, after) <= 0
    assert area[turned].sum() < 1e-4 * area.sum()  # at most a few slivers turn over


def test_a_closed_mesh_is_left_alone():
    mesh = extract_surface(A.sample_grid(A.sphere((0, 0, 0), 0.3), [-0.5] * 3, [0.5] * 3, 32,
                                         exact=False)).mesh
    assert np.array_equal(smooth_rims(mesh.vertices, mesh.faces), mesh.vertices)
