"""The radius selector: predicts each query's ball radius from its parent patch (the paper's
learned radius).

Input per query: the (up to) PARENT_POINTS nearest input points within the parent radius R,
as ``rel = (p - q) / R`` (the patch contract of :mod:`engine.patches`). Features:

- a masked ResNet-PointNet over every STRIDE-th of those points (nearest first, so the stride
  keeps the radial spread of the whole ball while bounding cost) -> a 256-d code;
- log(1 + N) with N the points in the parent ball (saturating at PARENT_POINTS);
- a 6-bin radial density histogram: the share of the ball's points in each shell of width R/6;
- the patch's roughness (:mod:`engine.patch_roughness`: thickness across its plane, the
  residual of a fitted quadric and how well its heights split into two sheets), which tells
  noisy patches from clean ones and a second sheet from noise, over the strided
  patch and over the NEAR_POINTS nearest points alone: noise roughens both, a second sheet or
  a crease a few point spacings away only the first.

These extra features are standardised inside the network (``extra_mean``, ``extra_scale``: the
training set's mean and inverse standard deviation, stored with the weights): unscaled, their
small spread left the head blind to them and every query got the same radius.

A 3-layer MLP with a sigmoid gives s in (0, 1); rho = rho_min + (rho_max - rho_min) * s and
r_hat = rho * R. The range is applied at inference, so changing rho_min / rho_max needs no
retraining (the network learns where in the range to sit).

Two implementations read one weights file: :class:`NumpySelector` (CPU, Blender) and
:class:`engine.selector_torch.RadiusSelector` (training, CUDA). This module never imports torch
itself: the torch network is imported when it is asked for.
"""

from pathlib import Path
from typing import Dict, Optional, Tuple, Union

import numpy as np

from .backbone import ZEROS, max_pool, relu_
from .cpu_threads import run_in_threads
from .patch_roughness import ROUGHNESS_FEATURES, patch_roughness
from .patches import (QUERY_CHUNK, Neighbours, groups_by_count, nearest_within,
                      patches_from_neighbours)
from .weights_file import read_weights

DEFAULT_WEIGHTS = Path(__file__).resolve().parent / "weights" / "selector.npz"
PARENT_POINTS = 64
STRIDE = 4
HISTOGRAM_BINS = 6
NEAR_POINTS = 16
EXTRA_FEATURES = 1 + HISTOGRAM_BINS + 2 * ROUGHNESS_FEATURES  # log count, histogram, roughness
# (strided, near)
# Queries per numpy forward pass: their per-point activations (256 x about 10 points x 64
# float32) stay in a core's cache between the layers.
BATCH = 256

DEFAULT_CONFIG = {
    "hidden": 16,      # H of the ResNet-PointNet
    "blocks": 3,       # ResNet blocks
    "code": 256,       # the patch code's width (the paper's 256-d feature)
    "mlp": [128, 64],  # hidden widths of the 3-layer MLP
}


def parent_features(tree, points: np.ndarray, queries: np.ndarray, parent_radius: float,
                    neighbours: Optional[Neighbours] = None, threads: int = 1,
                    ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the selector reads for each query.

    ``neighbours``, when given, are the queries' :func:`parent_neighbours` (the field computes
    them once for the selector and the backbone); otherwise they are looked up in ``tree``.
    ``threads``: CPU threads for the roughness fits (the answers do not depend on it).

    Returns
    -------
    rel : (Q, PARENT_POINTS // STRIDE, 3) float32, strided parent-patch points / R
    mask : (Q, PARENT_POINTS // STRIDE) bool
    extra : (Q, EXTRA_FEATURES) float32, [log(1 + N) / log(1 + PARENT_POINTS), histogram,
        roughness (thickness, quadric residual, split) of the strided patch and of the NEAR_POINTS
        nearest], as measured (standardised in the network)
    """
    if neighbours is None:  # chunk by chunk: the lists take 2 kB per query
        parts = [parent_features(tree, points, queries[start:start + QUERY_CHUNK], parent_radius,
                                 parent_neighbours(tree, queries[start:start + QUERY_CHUNK],
                                                   parent_radius), threads)
                 for start in range(0, max(len(queries), 1), QUERY_CHUNK)]
        return tuple(np.concatenate(arrays) for arrays in zip(*parts))
    strided = Neighbours(neighbours.distance[:, :PARENT_POINTS:STRIDE],
                         neighbours.index[:, :PARENT_POINTS:STRIDE])
    rel, mask, _ = patches_from_neighbours(points, queries, strided, parent_radius,
                                           PARENT_POINTS // STRIDE)
    distance = neighbours.distance[:, :PARENT_POINTS]
    counts = np.count_nonzero(distance <= parent_radius, axis=1)
    # a point's shell is floor(scaled), the last shell also taking scaled == HISTOGRAM_BINS
    # (d = R); floor(scaled) < k exactly when scaled < k, so the points below each shell are
    # counted without gathering them (points beyond R have scaled > HISTOGRAM_BINS)
    scaled = distance / parent_radius * HISTOGRAM_BINS
    below = np.empty((len(distance), HISTOGRAM_BINS + 1), dtype=np.int64)
    below[:, 0] = 0
    for k in range(1, HISTOGRAM_BINS):
        below[:, k] = np.count_nonzero(scaled < k, axis=1)
    below[:, HISTOGRAM_BINS] = counts
    hist = np.diff(below, axis=1) / np.maximum(counts, 1)[:, None]
    log_count = np.log1p(counts) / np.log1p(PARENT_POINTS)
    roughness = patch_roughness(rel, mask, threads)
    near = Neighbours(neighbours.distance[:, :NEAR_POINTS], neighbours.index[:, :NEAR_POINTS])
    near_rel, near_mask, _ = patches_from_neighbours(points, queries, near, parent_radius,
                                                     NEAR_POINTS)
    near_roughness = patch_roughness(near_rel, near_mask, threads)
    extra = np.column_stack([log_count, hist, roughness, near_roughness]).astype(np.float32)
    return rel, mask, extra


def parent_neighbours(tree, queries: np.ndarray, parent_radius: float) -> Neighbours:
    """The PARENT_POINTS nearest points within R of each query: the parent ball's lists."""
    return nearest_within(tree, queries, parent_radius, PARENT_POINTS)


def macs_per_query(config: Dict) -> int:
    """Multiply-accumulates of one selector pass (layers only)."""
    h, points = config["hidden"], PARENT_POINTS // STRIDE
    per_point = 3 * 2 * h + config["blocks"] * (2 * h * h + h * h + 2 * h * h)
    widths = [config["code"] + EXTRA_FEATURES] + config["mlp"] + [1]
    mlp = sum(a * b for a, b in zip(widths, widths[1:]))
    return points * per_point + h * config["code"] + mlp


class NumpySelector:
    """Pure-numpy forward pass. ``predict_unit(rel, mask, extra) -> (Q,) s in (0, 1)``."""

    def __init__(self, params: Dict[str, np.ndarray], config: Dict):
        self.config = dict(config)
        self.p = {k: (np.ascontiguousarray(v.T) if v.ndim == 2 else v).astype(np.float32)
                  for k, v in params.items()}
        # The first layer reads [rel, 1] (its bias is the weight of the constant input). The
        # first block's shortcut is linear in that layer's output, so it folds into the same
        # product: [rel, 1] @ [pos | pos @ shortcut] gives both at once.
        pos = np.vstack([params["pos.weight"].T, params["pos.bias"][None]]).astype(np.float64)
        shortcut = pos @ params["block0.shortcut.weight"].T.astype(np.float64)
        self.pos = np.hstack([pos, shortcut]).astype(np.float32)
        self.max_pool = max_pool()

    def _linear(self, x, name, bias=True):
        y = x @ self.p[name + ".weight"]
        if bias:
            y += self.p[name + ".bias"]
        return y

    def _first_block(self, x):
        """The first layer and the first ResNet block, fc_1(relu(fc_0(relu(pos)))) +
        shortcut(pos), from x = [rel, 1] (b*n, 4)."""
        both = x @ self.pos                                               # (b*n, 2H + H)
        width = self.p["pos.weight"].shape[1]
        pos = np.maximum(both[:, :width], ZEROS.like(both[:, :width]))
        t = self._linear(pos, "block0.fc0")
        t = self._linear(relu_(t), "block0.fc1")
        t += both[:, width:]
        return t

    def _pooled_block(self, x, pooled, name):
        """The block on [x, pooled] (b, n, 2H) without building it: each weight matrix is split
        into its x rows and its pooled rows, and the pooled part is computed once per patch."""
        b, n, h = x.shape
        p = self.p
        w0, ws = p[name + ".fc0.weight"], p[name + ".shortcut.weight"]
        per_patch = np.maximum(pooled, ZEROS.like(pooled)) @ w0[h:]         # (b, H)
        per_patch += p[name + ".fc0.bias"]
        x = x.reshape(b * n, h)
        t = (np.maximum(x, ZEROS.like(x)) @ w0[:h]).reshape(b, n, -1)
        t += per_patch[:, None]
        t = relu_(t).reshape(b * n, -1) @ p[name + ".fc1.weight"]
        t += x @ ws[:h]
        t = t.reshape(b, n, -1)
        per_patch = pooled @ ws[h:]
        per_patch += p[name + ".fc1.bias"]
        t += per_patch[:, None]
        return t

    def _forward(self, rel, mask, extra):
        b, n, _ = rel.shape
        h = self.config["hidden"]
        # Padding rows become copies of the patch's first point: every per-point feature of a
        # copy equals that point's, so the max pools need no mask.
        if not mask.all():
            first = rel[np.arange(b), mask.argmax(axis=1)]
            rel = np.where(mask[:, :, None], rel, first[:, None, :])
        x = np.empty((b * n, 4), dtype=np.float32)
        x[:, :3] = rel.reshape(b * n, 3)
        x[:, 3] = 1.0
        net = self._first_block(x).reshape(b, n, h)                       # (b, n, H)
        for k in range(1, self.config["blocks"]):
            pooled = self.max_pool(net)                                # (b, H)
            net = self._pooled_block(net, pooled, f"block{k}")            # (b, n, H)
        pooled = self.max_pool(net)
        code = self._linear(np.maximum(pooled, ZEROS.like(pooled)), "code")   # (b, 256)
        extra = (extra - self.p["extra_mean"]) * self.p["extra_scale"]
        z = np.concatenate([code, extra], axis=1)
        for k in range(len(self.config["mlp"])):
            z = relu_(self._linear(z, f"mlp{k}"))
        z = self._linear(z, "out")[:, 0]
        return (0.5 * (1.0 + np.tanh(0.5 * z))).astype(np.float32)  # overflow-free sigmoid

    def predict_unit(self, rel, mask, extra, batch_size: int = BATCH, threads: int = 1,
                     ) -> np.ndarray:
        """s per query. Padding columns never change it (the pools are masked) but cost as much
        as points: queries go in order of point count, each batch cut to its largest count.
        With ``threads`` > 1 the batches run on that many threads (:mod:`engine.cpu_threads`);
        each batch's answer is the same either way."""
        rel = np.asarray(rel, dtype=np.float32)
        mask = np.asarray(mask, dtype=bool)
        extra = np.asarray(extra, dtype=np.float32)
        out = np.empty(rel.shape[0], dtype=np.float32)

        def run(item):
            batch, width = item
            out[batch] = self._forward(rel[batch, :width], mask[batch, :width], extra[batch])

        run_in_threads(run, groups_by_count(mask.sum(axis=1), batch_size), threads)
        return out


def predict_radii(selector, tree, points: np.ndarray, queries: np.ndarray, parent_radius: float,
                  rho_min: float, rho_max: float,
                  neighbours: Optional[Neighbours] = None, threads: int = 1) -> np.ndarray:
    """Per-query radii r_hat = rho * R with rho in [rho_min, rho_max]; (Q,) float64, unit frame.

    A query whose parent ball is empty keeps rho_max (the backbone treats it as far anyway).
    ``neighbours``: the queries' :func:`parent_neighbours`, when already at hand. ``threads``:
    CPU threads for the roughness fits and the network (the answers do not depend on it).
    """
    rel, mask, extra = parent_features(tree, points, queries, parent_radius, neighbours, threads)
    s = np.ones(len(queries), dtype=np.float64)
    has_points = mask.any(axis=1)
    if np.any(has_points):
        s[has_points] = selector.predict_unit(rel[has_points], mask[has_points],
                                              extra[has_points], threads=threads)
    return (rho_min + (rho_max - rho_min) * s) * parent_radius


def build_selector_torch(config: Optional[Dict] = None):
    """A freshly initialised torch :class:`~engine.selector_torch.RadiusSelector` (training)."""
    from .selector_torch import RadiusSelector

    return RadiusSelector(config)


def load_selector_numpy(path: Union[str, Path, None] = None) -> NumpySelector:
    """The numpy selector from a weights file (default ``engine/weights/selector.npz``)."""
    params, header = read_weights(DEFAULT_WEIGHTS if path is None else path)
    return NumpySelector(params, header["config"])


class TorchSelector:
    """The torch selector behind :class:`NumpySelector`'s ``predict_unit``: for a CUDA GPU."""

    def __init__(self, module, device: str):
        self.module = module
        self.device = device

    def predict_unit(self, rel, mask, extra, batch_size: int = 65536, threads: int = 1,
                     ) -> np.ndarray:
        """s per query (``threads`` is the CPU selector's and is ignored here)."""
        import torch

        out = np.empty(len(rel), dtype=np.float32)
        with torch.no_grad():
            for start in range(0, len(rel), batch_size):
                part = slice(start, start + batch_size)
                inputs = (torch.from_numpy(np.ascontiguousarray(a[part])).to(self.device)
                          for a in (rel, mask, extra))
                out[part] = self.module(*inputs).float().cpu().numpy()
        return out


def load_selector_torch(path: Union[str, Path, None] = None, device: str = "cpu"):
    """The torch selector (eval mode, on ``device``) from a weights file (default shipped)."""
    import torch

    params, header = read_weights(DEFAULT_WEIGHTS if path is None else path)
    module = build_selector_torch(header["config"])
    module.load_state_dict({k: torch.from_numpy(v) for k, v in params.items()})
    return module.to(device).eval()
