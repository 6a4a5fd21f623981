"""Patches follow the contract: nearest points within r, relative, scaled, sorted, padded."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from engine.patches import gather_patches


def brute_force(points, queries, radii, max_points):
    """The patch contract written the slow, obvious way."""
    rel = np.zeros((len(queries), max_points, 3), np.float32)
    mask = np.zeros((len(queries), max_points), bool)
    for row, (q, r) in enumerate(zip(queries, radii)):
        distance = np.linalg.norm(points - q, axis=1)
        inside = np.flatnonzero(distance <= r)
        nearest = inside[np.argsort(distance[inside], kind="stable")][:max_points]
        rel[row, :len(nearest)] = (points[nearest] - q) / r
        mask[row, :len(nearest)] = True
    return rel, mask


def random_cloud(seed=0, n=3000):
    rng = np.random.default_rng(seed)
    points = rng.uniform(-0.5, 0.5, (n, 3))
    queries = rng.uniform(-0.55, 0.55, (500, 3))
    return points, queries


def test_patches_match_brute_force_gather():
    points, queries = random_cloud()
    radius = 0.12  # ~22 points per ball on average: some full (64 cap reached), some empty
    rel, mask, counts = gather_patches(cKDTree(points), points, queries, radius, 64)
    want_rel, want_mask = brute_force(points, queries, np.full(len(queries), radius), 64)
    assert rel.shape == (500, 64, 3) and rel.dtype == np.float32 and mask.dtype == bool
    np.testing.assert_array_equal(mask, want_mask)
    np.testing.assert_allclose(rel, want_rel, atol=1e-6)
    np.testing.assert_array_equal(counts, want_mask.sum(axis=1))
    assert counts.min() == 0 and counts.max() > 0
    # the real points form a prefix, sorted by distance, inside the unit ball; padding is zero
    assert np.all(mask[:, :-1] >= mask[:, 1:])
    norms = np.linalg.norm(rel, axis=2)
    assert np.all(norms[mask] <= 1.0 + 1e-6)
    assert np.all(np.diff(np.where(mask, norms, 2.0), axis=1)[mask[:, 1:]] >= -1e-6)
    assert np.all(rel[~mask] == 0.0)


def test_cap_keeps_the_nearest_points():
    points, queries = random_cloud(seed=1, n=20000)
    rel, mask, counts = gather_patches(cKDTree(points), points, queries, 0.2, 16)
    want_rel, want_mask = brute_force(points, queries, np.full(len(queries), 0.2), 16)
    assert counts.max() == 16
    np.testing.assert_array_equal(mask, want_mask)
    np.testing.assert_allclose(rel, want_rel, atol=1e-6)


def test_per_query_radii():
    points, queries = random_cloud(seed=2)
    radii = np.random.default_rng(3).uniform(0.03, 0.15, len(queries))
    rel, mask, counts = gather_patches(cKDTree(points), points, queries, radii, 64)
    want_rel, want_mask = brute_force(points, queries, radii, 64)
    np.testing.assert_array_equal(mask, want_mask)
    np.testing.assert_allclose(rel, want_rel, atol=1e-6)


def test_chunks_give_the_same_patches(monkeypatch):
    import engine.patches as patches

    points, queries = random_cloud(seed=4)
    tree = cKDTree(points)
    whole = gather_patches(tree, points, queries, 0.1)
    monkeypatch.setattr(patches, "QUERY_CHUNK", 37)
    chunked = gather_patches(tree, points, queries, 0.1)
    for a, b in zip(whole, chunked):
        np.testing.assert_array_equal(a, b)


def test_patches_cut_from_a_larger_ball_equal_a_direct_gather():
    # the field reads the backbone's patch (64 nearest within r) out of the parent ball's lists
    # (128 nearest within R >= r) instead of a second k-d query: it must be the same patch
    from engine.patches import nearest_within, patches_from_neighbours

    points, queries = random_cloud(seed=5, n=20000)  # dense: many parent lists hit the cap
    tree = cKDTree(points)
    radii = np.random.default_rng(6).uniform(0.05, 0.15, len(queries))
    parent = nearest_within(tree, queries, 0.15, 128)
    assert np.isfinite(parent.distance).all(axis=1).any()  # some lists are full
    cut = patches_from_neighbours(points, queries, parent, radii, 64)
    direct = gather_patches(tree, points, queries, radii, 64)
    assert direct[2].max() == 64
    for a, b in zip(cut, direct):
        np.testing.assert_array_equal(a, b)


def test_short_neighbour_lists_are_refused():
    from engine.patches import nearest_within, patches_from_neighbours

    points, queries = random_cloud(seed=7)
    parent = nearest_within(cKDTree(points), queries, 0.1, 32)
    with pytest.raises(ValueError, match="shorter"):
        patches_from_neighbours(points, queries, parent, 0.1, 64)


def test_full_and_sparse_batches_are_gathered_alike(monkeypatch):
    """Balls that fill their patch take the whole-batch gather, sparse ones the point-by-point
    one; both give what the other would."""
    import engine.patches as patches

    rng = np.random.default_rng(3)
    points = rng.random((3000, 3))
    queries = rng.random((200, 3))
    neighbours = patches.nearest_within(cKDTree(points), queries, 0.2, 32)
    for radius in (0.2, 0.05):  # nearly every slot filled; a few
        monkeypatch.setattr(patches, "DENSE_GATHER_FILL", 0.5)
        chosen = patches.patches_from_neighbours(points, queries, neighbours, radius, 32)
        monkeypatch.setattr(patches, "DENSE_GATHER_FILL", 2.0 if chosen[1].mean() > 0.5 else -1.0)
        other = patches.patches_from_neighbours(points, queries, neighbours, radius, 32)
        for a, b in zip(chosen, other):
            np.testing.assert_array_equal(a, b)
