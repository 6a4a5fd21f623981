"""The mesher's floor: the truth's distances at the band nodes, and one layer meshed from them."""

import numpy as np

from engine.geometry import Mesh, PointCloud
from engine.meshing import mesh_ops
from engine.metrics import double_layer_share
from lab.bench.truth_udf import make_truth_udf, truth_distances

SQUARE = Mesh(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float64),
              np.array([[0, 1, 2], [0, 2, 3]]))


def test_distances_to_a_square_over_it_and_past_its_rim():
    spacing = 0.02
    rng = np.random.default_rng(0)
    over = np.c_[rng.uniform(0.05, 0.95, (500, 2)), rng.uniform(-0.1, 0.1, 500)]
    past = np.c_[rng.uniform(1.02, 1.1, 500), rng.uniform(0.1, 0.9, 500),
                 rng.uniform(-0.05, 0.05, 500)]
    d = truth_distances(SQUARE, np.r_[over, past], spacing)
    true = np.r_[np.abs(over[:, 2]), np.hypot(past[:, 0] - 1, past[:, 2])]
    assert np.abs(d - true).max() < 0.01 * spacing


def test_a_disk_meshed_from_its_true_distances_is_one_layer_of_its_area():
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    rim = np.c_[0.4 * np.cos(t), 0.4 * np.sin(t), np.zeros_like(t)]
    disk = Mesh(np.r_[[[0.0, 0.0, 0.0]], rim],
                np.c_[np.zeros(64, int), 1 + np.arange(64), 1 + (np.arange(64) + 1) % 64])
    rng = np.random.default_rng(1)
    r, a = 0.4 * np.sqrt(rng.random(20000)), rng.uniform(0, 2 * np.pi, 20000)
    cloud = PointCloud(np.c_[r * np.cos(a), r * np.sin(a), np.zeros_like(r)])
    mesh = make_truth_udf(resolution=64)(cloud, disk)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    area = mesh_ops.face_normals(v, f)[1].sum()
    true_area = mesh_ops.face_normals(disk.vertices, disk.faces)[1].sum()
    assert abs(area / true_area - 1) < 0.03
    assert double_layer_share(v, f, 0.8 / 63) < 0.01
    assert np.abs(v[:, 2]).max() < 0.1 * 0.8 / 63
