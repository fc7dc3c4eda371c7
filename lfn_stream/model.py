"""The nested-width light field network (one file, readable top to bottom).

Width w uses the top-left w×w block of every hidden matrix (first layer: all 6 inputs; last
layer: all 4 outputs), so every smaller network is inside the larger one. A fractional width
w + α (0 < α < 1) activates neuron w with weight α: it enters each LayerNorm's statistics
with weight α and its activation is multiplied by α, so level w + 0 is exactly the width-w
network and quality changes continuously in between (neuron masking).
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from .config import LfnConfig


def _mask(neurons: float, device, dtype) -> tuple[int, torch.Tensor]:
    """Active neuron count and per-neuron weights [1, …, 1, α] for a fractional neuron count."""
    w = int(math.floor(neurons + 1e-9))
    a = float(neurons - w)
    if a > 1e-6:
        m = torch.ones(w + 1, device=device, dtype=dtype)
        m[-1] = a
        return w + 1, m
    return w, torch.ones(w, device=device, dtype=dtype)


class NestedLFN(nn.Module):
    """Plücker ray (N, 6) → RGBA (N, 4) in [0, 1], at any width in [min_neurons, max_neurons]."""

    def __init__(self, cfg: LfnConfig):
        super().__init__()
        self.cfg = cfg
        W, D = cfg.max_neurons, cfg.depth
        dims_in = [cfg.in_features] + [W] * (D - 1)
        self.weights = nn.ParameterList([nn.Parameter(torch.empty(W, d)) for d in dims_in])     # (W, in)
        self.biases = nn.ParameterList([nn.Parameter(torch.zeros(W)) for _ in range(D)])
        self.gammas = nn.ParameterList([nn.Parameter(torch.ones(W)) for _ in range(D)])
        self.betas = nn.ParameterList([nn.Parameter(torch.zeros(W)) for _ in range(D)])
        self.out_w = nn.Parameter(torch.empty(cfg.out_features, W))                             # (4, W)
        self.out_b = nn.Parameter(torch.zeros(cfg.out_features))
        for w in self.weights:
            nn.init.kaiming_uniform_(w, a=math.sqrt(5))
        nn.init.uniform_(self.out_w, -1 / math.sqrt(W), 1 / math.sqrt(W))

    def forward(self, x: torch.Tensor, neurons: float | None = None) -> torch.Tensor:
        """x: (N, 6) Plücker rays; neurons: fractional network size (default: full). Returns (N, 4)."""
        neurons = float(self.cfg.max_neurons if neurons is None else neurons)
        if not self.cfg.min_neurons - 1e-9 <= neurons <= self.cfg.max_neurons + 1e-9:
            raise ValueError(f"{neurons} neurons outside [{self.cfg.min_neurons}, {self.cfg.max_neurons}]")
        n, m = _mask(min(neurons, self.cfg.max_neurons), x.device, x.dtype)
        if not self.training and bool((m == 1).all()):     # an integer size: fused LayerNorm (1.5x faster)
            return self._plain(x, n)
        return self._masked(x, n, m, m.sum())

    def _plain(self, x: torch.Tensor, n: int) -> torch.Tensor:
        """The first n neurons of every layer, all with weight 1 (the same network as
        :meth:`_masked` with unit weights, up to float rounding, in fused kernels)."""
        h = x
        for i in range(self.cfg.depth):
            z = F.linear(h, self.weights[i][:n, :h.shape[1]], self.biases[i][:n])
            h = torch.relu(F.layer_norm(z, (n,), self.gammas[i][:n], self.betas[i][:n], 1e-5))
        return torch.sigmoid(F.linear(h, self.out_w[:, :n], self.out_b))

    def _masked(self, x: torch.Tensor, n: int, m: torch.Tensor, msum: torch.Tensor) -> torch.Tensor:
        """The first n neurons of every layer, neuron weights m ((n,) for all rays or (N, n) per
        ray) summing to msum: LayerNorm statistics and activations weighted by m."""
        h = x
        for i in range(self.cfg.depth):
            k = h.shape[1]
            z = h @ self.weights[i][:n, :k].T + self.biases[i][:n]                              # (N, n)
            mean = (z * m).sum(1, keepdim=True) / msum
            var = (((z - mean) ** 2) * m).sum(1, keepdim=True) / msum
            z = (z - mean) * torch.rsqrt(var + 1e-5) * self.gammas[i][:n] + self.betas[i][:n]
            h = torch.relu(z) * m                                                               # (N, n)
        return torch.sigmoid(h @ self.out_w[:, :n].T + self.out_b)                              # (N, 4)

    def forward_lod(self, x: torch.Tensor, neurons: torch.Tensor) -> torch.Tensor:
        """Each ray at its own fractional size: x (N, 6), neurons (N,) within [min_neurons,
        max_neurons]. One pass at width ceil(max(neurons)); ray r weighs neuron j by
        clamp(neurons[r] − j, 0, 1), so every row equals :meth:`forward` at that row's size (up
        to float rounding: the masked columns add exact zeros). Returns (N, 4)."""
        if x.shape[0] == 0:
            return x.new_zeros((0, self.cfg.out_features))
        top = float(neurons.max())
        n = min(int(math.ceil(top - 1e-9)), self.cfg.max_neurons)
        if not self.training and bool((neurons == n).all()):
            return self._plain(x, n)
        m = (neurons[:, None].to(x.dtype) - torch.arange(n, device=x.device, dtype=x.dtype)[None, :]).clamp_(0, 1)
        m = torch.where(m > 1e-6, m, torch.zeros_like(m))        # as _mask: α ≤ 1e-6 is no neuron
        return self._masked(x, n, m, m.sum(1, keepdim=True))

    def n_params(self, neurons: int | None = None) -> int:
        """Parameters used at an integer neuron count."""
        w = neurons or self.cfg.max_neurons
        c = self.cfg
        first = w * c.in_features + 3 * w
        hidden = (c.depth - 1) * (w * w + 3 * w)
        return first + hidden + c.out_features * w + c.out_features


class OccupancyNet(nn.Module):
    """Tiny MLP: Plücker ray (N, 6) → logit that the ray hits the object (alpha > 0)."""

    def __init__(self, neurons: int = 32, in_features: int = 6):
        super().__init__()
        self.net = nn.Sequential(nn.Linear(in_features, neurons), nn.ReLU(), nn.Linear(neurons, neurons), nn.ReLU(),
                                 nn.Linear(neurons, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)[:, 0]
