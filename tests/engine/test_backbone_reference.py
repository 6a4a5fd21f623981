"""The numpy networks against float64 references of their forward passes, on real patches of
the bundled owl: the float32 kernels (float32 geometric features, padding rows copied from the
first point instead of masked, folded biases, split weight matrices, the selector's shortcut
folded into its first layer) change the answers by float32 round-off only.

The references below are the forward passes as first written: every sum masked, every feature in
float64, one weight matrix per layer. Tolerances are in the networks' output units: the
backbone answers UDF / r, so 1e-4 is 1e-4 of the ball radius; the selector answers s in
(0, 1).
"""

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from engine import backbone as bb
from engine import selector as sel
from engine.frame import UnitFrame
from engine.io import read_point_cloud
from engine.patches import gather_patches
from engine.weights_file import read_weights

OWL = Path(__file__).resolve().parents[2] / "examples" / "owl_50k.ply"
TOLERANCE = 1e-4  # of the ball radius (backbone) or of s (selector)


# ----------------------------------------------------------------------------- references

def reference_geometric_features(rel, mask, config):
    """The geometric features in float64, with masked sums and a sort (the module doc)."""
    rel = rel.astype(np.float64)
    m = mask.astype(np.float64)
    dist = np.sqrt(np.sum(rel * rel, axis=2))
    padded = np.where(mask, dist, 1.0)
    k = config["smallest"]
    smallest = np.sort(padded, axis=1)[:, :k]
    if smallest.shape[1] < k:
        smallest = np.concatenate([smallest, np.ones((len(smallest), k - smallest.shape[1]))],
                                  axis=1)
    dmin = smallest[:, 0]
    feats = [smallest[:, j] for j in range(k)]
    for tau in config["softmin_taus"]:
        feats.append(dmin - tau * np.log(np.sum(m * np.exp(-(padded - dmin[:, None]) / tau),
                                                axis=1)))
    count = m.sum(axis=1)
    feats.append(count / 64.0)
    gauss = m * np.exp(-(padded / config["gauss_sigma"]) ** 2)
    for w in (m / count[:, None], gauss / gauss.sum(axis=1, keepdims=True)):
        c = np.einsum("bn,bnk->bk", w, rel)
        d = rel - c[:, None, :]
        cov = np.einsum("bn,bni,bnj->bij", w, d, d)
        trace = np.trace(cov, axis1=1, axis2=2)
        feats.extend([np.linalg.norm(c, axis=1), np.sqrt(trace)])
        for alpha in config["plane_alphas"]:
            eps = alpha * trace + 1e-6
            solved = np.linalg.solve(cov + eps[:, None, None] * np.eye(3), c[:, :, None])[..., 0]
            feats.append(np.sqrt(np.maximum(eps * np.sum(c * solved, axis=1), 0.0)))
    return np.stack(feats, axis=1)


def reference_backbone(params, config, rel, mask):
    """UDF / r of each patch, float64 throughout, padding masked at every pool."""
    p = {k: (v.T if v.ndim == 2 else v).astype(np.float64) for k, v in params.items()}

    def linear(x, name):
        return x @ p[name + ".weight"] + p[name + ".bias"]

    b, n, _ = rel.shape
    hdim, heads = config["hidden"], config["heads"]
    geo = reference_geometric_features(rel, mask, config)
    rel = rel.astype(np.float64)
    x = np.concatenate([rel, np.linalg.norm(rel, axis=2, keepdims=True)], axis=2)
    h1 = linear(np.maximum(linear(x, "enc0"), 0), "enc1")
    pad = np.where(mask, 0.0, -np.inf)[:, :, None]
    g1 = (h1 + pad).max(axis=1)
    t = np.maximum(h1, 0) @ p["enc2a.weight"] + (g1 @ p["enc2b.weight"] + p["enc2b.bias"])[:, None]
    h2 = h1 + linear(np.maximum(t, 0), "enc3")
    m = mask.astype(np.float64)
    pmax = (h2 + pad).max(axis=1)
    pmean = np.einsum("bn,bnc->bc", m, h2) / m.sum(axis=1, keepdims=True)
    pooled = np.concatenate([pmax, pmean, geo], axis=1)
    query = linear(np.maximum(linear(pooled, "query0"), 0), "query1")
    query = query.reshape(b, heads, hdim) / np.sqrt(hdim)
    scores = np.einsum("bhc,bnc->bhn", query, h2) + pad.reshape(b, 1, n)
    scores = np.exp(scores - scores.max(axis=2, keepdims=True))
    scores /= scores.sum(axis=2, keepdims=True)
    ctx = np.einsum("bhn,bnc->bhc", scores, h2).reshape(b, heads * hdim)
    z = np.concatenate([pmax, pmean, ctx, geo], axis=1)
    z = np.maximum(linear(z, "head0"), 0)
    z = np.maximum(linear(z, "head1"), 0)
    return np.logaddexp(linear(z, "head2")[:, 0], 0.0)


def reference_selector(params, config, rel, mask, extra):
    """s of each query, float64 throughout, each block on [x, pooled] built in full."""
    p = {k: (v.T if v.ndim == 2 else v).astype(np.float64) for k, v in params.items()}

    def linear(x, name, bias=True):
        return x @ p[name + ".weight"] + (p[name + ".bias"] if bias else 0.0)

    def block(x, name):
        t = linear(np.maximum(linear(np.maximum(x, 0), name + ".fc0"), 0), name + ".fc1")
        return t + linear(x, name + ".shortcut", bias=False)

    pad = np.where(mask, 0.0, -np.inf)[:, :, None]
    net = block(linear(rel.astype(np.float64), "pos"), "block0")
    for k in range(1, config["blocks"]):
        pooled = (net + pad).max(axis=1)
        net = block(np.concatenate([net, np.broadcast_to(pooled[:, None], net.shape)], axis=2),
                    f"block{k}")
    code = linear(np.maximum((net + pad).max(axis=1), 0), "code")
    z = np.concatenate([code, (extra - p["extra_mean"]) * p["extra_scale"]], axis=1)
    for k in range(len(config["mlp"])):
        z = np.maximum(linear(z, f"mlp{k}"), 0)
    return 1.0 / (1.0 + np.exp(-linear(z, "out")[:, 0]))


# ----------------------------------------------------------------------------- fixtures

@pytest.fixture(scope="module")
def owl():
    cloud = read_point_cloud(OWL)
    points = UnitFrame.from_points(cloud.points).to_unit(cloud.points)
    rng = np.random.default_rng(19)
    queries = (points[rng.choice(len(points), 3000, replace=False)]
               + rng.normal(scale=0.01, size=(3000, 3)))
    return points, cKDTree(points), queries


@pytest.fixture(scope="module")
def owl_patches(owl):
    """Backbone patches of the owl at radii from 0.012 to 0.03 (3 to 64 points)."""
    points, tree, queries = owl
    radii = np.random.default_rng(20).uniform(0.012, 0.03, len(queries))
    rel, mask, counts = gather_patches(tree, points, queries, radii)
    keep = counts >= 3
    return rel[keep], mask[keep]


@pytest.fixture(scope="module")
def shipped_backbone():
    params, header = read_weights(bb.DEFAULT_WEIGHTS)
    return params, header["config"], bb.NumpyBackbone(params, header["config"])


# ----------------------------------------------------------------------------- backbone

def test_float32_geometric_features_match_the_float64_ones(owl_patches, shipped_backbone):
    rel, mask = owl_patches
    config = shipped_backbone[1]
    got = bb.geometric_features_np(rel, mask, config)
    expect = reference_geometric_features(rel, mask, config)
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, expect, atol=1e-5, rtol=0)


def test_backbone_matches_the_float64_reference_on_owl_patches(owl_patches, shipped_backbone):
    rel, mask = owl_patches
    params, config, network = shipped_backbone
    counts = mask.sum(axis=1)
    assert counts.min() < 8 and counts.max() == 64 and len(rel) > 2500
    expect = reference_backbone(params, config, rel, mask)
    got = network.predict(rel, mask)
    assert got.dtype == np.float32
    difference = np.abs(got - expect)
    assert difference.max() <= TOLERANCE, difference.max()
    assert difference.mean() <= 1e-6


def test_backbone_reads_unsorted_rows_and_gapped_masks_as_the_reference(owl_patches,
                                                                        shipped_backbone):
    """Rows in any order, padding anywhere (not only after the points) and garbage in it."""
    rel, mask = owl_patches
    rel, mask = rel[:400].copy(), mask[:400].copy()
    params, config, network = shipped_backbone
    rng = np.random.default_rng(5)
    order = np.stack([rng.permutation(rel.shape[1]) for _ in range(len(rel))])
    rel = np.take_along_axis(rel, order[..., None], axis=1)
    mask = np.take_along_axis(mask, order, axis=1)
    rel[~mask] = rng.uniform(-1, 1, size=(int((~mask).sum()), 3))
    expect = reference_backbone(params, config, rel, mask)
    np.testing.assert_allclose(network.predict(rel, mask), expect, atol=TOLERANCE, rtol=0)


def testmax_over_points_is_the_maximum_for_every_width():
    rng = np.random.default_rng(0)
    for n in range(1, 12):
        x = rng.normal(size=(7, n, 5)).astype(np.float32)
        np.testing.assert_array_equal(bb.max_over_points(x), x.max(axis=1))


# ----------------------------------------------------------------------------- selector

def test_selector_matches_the_float64_reference_on_owl_parent_balls(owl):
    points, tree, queries = owl
    rel, mask, extra = sel.parent_features(tree, points, queries, 0.024)
    has = mask.any(axis=1)
    rel, mask, extra = rel[has], mask[has], extra[has]
    params, header = read_weights(sel.DEFAULT_WEIGHTS)
    network = sel.NumpySelector(params, header["config"])
    expect = reference_selector(params, header["config"], rel, mask, extra)
    got = network.predict_unit(rel, mask, extra)
    assert np.abs(got - expect).max() <= TOLERANCE
    # the threads cut the batches as one thread does: the same answers bit for bit
    np.testing.assert_array_equal(network.predict_unit(rel, mask, extra, threads=2), got)
