"""The backbone: a local-patch network that predicts the unsigned distance from a query to the
surface sampled by the points of its patch (LoSF-UDF's idea, our own clean design).

Input (the patch contract of :mod:`engine.patches`): ``rel`` (B, N, 3) float32, the patch points
relative to the query divided by the ball radius r (all inside the unit ball), nearest first,
zero-padded, and ``mask`` (B, N) bool, True on real points (at least one per patch).
Output: (B,) float32, the unsigned distance divided by r (>= 0); multiply by r for world units.

Architecture (every operation is per patch and permutation invariant over the real points;
padded rows never influence the result):

1. Per-point encoder over x_i = [rel_i, |rel_i|] (4 channels):
   h1_i = W1 relu(W0 x_i + b0) + b1;  g1 = max_i h1_i (masked);
   h2_i = h1_i + W3 relu(W2a relu(h1_i) + W2b g1 + b2) + b3   (a ResNet block that sees the
   pooled patch feature, as a ResNet-PointNet does).
2. Pooled features: masked max and mean of h2 (2H).
3. Geometric features (F = 20, invariant to rotations and point order): the 8 smallest point
   distances (padded with 1), soft minima of the distances at 3 temperatures, the point count
   / 64, and for uniform and Gaussian (sigma 0.5) point weights: the weighted centroid's
   norm, the RMS spread and the distance from the query to the weighted least-squares plane
   (line, point) at two regularisations, computed as eps * c^T (C + eps I)^-1 c.
4. Per-sample multi-head attention: a query vector per head from [pooled, geometric] attends
   over the patch's own h2_i with the padding mask (softmax over points, never over the batch).
5. Head MLP on [pooled, attention outputs, geometric] -> Softplus.

Two implementations of the same forward pass read the same weights file (the format of
:mod:`engine.weights_file`): :class:`engine.backbone_torch.UDFBackbone` (torch, for training and
GPU inference) and :class:`NumpyBackbone` (pure numpy, for Blender). This module never imports
torch itself: the torch network is imported when it is asked for.

The numpy pass runs in float32, the geometric features' sums over the points too (their 3 x 3
algebra per patch in float64). It copies each patch's first point into its padding rows, so that
the max pools need no mask (a copy's features equal the point's), folds the first layer's bias
into its product and splits the pooled layers' weights by input block instead of concatenating
inputs. tests/engine/test_backbone_reference.py holds it to a float64 evaluation of the
masked forward pass above within 1e-4 of r on the owl's patches.
"""

from pathlib import Path
from typing import Dict, Optional, Union

import numpy as np

from .compiled import kernels as load_kernels
from .weights_file import read_weights, save_weights

DEFAULT_WEIGHTS = Path(__file__).resolve().parent / "weights" / "backbone.npz"

DEFAULT_CONFIG = {
    "hidden": 64,          # H, per-point feature width
    "heads": 4,            # attention heads (each attends with an H-dim query)
    "head_width": 128,     # width of the head MLP and of the attention-query MLP
    "smallest": 8,         # how many sorted smallest distances enter the geometric features
    "softmin_taus": [0.03, 0.1, 0.3],
    "plane_alphas": [0.02, 0.2],
    "gauss_sigma": 0.5,
}


def geometric_feature_count(config: Dict) -> int:
    return config["smallest"] + len(config["softmin_taus"]) + 1 + 2 * (2 + len(config["plane_alphas"]))


# ----------------------------------------------------------------------------- features (numpy)

def _plane_distance_np(rel_t: np.ndarray, weights: np.ndarray, alphas) -> list:
    """Centroid norm, RMS spread and regularised plane distances, per weighting.

    rel_t (3, B, N) float32 (the patch points by coordinate), weights (W, B, N) float32, each
    row summing to 1 (0 on padding). Returns 2 + len(alphas) arrays of shape (W, B), float64.
    The sums over the points (centroid, covariance) run in float32; the 3 x 3 algebra runs in
    float64 per patch (the regularisation keeps (cov + eps I) within a condition number of
    about 1 / alpha).
    """
    c = np.einsum("kbn,wbn->wkb", rel_t, weights)                      # (W, 3, B)
    d = rel_t[None] - c[..., None]                                     # (W, 3, B, N)
    cov = np.einsum("wibn,wjbn->wbij", d * weights[:, None], d).astype(np.float64)
    c = c.transpose(0, 2, 1).astype(np.float64).reshape(-1, 3)
    cov = cov.reshape(-1, 3, 3)
    shape = weights.shape[:2]
    trace = cov[:, 0, 0] + cov[:, 1, 1] + cov[:, 2, 2]
    out = [np.sqrt(np.sum(c * c, axis=1)), np.sqrt(trace)]
    for alpha in alphas:
        eps = alpha * trace + 1e-6
        out.append(np.sqrt(np.maximum(eps * _quadratic_inverse(cov, eps, c, np), 0.0)))
    return [o.reshape(shape) for o in out]


def _quadratic_inverse(cov, eps, c, xp):
    """c^T (cov + eps I)^-1 c by the adjugate of a symmetric 3x3 matrix (numpy or torch)."""
    a = cov[:, 0, 0] + eps
    e = cov[:, 1, 1] + eps
    i = cov[:, 2, 2] + eps
    b, cc, f = cov[:, 0, 1], cov[:, 0, 2], cov[:, 1, 2]
    A = e * i - f * f
    B = cc * f - b * i
    C = b * f - cc * e
    E = a * i - cc * cc
    F = b * cc - a * f
    I = a * e - b * b
    det = a * A + b * B + cc * C
    x, y, z = c[:, 0], c[:, 1], c[:, 2]
    quad = A * x * x + E * y * y + I * z * z + 2 * (B * x * y + C * x * z + F * y * z)
    return quad / det


def geometric_features_np(rel: np.ndarray, mask: np.ndarray, config: Dict,
                          dist: Optional[np.ndarray] = None) -> np.ndarray:
    """(B, F) float32 rotation- and order-invariant features of patches (see module doc).

    Per-point work in float32, per-patch 3 x 3 algebra in float64 (:func:`_plane_distance_np`);
    within 1e-6 of a float64 evaluation on patches of the contract. ``dist``: the rows' norms
    (B, N) float32 when the caller has them.
    """
    rel = np.asarray(rel, dtype=np.float32)
    mask = np.asarray(mask, dtype=bool)
    m = mask.astype(np.float32)
    if dist is None:
        dist = np.sqrt(np.einsum("bnk,bnk->bn", rel, rel))
    padded = np.where(mask, dist, np.float32(1.0))
    k = config["smallest"]
    if padded.shape[1] > 1 and not np.all(padded[:, 1:] >= padded[:, :-1]):
        padded_sorted = np.sort(padded, axis=1)      # rows not nearest first (the contract's order)
    else:
        padded_sorted = padded
    smallest = padded_sorted[:, :k].astype(np.float64)
    if smallest.shape[1] < k:                     # fewer rows than k: missing distances are 1 (= r)
        smallest = np.concatenate([smallest, np.ones((len(smallest), k - smallest.shape[1]))], axis=1)
    dmin = smallest[:, 0]
    feats = [smallest[:, j] for j in range(k)]
    taus = np.asarray(config["softmin_taus"], dtype=np.float64)
    below = dmin.astype(np.float32)[:, None] - padded                     # <= 0
    scaled = below[None] * (1.0 / taus).astype(np.float32)[:, None, None]   # (T, B, N)
    s = np.einsum("tbn,bn->tb", np.exp(scaled), m).astype(np.float64)
    feats.extend(dmin - taus[:, None] * np.log(s))
    count = m.sum(axis=1)
    feats.append(count.astype(np.float64) / 64.0)
    weights = np.empty((2,) + m.shape, dtype=np.float32)                  # uniform, Gaussian
    np.divide(m, count[:, None], out=weights[0])
    scaled = padded * np.float32(1.0 / config["gauss_sigma"])
    np.exp(-(scaled * scaled), out=weights[1])
    weights[1] *= m
    weights[1] /= weights[1].sum(axis=1, keepdims=True)
    planes = _plane_distance_np(np.ascontiguousarray(rel.transpose(2, 0, 1)), weights,
                                config["plane_alphas"])
    for w in range(2):
        feats.extend(p[w] for p in planes)
    return np.stack(feats, axis=1).astype(np.float32)


def max_over_points(x: np.ndarray) -> np.ndarray:
    """(B, N, C) -> (B, C): the maximum over axis 1, by halving (two halves at a time,
    overlapping by one row when N is odd: max is idempotent). Exact; each step is one
    element-wise maximum over long contiguous runs, where numpy's reduction over a middle axis
    loops row by row. :func:`max_pool` gives the compiled loop instead where it can."""
    while x.shape[1] > 1:
        half = (x.shape[1] + 1) // 2
        x = np.maximum(x[:, :half], x[:, x.shape[1] - half:])
    return x[:, 0]


def max_pool():
    """The max pool over a patch's points for the networks' forward passes: the compiled loop
    (:mod:`.network_kernels`, the same values) where numba is there, else
    :func:`max_over_points`. Call it where the network is built, on the thread that builds it:
    the kernel is loaded there (compiled on a machine's first run), not inside the forward
    passes' threads. The compiled loop takes C-contiguous float32 activations only."""
    return network_steps()[0]


def network_steps():
    """``(max_pool, bias_pool_relu, add_patch_relu, bias_residual_pool)``: the compiled loops of
    :mod:`.network_kernels` where numba is there, else their numpy forms (the same values).
    Called where a network is built, as :func:`max_pool`."""
    compiled = load_kernels("network_kernels")  # compiled (or read from the cache) on import
    if compiled is None:
        return max_over_points, _bias_pool_relu, _add_patch_relu, _bias_residual_pool
    return (compiled.max_over_points, compiled.bias_pool_relu, compiled.add_patch_relu,
            compiled.bias_residual_pool)


def _bias_pool_relu(h: np.ndarray, bias: np.ndarray, relu_out: np.ndarray) -> np.ndarray:
    """``h += bias``; ``relu_out = max(h, 0)``; the max pool of ``h``. (B, N, C) float32; the
    numpy form of :func:`.network_kernels.bias_pool_relu`."""
    h += bias
    np.maximum(h, ZEROS.like(h), out=relu_out)
    return max_over_points(h)


def _add_patch_relu(u: np.ndarray, per_patch: np.ndarray) -> None:
    """``u = max(u + per_patch[:, None, :], 0)`` in place; :func:`.network_kernels.add_patch_relu`
    in numpy."""
    u += per_patch[:, None, :]
    relu_(u)


def _bias_residual_pool(h: np.ndarray, bias: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """``h = h + bias + residual`` in place; the max pool of ``h``;
    :func:`.network_kernels.bias_residual_pool` in numpy."""
    h += bias
    h += residual
    return max_over_points(h)


class _Zeros:
    """A shared read-only buffer of float32 zeros for ReLUs: ``np.maximum(x, 0)`` takes numpy's
    scalar-broadcast loop, which is not vectorised; ``np.maximum(x, zeros)`` with an array of
    x's shape takes the vectorised one (same values)."""

    def __init__(self):
        self.buffer = np.zeros(0, dtype=np.float32)

    def like(self, x: np.ndarray) -> np.ndarray:
        if self.buffer.size < x.size:
            buffer = np.zeros(max(x.size, 2 * self.buffer.size), dtype=np.float32)
            buffer.flags.writeable = False
            self.buffer = buffer
        return self.buffer[:x.size].reshape(x.shape)


ZEROS = _Zeros()


def relu_(x: np.ndarray) -> np.ndarray:
    """max(x, 0) in place on a float32 array; returns x."""
    return np.maximum(x, ZEROS.like(x), out=x)


# ----------------------------------------------------------------------------- numpy network

class NumpyBackbone:
    """Pure-numpy forward pass of the backbone (float32). ``predict(rel, mask) -> (B,)``."""

    def __init__(self, params: Dict[str, np.ndarray], config: Dict):
        self.config = dict(config)
        # torch Linear stores (out, in); keep (in, out) for x @ W.
        self.p = {k: (np.ascontiguousarray(v.T) if v.ndim == 2 else v).astype(np.float32)
                  for k, v in params.items()}
        p, hdim = self.p, self.config["hidden"]
        # the first layer reads [rel, |rel|, 1]: its bias is the weight of the constant input
        self.enc0 = np.ascontiguousarray(np.vstack([p["enc0.weight"], p["enc0.bias"][None]]))
        # the pooled features' layers split by input block (no concatenation per batch)
        q0 = p["query0.weight"]
        self.query0 = (q0[:hdim], q0[hdim:2 * hdim], q0[2 * hdim:])
        h0 = p["head0.weight"]
        ctx = 2 * hdim + self.config["heads"] * hdim
        self.head0 = (h0[:2 * hdim], h0[2 * hdim:ctx], h0[ctx:])
        # the max pool, and the per-point steps after the encoder's products: compiled where
        # numba is there
        self.max_pool, *self.steps = network_steps()

    def _linear(self, x: np.ndarray, name: str) -> np.ndarray:
        y = x @ self.p[name + ".weight"]
        y += self.p[name + ".bias"]
        return y

    def _forward(self, rel: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """UDF / r of (b, n, 3) float32 patches with (b, n) bool masks (one chunk)."""
        cfg, p = self.config, self.p
        rel = np.asarray(rel, dtype=np.float32)
        mask = np.asarray(mask, dtype=bool)
        b, n, _ = rel.shape
        hdim, heads = cfg["hidden"], cfg["heads"]
        # Padding rows become copies of the patch's first point: every per-point feature of a
        # copy equals that point's, so the max pools need no mask (the mean and the attention
        # keep theirs).
        if not mask.all():
            first = rel[np.arange(b), mask.argmax(axis=1)]
            rel = np.where(mask[:, :, None], rel, first[:, None, :])
        x = np.empty((b, n, 5), dtype=np.float32)
        x[..., :3] = rel
        dist = x[..., 3]
        np.sqrt(np.einsum("bnk,bnk->bn", rel, rel), out=dist)
        x[..., 4] = 1.0
        geo = geometric_features_np(rel, mask, cfg, dist)
        bias_pool_relu, add_patch_relu, bias_residual_pool = self.steps
        t = x.reshape(b * n, 5) @ self.enc0                              # enc0 with its bias
        relu_(t)
        h1 = (t @ p["enc1.weight"]).reshape(b, n, hdim)                  # enc1 (bias below)
        g1 = bias_pool_relu(h1, p["enc1.bias"], t.reshape(b, n, hdim))  # t = relu(h1)
        u = (t @ p["enc2a.weight"]).reshape(b, n, hdim)
        add_patch_relu(u, g1 @ p["enc2b.weight"] + p["enc2b.bias"])
        h2 = np.matmul(u.reshape(b * n, hdim), p["enc3.weight"], out=t).reshape(b, n, hdim)
        pmax = bias_residual_pool(h2, p["enc3.bias"], h1)               # h2 += bias + h1
        m = mask.astype(np.float32)
        count = m.sum(axis=1, keepdims=True)
        pmean = np.matmul(m[:, None, :], h2)[:, 0, :] / count
        w = self.query0
        query = pmax @ w[0]
        query += pmean @ w[1]
        query += geo @ w[2]
        query += p["query0.bias"]
        query = self._linear(relu_(query), "query1")
        query = query.reshape(b, heads, hdim)
        query *= np.float32(1.0 / np.sqrt(hdim))
        scores = np.matmul(query, h2.transpose(0, 2, 1))                # (b, heads, n)
        scores += np.where(mask, np.float32(0), np.float32(-np.inf))[:, None, :]
        scores -= scores.max(axis=2, keepdims=True)
        np.exp(scores, out=scores)
        scores /= scores.sum(axis=2, keepdims=True)
        ctx = np.matmul(scores, h2).reshape(b, heads * hdim)           # (b, heads * H)
        w = self.head0
        z = np.concatenate([pmax, pmean], axis=1) @ w[0]
        z += ctx @ w[1]
        z += geo @ w[2]
        z += p["head0.bias"]
        z = relu_(self._linear(relu_(z), "head1"))
        z = self._linear(z, "head2")[:, 0]
        return np.logaddexp(z, np.float32(0)).astype(np.float32)      # softplus

    def predict(self, rel: np.ndarray, mask: np.ndarray, batch_size: int = 256) -> np.ndarray:
        """UDF / r for each patch.

        rel (B, N, 3) float, mask (B, N) bool with at least one True per row -> (B,) float32.
        Processed in chunks of ``batch_size`` patches (each patch independently); columns that
        are padding in every patch of a chunk are skipped (exact, by padding invariance). A
        chunk of 256 patches keeps the per-point activations (256 x N x 64 float32) within a
        core's cache between the layers, where larger chunks stream them through memory.
        """
        rel = np.asarray(rel, dtype=np.float32)
        mask = np.asarray(mask, dtype=bool)
        out = np.empty(rel.shape[0], dtype=np.float32)
        for start in range(0, rel.shape[0], batch_size):
            stop = start + batch_size
            used = mask[start:stop].any(axis=0)
            out[start:stop] = self._forward(rel[start:stop][:, used], mask[start:stop][:, used])
        return out


# ----------------------------------------------------------------------------- torch network

def build_backbone_torch(config: Optional[Dict] = None):
    """A freshly initialised torch :class:`~engine.backbone_torch.UDFBackbone` (for training)."""
    from .backbone_torch import UDFBackbone

    return UDFBackbone(config)


def macs_per_query(config: Dict, points: int = 64) -> int:
    """Multiply-accumulates of one query's forward pass with ``points`` patch rows (layers and
    attention; the geometric features' few hundred operations are left out)."""
    h, w, heads = config["hidden"], config["head_width"], config["heads"]
    f = geometric_feature_count(config)
    per_point = 4 * h + 3 * h * h + 2 * heads * h          # enc0, enc1, enc2a, enc3; scores, ctx
    per_patch = h * h + (2 * h + f) * w + w * heads * h + (2 * h + heads * h + f) * w + w * w + w
    return points * per_point + per_patch


# ----------------------------------------------------------------------------- weights file

save_backbone = save_weights  # the shared weights format of engine/weights_file.py


def load_backbone_numpy(path: Union[str, Path, None] = None) -> NumpyBackbone:
    """The numpy backbone from a weights file (default ``engine/weights/backbone.npz``)."""
    params, header = read_weights(DEFAULT_WEIGHTS if path is None else path)
    return NumpyBackbone(params, header["config"])


def load_backbone_torch(path: Union[str, Path, None] = None, device: str = "cpu"):
    """The torch backbone (eval mode, on ``device``) from the same weights file."""
    import torch

    params, header = read_weights(DEFAULT_WEIGHTS if path is None else path)
    module = build_backbone_torch(header["config"])
    module.load_state_dict({k: torch.from_numpy(v) for k, v in params.items()})
    return module.to(device).eval()


def weights_meta(path: Union[str, Path, None] = None) -> Dict:
    """The config and training metadata stored in a weights file."""
    return read_weights(DEFAULT_WEIGHTS if path is None else path)[1]
