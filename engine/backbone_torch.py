"""The backbone in torch (training and GPU inference): the same forward pass as
:class:`engine.backbone.NumpyBackbone`, reading the same weights file.

This module imports torch; :mod:`engine.backbone` imports it only when a torch network is asked
for, so reconstructing on the CPU never loads torch.
"""

from typing import Dict, Optional

import numpy as np
import torch
from torch import nn

from .backbone import DEFAULT_CONFIG, _quadratic_inverse, geometric_feature_count


def geometric_features(rel: torch.Tensor, mask: torch.Tensor, config: Dict) -> torch.Tensor:
    """(B, F) float32 features of patches: :func:`engine.backbone.geometric_features_np` in
    torch (computed in float64)."""
    rel64 = rel.double()
    m = mask.double()
    dist = torch.sqrt(torch.sum(rel64 * rel64, dim=2))
    padded = torch.where(mask, dist, torch.ones_like(dist))
    k = config["smallest"]
    smallest = torch.sort(padded, dim=1).values[:, :k]
    if smallest.shape[1] < k:
        fill = smallest.new_ones((smallest.shape[0], k - smallest.shape[1]))
        smallest = torch.cat([smallest, fill], dim=1)
    dmin = smallest[:, 0]
    feats = [smallest[:, j] for j in range(k)]
    for tau in config["softmin_taus"]:
        s = torch.sum(m * torch.exp(-(padded - dmin[:, None]) / tau), dim=1)
        feats.append(dmin - tau * torch.log(s))
    count = m.sum(dim=1)
    feats.append(count / 64.0)
    uniform = m / count[:, None]
    gauss = m * torch.exp(-(padded / config["gauss_sigma"]) ** 2)
    gauss = gauss / gauss.sum(dim=1, keepdim=True)
    for w in (uniform, gauss):
        c = torch.einsum("bn,bnk->bk", w, rel64)
        d = rel64 - c[:, None, :]
        cov = torch.einsum("bn,bni,bnj->bij", w, d, d)
        trace = cov[:, 0, 0] + cov[:, 1, 1] + cov[:, 2, 2]
        feats.extend([torch.sqrt(torch.sum(c * c, dim=1)), torch.sqrt(trace)])
        for alpha in config["plane_alphas"]:
            eps = alpha * trace + 1e-6
            quad = _quadratic_inverse(cov, eps, c, torch)
            feats.append(torch.sqrt(torch.clamp(eps * quad, min=0)))
    return torch.stack(feats, dim=1).float()


class UDFBackbone(nn.Module):
    """forward(rel (B, N, 3), mask (B, N) bool) -> (B,) UDF / r; see :mod:`engine.backbone`."""

    def __init__(self, config: Optional[Dict] = None):
        super().__init__()
        self.config = dict(DEFAULT_CONFIG if config is None else config)
        h, w, heads = self.config["hidden"], self.config["head_width"], self.config["heads"]
        f = geometric_feature_count(self.config)
        self.enc0 = nn.Linear(4, h)
        self.enc1 = nn.Linear(h, h)
        self.enc2a = nn.Linear(h, h, bias=False)
        self.enc2b = nn.Linear(h, h)
        self.enc3 = nn.Linear(h, h)
        self.query0 = nn.Linear(2 * h + f, w)
        self.query1 = nn.Linear(w, heads * h)
        self.head0 = nn.Linear(2 * h + heads * h + f, w)
        self.head1 = nn.Linear(w, w)
        self.head2 = nn.Linear(w, 1)
        with torch.no_grad():
            self.enc3.weight.mul_(0.1)
            self.query1.weight.mul_(0.1)

    def forward(self, rel, mask, geo=None):
        """rel (B, N, 3) float32, mask (B, N) bool -> (B,) UDF / r.

        ``geo`` (B, F) may pass precomputed :func:`engine.backbone.geometric_features_np` (they
        are rotation invariant, so training caches them per patch).
        """
        cfg = self.config
        b, n, _ = rel.shape
        hdim, heads = cfg["hidden"], cfg["heads"]
        if geo is None:
            with torch.no_grad():
                geo = geometric_features(rel, mask, cfg)
        dist = torch.sqrt(torch.sum(rel * rel, dim=2, keepdim=True))
        x = torch.cat([rel, dist], dim=2)
        h1 = self.enc1(torch.relu(self.enc0(x)))
        neg = ~mask[:, :, None]
        g1 = h1.masked_fill(neg, float("-inf")).max(dim=1).values
        t = self.enc2a(torch.relu(h1)) + self.enc2b(g1)[:, None, :]
        h2 = h1 + self.enc3(torch.relu(t))
        count = mask.sum(dim=1, keepdim=True).float()
        pmax = h2.masked_fill(neg, float("-inf")).max(dim=1).values
        pmean = h2.masked_fill(neg, 0.0).sum(dim=1) / count
        pooled = torch.cat([pmax, pmean, geo], dim=1)
        query = self.query1(torch.relu(self.query0(pooled))).view(b, heads, hdim)
        scores = torch.einsum("bhc,bnc->bhn", query, h2) / float(np.sqrt(hdim))
        scores = scores.masked_fill(~mask[:, None, :], float("-inf"))
        attn = torch.softmax(scores, dim=2)
        ctx = torch.einsum("bhn,bnc->bhc", attn, h2).reshape(b, heads * hdim)
        z = torch.cat([pmax, pmean, ctx, geo], dim=1)
        z = torch.relu(self.head0(z))
        z = torch.relu(self.head1(z))
        return nn.functional.softplus(self.head2(z)[:, 0])
