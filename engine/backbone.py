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
"""

from pathlib import Path
from typing import Dict, Optional, Union

import numpy as np

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

def _plane_distance_np(rel: np.ndarray, weights: np.ndarray, alphas) -> list:
    """Centroid norm, RMS spread and regularised plane distances for one weighting (float64).

    rel (B, N, 3) float64, weights (B, N) float64 summing to 1 per row (0 on padding).
    """
    c = np.einsum("bn,bnk->bk", weights, rel)
    d = rel - c[:, None, :]
    cov = np.einsum("bn,bni,bnj->bij", weights, d, d)
    trace = cov[:, 0, 0] + cov[:, 1, 1] + cov[:, 2, 2]
    out = [np.sqrt(np.sum(c * c, axis=1)), np.sqrt(trace)]
    for alpha in alphas:
        eps = alpha * trace + 1e-6
        out.append(np.sqrt(np.maximum(eps * _quadratic_inverse(cov, eps, c, np), 0.0)))
    return out


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


def geometric_features_np(rel: np.ndarray, mask: np.ndarray, config: Dict) -> np.ndarray:
    """(B, F) float32 rotation- and order-invariant features of patches (see module doc)."""
    rel64 = rel.astype(np.float64)
    m = mask.astype(np.float64)
    dist = np.sqrt(np.sum(rel64 * rel64, axis=2))
    padded = np.where(mask, dist, 1.0)
    k = config["smallest"]
    smallest = np.sort(padded, axis=1)[:, :k]
    if smallest.shape[1] < k:                     # fewer rows than k: missing distances are 1 (= r)
        smallest = np.concatenate([smallest, np.ones((len(smallest), k - smallest.shape[1]))], axis=1)
    dmin = smallest[:, 0]
    feats = [smallest[:, j] for j in range(k)]
    for tau in config["softmin_taus"]:
        s = np.sum(m * np.exp(-(padded - dmin[:, None]) / tau), axis=1)
        feats.append(dmin - tau * np.log(s))
    count = m.sum(axis=1)
    feats.append(count / 64.0)
    uniform = m / count[:, None]
    gauss = m * np.exp(-(padded / config["gauss_sigma"]) ** 2)
    gauss = gauss / gauss.sum(axis=1, keepdims=True)
    for w in (uniform, gauss):
        feats.extend(_plane_distance_np(rel64, w, config["plane_alphas"]))
    return np.stack(feats, axis=1).astype(np.float32)


# ----------------------------------------------------------------------------- numpy network

class NumpyBackbone:
    """Pure-numpy forward pass of the backbone (float32). ``predict(rel, mask) -> (B,)``."""

    def __init__(self, params: Dict[str, np.ndarray], config: Dict):
        self.config = dict(config)
        # torch Linear stores (out, in); keep (in, out) for x @ W.
        self.p = {k: (np.ascontiguousarray(v.T) if v.ndim == 2 else v).astype(np.float32)
                  for k, v in params.items()}

    def _linear(self, x: np.ndarray, name: str) -> np.ndarray:
        return x @ self.p[name + ".weight"] + self.p[name + ".bias"]

    def _forward(self, rel: np.ndarray, mask: np.ndarray) -> np.ndarray:
        cfg, p = self.config, self.p
        b, n, _ = rel.shape
        hdim, heads = cfg["hidden"], cfg["heads"]
        geo = geometric_features_np(rel, mask, cfg)
        dist = np.sqrt(np.sum(rel * rel, axis=2, keepdims=True))
        x = np.concatenate([rel, dist], axis=2).reshape(b * n, 4)
        t = self._linear(x, "enc0")
        np.maximum(t, 0, out=t)
        h1 = self._linear(t, "enc1")                                   # (b*n, H)
        # 0 on real rows, -inf on padding: added before a max so padding never wins.
        pad = np.where(mask, np.float32(0), np.float32(-np.inf)).reshape(b, n, 1)
        g1 = (h1.reshape(b, n, hdim) + pad).max(axis=1)
        t = np.maximum(h1, 0) @ p["enc2a.weight"]
        t = t.reshape(b, n, hdim)
        t += (g1 @ p["enc2b.weight"] + p["enc2b.bias"])[:, None, :]
        np.maximum(t, 0, out=t)
        h2 = self._linear(t.reshape(b * n, hdim), "enc3")
        h2 += h1
        h2 = h2.reshape(b, n, hdim)
        m = mask.astype(np.float32)
        count = m.sum(axis=1, keepdims=True)
        pmax = (h2 + pad).max(axis=1)
        pmean = np.matmul(m[:, None, :], h2)[:, 0, :] / count
        pooled = np.concatenate([pmax, pmean, geo], axis=1)
        query = self._linear(np.maximum(self._linear(pooled, "query0"), 0), "query1")
        query = query.reshape(b, heads, hdim) * np.float32(1.0 / np.sqrt(hdim))
        scores = np.matmul(query, h2.transpose(0, 2, 1))              # (b, heads, n)
        scores += pad.reshape(b, 1, n)
        scores -= scores.max(axis=2, keepdims=True)
        np.exp(scores, out=scores)
        scores /= scores.sum(axis=2, keepdims=True)
        ctx = np.matmul(scores, h2).reshape(b, heads * hdim)         # (b, heads * H)
        z = np.concatenate([pmax, pmean, ctx, geo], axis=1)
        z = np.maximum(self._linear(z, "head0"), 0)
        z = np.maximum(self._linear(z, "head1"), 0)
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
