"""Backbone network: invariances, batch independence, numpy == torch, the weights file."""

import json
import subprocess
import sys

import numpy as np
import pytest
import torch  # a runtime requirement (requirements.txt): never skipped

from engine import backbone as bb
from engine.patches import MAX_POINTS


def random_patches(count, seed, min_points=1):
    """Contract-shaped random patches: real rows inside the unit ball, nearest first."""
    rng = np.random.default_rng(seed)
    rel = np.zeros((count, MAX_POINTS, 3), np.float32)
    mask = np.zeros((count, MAX_POINTS), bool)
    counts = rng.integers(min_points, MAX_POINTS + 1, count)
    for i, n in enumerate(counts):
        p = rng.normal(size=(n, 3))
        p *= (rng.random((n, 1)) ** (1 / 3)) / np.linalg.norm(p, axis=1, keepdims=True)
        p[:, 2] *= rng.uniform(0.05, 1.0)             # flattened, surface-like
        p = p[np.argsort(np.linalg.norm(p, axis=1))]
        rel[i, :n] = p
        mask[i, :n] = True
    return rel, mask


@pytest.fixture(scope="module")
def weights(tmp_path_factory):
    """A randomly initialised (but not trivial) backbone written to a weights file."""
    torch.manual_seed(0)
    model = bb.build_backbone_torch()
    with torch.no_grad():                              # make every path matter
        for p in model.parameters():
            p.add_(0.05 * torch.randn_like(p))
    path = tmp_path_factory.mktemp("bb") / "backbone.npz"
    bb.save_backbone(model, path, {"note": "test"})
    return path


def test_importing_the_engine_module_does_not_import_torch():
    code = "import sys, engine.backbone; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_numpy_matches_torch_and_output_is_nonnegative(weights):
    rel, mask = random_patches(500, 1)
    net_np = bb.load_backbone_numpy(weights)
    net_t = bb.load_backbone_torch(weights)
    with torch.no_grad():
        expect = net_t(torch.from_numpy(rel), torch.from_numpy(mask)).numpy()
    got = net_np.predict(rel, mask)
    assert got.shape == (500,) and got.dtype == np.float32
    np.testing.assert_allclose(got, expect, atol=1e-5, rtol=1e-5)
    assert (got >= 0).all()


def test_permutation_invariance(weights):
    rel, mask = random_patches(200, 2)
    net = bb.load_backbone_numpy(weights)
    rng = np.random.default_rng(3)
    order = np.stack([rng.permutation(MAX_POINTS) for _ in range(len(rel))])
    shuffled_rel = np.take_along_axis(rel, order[..., None], axis=1)
    shuffled_mask = np.take_along_axis(mask, order, axis=1)
    np.testing.assert_allclose(net.predict(shuffled_rel, shuffled_mask), net.predict(rel, mask),
                               atol=1e-5, rtol=1e-5)
    with torch.no_grad():
        t = bb.load_backbone_torch(weights)
        a = t(torch.from_numpy(shuffled_rel), torch.from_numpy(shuffled_mask)).numpy()
        b = t(torch.from_numpy(rel), torch.from_numpy(mask)).numpy()
    np.testing.assert_allclose(a, b, atol=1e-5, rtol=1e-5)


def test_batch_independence(weights):
    rel, mask = random_patches(1001, 4)
    net = bb.load_backbone_numpy(weights)
    alone = net.predict(rel[:1], mask[:1])
    together = net.predict(rel, mask)
    np.testing.assert_allclose(together[:1], alone, atol=1e-5, rtol=1e-5)
    with torch.no_grad():
        t = bb.load_backbone_torch(weights)
        a = t(torch.from_numpy(rel[:1]), torch.from_numpy(mask[:1])).numpy()
        b = t(torch.from_numpy(rel), torch.from_numpy(mask)).numpy()
    np.testing.assert_allclose(b[:1], a, atol=1e-5, rtol=1e-5)


def test_padding_invariance(weights):
    """Extra masked rows (zeros or garbage) change nothing; fewer padded rows neither."""
    rel, mask = random_patches(100, 5, min_points=1)
    net = bb.load_backbone_numpy(weights)
    base = net.predict(rel, mask)
    extra_rel = np.concatenate([rel, np.zeros((100, 16, 3), np.float32)], axis=1)
    extra_mask = np.concatenate([mask, np.zeros((100, 16), bool)], axis=1)
    np.testing.assert_allclose(net.predict(extra_rel, extra_mask), base, atol=1e-5, rtol=1e-5)
    garbage = rel.copy()
    garbage[~mask] = 0.7
    np.testing.assert_allclose(net.predict(garbage, mask), base, atol=1e-5, rtol=1e-5)


def test_degenerate_patches_are_finite(weights):
    """One point, two points, collinear and coincident points, a point at the query."""
    rel = np.zeros((5, MAX_POINTS, 3), np.float32)
    mask = np.zeros((5, MAX_POINTS), bool)
    rel[0, 0] = [0.3, 0, 0]
    rel[1, :2] = [[0.3, 0, 0], [0, 0.5, 0]]
    rel[2, :3] = [[0.1, 0, 0], [0.2, 0, 0], [0.3, 0, 0]]
    rel[3, :4] = [0.2, 0.2, 0.2]
    for i, n in enumerate([1, 2, 3, 4, 1]):
        mask[i, :n] = True
    net_np = bb.load_backbone_numpy(weights)
    got = net_np.predict(rel, mask)
    assert np.isfinite(got).all() and (got >= 0).all()
    with torch.no_grad():
        expect = bb.load_backbone_torch(weights)(torch.from_numpy(rel), torch.from_numpy(mask))
    np.testing.assert_allclose(got, expect.numpy(), atol=1e-5, rtol=1e-5)


def test_weights_file_holds_config_and_float32(weights):
    meta = bb.weights_meta(weights)
    assert meta["config"] == bb.DEFAULT_CONFIG and meta["meta"]["note"] == "test"
    with np.load(weights) as data:
        assert all(data[k].dtype == np.float32 for k in data.files if k != "config_json")
        json.loads(str(data["config_json"]))


def test_budget():
    model = bb.build_backbone_torch()
    assert sum(p.numel() for p in model.parameters()) <= 300_000
    assert bb.macs_per_query(bb.DEFAULT_CONFIG) <= 1_100_000


def test_shipped_weights_beat_the_nearest_point_distance():
    """The shipped backbone on fresh synthetic patches (seed unseen in training)."""
    from lab.training import patch_data as pd
    data = pd.generate_patches(2000, np.random.default_rng(424242))
    net = bb.load_backbone_numpy()
    pred = net.predict(data["rel"], data["mask"])
    with torch.no_grad():
        expect = bb.load_backbone_torch()(torch.from_numpy(data["rel"]), torch.from_numpy(data["mask"]))
    np.testing.assert_allclose(pred, expect.numpy(), atol=1e-5, rtol=1e-5)
    err = np.abs(pred - data["udf"]).mean()
    base = np.abs(pd.nearest_point_baseline(data["rel"], data["mask"]) - data["udf"]).mean()
    assert err < 0.6 * base


def test_fewer_rows_than_max_points(weights):
    """A patch array narrower than 64 (even than the 8 sorted distances) gives the same answer."""
    rel, mask = random_patches(50, 6, min_points=1)
    mask[:, 3:] = False
    rel[:, 3:] = 0
    net = bb.load_backbone_numpy(weights)
    np.testing.assert_allclose(net._forward(rel[:, :3], mask[:, :3]), net.predict(rel, mask),
                               atol=1e-5, rtol=1e-5)
    with torch.no_grad():
        t = bb.load_backbone_torch(weights)
        a = t(torch.from_numpy(rel[:, :3]), torch.from_numpy(mask[:, :3])).numpy()
    np.testing.assert_allclose(a, net.predict(rel, mask), atol=1e-5, rtol=1e-5)


def test_compiled_max_pool_and_forward_pass_equal_numpy_ones(weights, monkeypatch):
    """The compiled pool and per-point steps give numpy's values exactly (NaN included), and the
    networks built with them (numba installed, as the requirements have it) give the same
    bits."""
    from engine.compiled import kernels
    from engine.selector import load_selector_numpy

    compiled = kernels("network_kernels")
    assert compiled is not None
    rng = np.random.default_rng(11)
    for points in (1, 2, 7, 64):
        x = rng.standard_normal((33, points, 64)).astype(np.float32)
        x[3, points // 2, 5] = np.nan
        assert np.array_equal(compiled.max_over_points(x), bb.max_over_points(x),
                              equal_nan=True)
        bias = rng.standard_normal(64).astype(np.float32)
        other = rng.standard_normal(x.shape).astype(np.float32)
        numpy_x, numpy_relu, compiled_relu = x.copy(), np.empty_like(x), np.empty_like(x)
        assert np.array_equal(compiled.bias_pool_relu(x, bias, compiled_relu),
                              bb._bias_pool_relu(numpy_x, bias, numpy_relu), equal_nan=True)
        assert np.array_equal(x, numpy_x, equal_nan=True)
        assert np.array_equal(compiled_relu, numpy_relu, equal_nan=True)
        assert not np.signbit(compiled_relu[compiled_relu == 0]).any()  # +0, as np.maximum
        per_patch = rng.standard_normal((33, 64)).astype(np.float32)
        compiled.add_patch_relu(x, per_patch)
        bb._add_patch_relu(numpy_x, per_patch)
        assert np.array_equal(x, numpy_x, equal_nan=True)
        assert np.array_equal(compiled.bias_residual_pool(x, bias, other),
                              bb._bias_residual_pool(numpy_x, bias, other), equal_nan=True)
        assert np.array_equal(x, numpy_x, equal_nan=True)
    rel, mask = random_patches(300, 12)
    net = bb.load_backbone_numpy(weights)
    radius = load_selector_numpy()
    extra = rng.random((300, radius.p["extra_mean"].shape[-1])).astype(np.float32)
    assert net.max_pool is compiled.max_over_points
    assert net.steps[0] is compiled.bias_pool_relu
    got = net.predict(rel, mask), radius.predict_unit(rel, mask, extra)
    monkeypatch.setenv("UDF_RECON_KERNELS", "numpy")
    numpy_net, numpy_radius = bb.load_backbone_numpy(weights), load_selector_numpy()
    assert numpy_net.max_pool is bb.max_over_points
    assert numpy_net.steps[0] is bb._bias_pool_relu
    assert np.array_equal(got[0], numpy_net.predict(rel, mask))
    assert np.array_equal(got[1], numpy_radius.predict_unit(rel, mask, extra))
