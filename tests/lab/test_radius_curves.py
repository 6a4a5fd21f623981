import json

import numpy as np
import pytest
from scipy.spatial import cKDTree

from engine.sampling import sample_surface
from lab.training.radius_curves import (PATCH_TYPES, RADII, error_curves, main, patch_types,
                                        summarise)


def quad(corners):
    """Two triangles over four corners (in order round the quad)."""
    return np.asarray(corners, dtype=np.float64), np.array([[0, 1, 2], [0, 2, 3]])


def merge(*meshes):
    vertices, faces, offset = [], [], 0
    for v, f in meshes:
        vertices.append(v)
        faces.append(f + offset)
        offset += len(v)
    return np.concatenate(vertices), np.concatenate(faces)


def square(z, half=0.2):
    return quad([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])


def label_of(vertices, faces, queries, points=20_000):
    rng = np.random.default_rng(0)
    cloud, _, _ = sample_surface(vertices, faces, points, rng)
    return patch_types(vertices, faces, queries, cKDTree(cloud), rng, samples=100_000)


def test_patch_types_tell_sheets_creases_sparse_and_smooth_apart():
    queries = np.array([[0.0, 0.0, 0.003], [0.05, -0.03, -0.002]])
    flat = label_of(*square(0.0), queries)
    assert [PATCH_TYPES[t] for t in flat["type"]] == ["smooth", "smooth"]
    # a second sheet 0.008 above: "sheet < 0.012"; 0.03 above: the 0.024-0.048 bin
    near = label_of(*merge(square(0.0), square(0.008)), queries)
    assert [PATCH_TYPES[t] for t in near["type"]] == ["sheet < 0.012"] * 2
    far = label_of(*merge(square(0.0), square(0.03)), queries)
    assert [PATCH_TYPES[t] for t in far["type"]] == ["sheet 0.024-0.048"] * 2
    # a right-angled crease along the y axis: a query at the edge is a crease, one far off not
    crease = merge(quad([[0, -0.2, 0], [0.2, -0.2, 0], [0.2, 0.2, 0], [0, 0.2, 0]]),
                   quad([[0, -0.2, 0], [0, 0.2, 0], [0, 0.2, 0.2], [0, -0.2, 0.2]]))
    edge = label_of(*crease, np.array([[0.003, 0.0, 0.003], [0.1, 0.0, 0.004]]))
    assert [PATCH_TYPES[t] for t in edge["type"]] == ["crease", "smooth"]
    # 300 points over the square: a ball of 0.024 holds about 4 of them
    sparse = label_of(*square(0.0), queries, points=300)
    assert [PATCH_TYPES[t] for t in sparse["type"]] == ["few points", "few points"]


def test_oracle_beats_every_fixed_radius_and_a_starved_ball_is_worse():
    from engine.field import backbone_predictor

    rng = np.random.default_rng(1)
    # a clean plane sampled so that a ball of 0.008 holds about 3-4 points, one of 0.024 about 40
    points = np.column_stack([rng.uniform(-0.2, 0.2, (3600, 2)), np.zeros(3600)])
    queries = np.column_stack([rng.uniform(-0.1, 0.1, (400, 2)), rng.uniform(-0.004, 0.004, 400)])
    radii = (0.008, 0.012, 0.018, 0.024)
    tree = cKDTree(points)
    in_tiny = tree.query_ball_point(queries, 0.008, return_length=True)
    assert 2 <= np.median(in_tiny) <= 5
    errors = error_curves(backbone_predictor("cpu"), tree, points, queries,
                          np.abs(queries[:, 2]), radii)
    result = summarise(errors, radii, local=np.argmin(errors, axis=1))
    assert len(result["curve"]) == len(radii)
    assert result["oracle"] <= min(result["curve"]) + 1e-9
    assert result["local_oracle"] == pytest.approx(result["oracle"])
    assert result["curve"][0] > 1.5 * result["curve"][2]  # 3-4 points: far worse than 15-20
    assert result["best_fixed"] == min(result["curve"])
    assert result["best_fixed_radius"] in radii
    assert 0.0 <= result["oracle_gain"] < 1.0


def test_command_writes_the_curves_per_domain_condition_and_patch_type(tmp_path):
    out = tmp_path / "curves.json"
    main(["--out", str(out), "--shapes", "1", "--queries", "150", "--domains", "cars",
          "--conditions", "sparse", "--radii", "0.008", "0.024", "0.048"])
    result = json.loads(out.read_text())
    assert result["radii"] == [0.008, 0.024, 0.048]
    cars = result["domains"]["cars"]
    assert set(cars) == {"sparse", "all conditions"}
    sparse = cars["sparse"]
    assert sparse["queries"] == 150 and sparse["seeds"] == [1_000_000]
    for key in ("curve", "best_fixed_radius", "best_fixed", "at_0.024", "oracle",
                "local_oracle", "median_64th_point_distance", "by_patch_type"):
        assert key in sparse
    assert sparse["oracle"] <= sparse["local_oracle"] + 1e-9
    assert sparse["oracle"] <= min(sparse["curve"]) + 1e-9
    assert sum(v["queries"] for v in sparse["by_patch_type"].values()) == 150
    assert set(sparse["by_patch_type"]) <= set(PATCH_TYPES)
    assert "sparse" in result["by_patch_type_all_domains"]
    pooled = cars["all conditions"]
    for key in ("oracle", "local_oracle", "type_oracle", "condition_oracle", "density_oracle"):
        assert pooled["oracle"] - 1e-9 <= pooled[key]
    for key in ("type_oracle", "condition_oracle", "density_oracle"):
        assert pooled[key] <= pooled["best_fixed"] + 1e-9  # a radius per group: never worse


def test_default_radii_span_a_few_times_todays_parent_radius():
    assert RADII[0] < 0.012 and RADII[-1] >= 4 * 0.024
    assert {0.018, 0.024} <= set(RADII)
    assert list(RADII) == sorted(RADII)


def test_lookup_table_gives_each_feature_cell_its_own_best_radius():
    from lab.training.radius_lookup import cell_index, fit_table

    rng = np.random.default_rng(2)
    features = rng.random((4000, 3))
    # queries with a first feature above its median are best at radius index 2, the rest at 0
    wants_large = features[:, 0] > np.quantile(features[:, 0], 0.5)  # on a bin edge
    errors = np.where(wants_large[:, None], [3.0, 2.0, 1.0], [1.0, 2.0, 3.0])
    errors = errors + 0.1 * rng.random(errors.shape)
    edges, choice = fit_table(errors, features, bins=4, min_cell=20)
    picked = choice[cell_index(features, edges)]
    assert np.all(picked[wants_large] == 2) and np.all(picked[~wants_large] == 0)
    # a cell with too few fitting queries falls back to the overall best radius
    _, sparse_choice = fit_table(errors[:30], features[:30], bins=4, min_cell=1000)
    assert np.all(sparse_choice == np.argmin(errors[:30].mean(axis=0)))
