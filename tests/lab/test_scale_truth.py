"""The scale benchmark's ground truth, cropped and sampled room by room as the whole floor, and
its score: exact point-to-triangle distances, so a perfect mesh scores perfectly."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from engine.sampling import face_areas_and_normals, sample_surface
from lab.bench.dataset import crop_to_input
from lab.bench.floor import make_floor, scan_floor
from lab.bench import scale
from lab.bench.scale import room_crop_path, truth_samples
from lab.bench.surface_distance import closest_on_mesh

CROP = 0.3  # metres: coarser than the benchmark's 5 cm, so that the crop's splits stay few
SAMPLES = 20000


@pytest.fixture(scope="module")
def floor():
    mesh, parts = make_floor(2, seed=3)
    cloud, _ = scan_floor(parts, 20000, seed=3)
    return mesh, parts, cloud


def test_room_by_room_samples_are_the_whole_floors_crop(floor, tmp_path):
    mesh, parts, cloud = floor
    points, normals, rooms = truth_samples(parts, cloud, tmp_path, np.random.default_rng(0),
                                           CROP, SAMPLES)
    assert points.shape == normals.shape == (SAMPLES, 3) and rooms.shape == (SAMPLES,)
    # each room's crop stays in the folder for the score
    assert sorted(tmp_path.iterdir()) == [room_crop_path(tmp_path, n) for n in range(len(parts))]
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
    for number, (mesh_room, _) in enumerate(parts):
        low, high = mesh_room.vertices.min(axis=0), mesh_room.vertices.max(axis=0)
        inside = np.all((points >= low - 1e-9) & (points <= high + 1e-9), axis=1)
        assert np.all(inside == (rooms == number))
        inside = inside.mean()
        kept = np.all((whole.vertices >= low - 1e-9) & (whole.vertices <= high + 1e-9), axis=1)
        faces = whole.faces[kept[whole.faces].all(axis=1)]
        share = face_areas_and_normals(whole.vertices, faces)[0].sum() / \
            face_areas_and_normals(whole.vertices, whole.faces)[0].sum()
        assert inside == pytest.approx(share, abs=0.01)


def test_closest_on_mesh_is_exact_far_from_the_origin():
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float) + 40.0
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    queries = np.array([[40.5, 40.5, 40.003], [42.0, 40.5, 40.0], [40.25, 40.75, 39.9999]])
    distances, normals = closest_on_mesh(queries, square, faces)
    assert distances == pytest.approx([0.003, 1.0, 0.0001], abs=1e-6)
    assert np.allclose(np.abs(normals[:, 2]), 1.0)
    empty, _ = closest_on_mesh(queries, square, np.zeros((0, 3), int))
    assert np.all(np.isinf(empty))


def test_closest_on_mesh_gives_a_sliver_its_own_normal():
    # a sliver 10 m out whose apex is 1e-8 m off its base: collinear in float32, not in float64
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0],
                         [10, 10, 0], [11, 10, 0], [10.5, 10 + 1e-8, 0]], float)
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    queries = np.array([[10.5, 10.0, 0.5], [10.2, 10.0, -0.3], [0.2, 0.2, 0.1]])
    distances, normals = closest_on_mesh(queries, vertices, faces)
    assert distances == pytest.approx([0.5, 0.3, 0.1], abs=1e-6)
    assert np.all(np.isfinite(normals))
    assert np.allclose(np.abs(normals[:, 2]), 1.0)


def _crops(folder, rooms):
    vertices, faces, offset = [], [], 0
    for number in range(rooms):
        room = np.load(room_crop_path(folder, number))
        vertices.append(room["vertices"])
        faces.append(room["faces"] + offset)
        offset += len(room["vertices"])
    return np.concatenate(vertices), np.concatenate(faces)


def test_score_reads_the_mesh_not_the_sampling(floor, tmp_path, monkeypatch):
    """The truth's own crop scores perfectly, however sparse the truth's samples (nearest
    samples would read their spacing); a mesh lifted by 7 mm fails F1 at 5 mm on the floors and
    ceilings and keeps it on the walls; a mesh missing a room loses that room's completeness."""
    _, parts, cloud = floor
    monkeypatch.setattr(scale, "SAMPLES", SAMPLES)
    points, normals, rooms = truth_samples(parts, cloud, tmp_path, np.random.default_rng(0),
                                           CROP, 2000)
    truth = {"points": points, "normals": normals, "room": rooms}
    vertices, faces = _crops(tmp_path, len(parts))

    perfect = scale.score(vertices, faces, tmp_path, truth)
    assert perfect["cd_cm"] < 1e-3 and perfect["nc"] > 0.999
    assert perfect["f1_0.5cm"] == perfect["f1_1cm"] == 1.0

    lifted = scale.score(vertices + [0.0, 0.0, 0.007], faces, tmp_path, truth)
    assert 0.5 < lifted["f1_0.5cm"] < 0.95 and lifted["f1_1cm"] > 0.99
    assert 0.1 < lifted["cd_cm"] < 0.7

    first = np.load(room_crop_path(tmp_path, 0))
    alone = scale.score(first["vertices"], first["faces"], tmp_path, truth)
    recall = np.mean(rooms == 0)
    assert alone["f1_1cm"] == pytest.approx(2 * recall / (1 + recall), abs=0.01)
