"""The scale benchmark's ground truth: cropped and sampled room by room, as the whole floor."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from engine.sampling import face_areas_and_normals, sample_surface
from lab.bench.dataset import crop_to_input
from lab.bench.floor import make_floor, scan_floor
from lab.bench.scale import truth_samples

CROP = 0.3  # metres: coarser than the benchmark's 5 cm, so that the crop's splits stay few
SAMPLES = 20000


@pytest.fixture(scope="module")
def floor():
    mesh, parts = make_floor(2, seed=3)
    cloud, _ = scan_floor(parts, 20000, seed=3)
    return mesh, parts, cloud


def test_room_by_room_samples_are_the_whole_floors_crop(floor, tmp_path):
    mesh, parts, cloud = floor
    points, normals = truth_samples(parts, cloud, tmp_path, np.random.default_rng(0), CROP,
                                    SAMPLES)
    assert points.shape == normals.shape == (SAMPLES, 3)
    assert not list(tmp_path.iterdir())  # the rooms' crops are removed once sampled
    whole = crop_to_input(mesh, cloud, CROP)
    # every sample lies on the whole floor's crop, and that crop is covered as densely
    reference, _, _ = sample_surface(whole.vertices, whole.faces, SAMPLES,
                                     np.random.default_rng(1))
    on_crop = cKDTree(reference).query(points)[0]
    back = cKDTree(points).query(reference)[0]
    spacing = np.sqrt(face_areas_and_normals(whole.vertices, whole.faces)[0].sum() / SAMPLES)
    assert np.median(on_crop) < spacing and np.median(back) < spacing
    assert np.quantile(on_crop, 0.999) < 5 * spacing and np.quantile(back, 0.999) < 5 * spacing
    # shared between the rooms by area: each room's share of the samples is its share of the
    # crop's area
    for mesh_room, _ in parts:
        low, high = mesh_room.vertices.min(axis=0), mesh_room.vertices.max(axis=0)
        inside = np.all((points >= low - 1e-9) & (points <= high + 1e-9), axis=1).mean()
        kept = np.all((whole.vertices >= low - 1e-9) & (whole.vertices <= high + 1e-9), axis=1)
        faces = whole.faces[kept[whole.faces].all(axis=1)]
        share = face_areas_and_normals(whole.vertices, faces)[0].sum() / \
            face_areas_and_normals(whole.vertices, whole.faces)[0].sum()
        assert inside == pytest.approx(share, abs=0.01)
