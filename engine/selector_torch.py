"""The radius selector in torch (training and CUDA inference): the same forward pass as
:class:`engine.selector.NumpySelector`, reading the same weights file.

This module imports torch; :mod:`engine.selector` imports it only when a torch network is asked
for, so reconstructing on the CPU never loads torch.
"""

from typing import Dict, Optional

import torch
from torch import nn

from .selector import DEFAULT_CONFIG, EXTRA_FEATURES


class Block(nn.Module):
    """ResNet block: fc1(relu(fc0(relu(x)))) + shortcut(x), fc1 zero-initialised."""

    def __init__(self, size_in: int, size_out: int):
        super().__init__()
        self.fc0 = nn.Linear(size_in, size_out)
        self.fc1 = nn.Linear(size_out, size_out)
        self.shortcut = nn.Linear(size_in, size_out, bias=False)
        nn.init.zeros_(self.fc1.weight)

    def forward(self, x):
        return self.fc1(torch.relu(self.fc0(torch.relu(x)))) + self.shortcut(x)


class RadiusSelector(nn.Module):
    """forward(rel (B,N,3), mask (B,N) bool, extra (B,EXTRA_FEATURES)) -> (B,) s in (0, 1)."""

    def __init__(self, config: Optional[Dict] = None):
        super().__init__()
        self.config = dict(DEFAULT_CONFIG if config is None else config)
        h = self.config["hidden"]
        self.pos = nn.Linear(3, 2 * h)
        for k in range(self.config["blocks"]):
            setattr(self, f"block{k}", Block(2 * h, h))
        self.code = nn.Linear(h, self.config["code"])
        widths = [self.config["code"] + EXTRA_FEATURES] + self.config["mlp"]
        for k, (a, b) in enumerate(zip(widths, widths[1:])):
            setattr(self, f"mlp{k}", nn.Linear(a, b))
        self.out = nn.Linear(widths[-1], 1)
        self.register_buffer("extra_mean", torch.zeros(EXTRA_FEATURES))
        self.register_buffer("extra_scale", torch.ones(EXTRA_FEATURES))

    def standardise_extra(self, extra):
        """Set the extra features' standardisation from training data (Q, EXTRA_FEATURES)."""
        extra = torch.as_tensor(extra, dtype=torch.float32)
        self.extra_mean.copy_(extra.mean(dim=0))
        self.extra_scale.copy_(1.0 / (extra.std(dim=0) + 1e-6))

    def forward(self, rel, mask, extra):
        return torch.sigmoid(self.logit(rel, mask, extra))

    def logit(self, rel, mask, extra):
        """The pre-sigmoid output z, s = sigmoid(z) (training watches it)."""
        neg = ~mask[:, :, None]
        net = self.pos(rel)
        for k in range(self.config["blocks"]):
            if k:
                pooled = net.masked_fill(neg, float("-inf")).max(dim=1).values
                net = torch.cat([net, pooled[:, None].expand_as(net)], dim=2)
            net = getattr(self, f"block{k}")(net)
        pooled = net.masked_fill(neg, float("-inf")).max(dim=1).values
        extra = (extra - self.extra_mean) * self.extra_scale
        z = torch.cat([self.code(torch.relu(pooled)), extra], dim=1)
        for k in range(len(self.config["mlp"])):
            z = torch.relu(getattr(self, f"mlp{k}")(z))
        return self.out(z)[:, 0]
