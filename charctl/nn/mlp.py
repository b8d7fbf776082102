"""Multi-layer perceptrons and a running observation normaliser (torch)."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

ACTIVATIONS: dict[str, type[nn.Module]] = {"relu": nn.ReLU, "tanh": nn.Tanh, "elu": nn.ELU, "silu": nn.SiLU}


def mlp(
    in_dim: int,
    hidden: Sequence[int],
    out_dim: int,
    activation: str = "relu",
    spectral_norm: bool = False,
    out_gain: float = 1.0,
) -> nn.Sequential:
    """Linear-activation stack in_dim -> hidden... -> out_dim (no activation on the output).

    `spectral_norm` wraps every Linear layer (torch.nn.utils.parametrizations.spectral_norm).
    `out_gain` scales the output layer's initial weights (small values = near-zero initial outputs).
    """
    if activation not in ACTIVATIONS:
        raise ValueError(f"unknown activation {activation!r}; choose one of {sorted(ACTIVATIONS)}")
    dims = [in_dim, *hidden, out_dim]
    layers: list[nn.Module] = []
    for i in range(len(dims) - 1):
        lin = nn.Linear(dims[i], dims[i + 1])
        if i == len(dims) - 2 and out_gain != 1.0:
            with torch.no_grad():
                lin.weight.mul_(out_gain)
                lin.bias.zero_()
        if spectral_norm:
            lin = nn.utils.parametrizations.spectral_norm(lin)
        layers.append(lin)
        if i < len(dims) - 2:
            layers.append(ACTIVATIONS[activation]())
    return nn.Sequential(*layers)


class RunningNorm(nn.Module):
    """Running mean/variance normaliser (parallel Welford); clip to +-`clip` std after normalising.

    Buffers (mean, var, count) are part of the state dict, so checkpoints and exports carry them.
    """

    def __init__(self, dim: int, clip: float = 5.0, eps: float = 1e-5):
        super().__init__()
        self.register_buffer("mean", torch.zeros(dim))
        self.register_buffer("var", torch.ones(dim))
        self.register_buffer("count", torch.tensor(eps))
        self.clip = clip
        self.eps = eps

    @torch.no_grad()
    def update(self, x: torch.Tensor) -> None:
        x = x.reshape(-1, x.shape[-1]).to(self.mean.dtype)
        n = x.shape[0]
        if n == 0:
            return
        b_mean = x.mean(0)
        b_var = x.var(0, unbiased=False)
        total = self.count + n
        delta = b_mean - self.mean
        self.mean += delta * n / total
        self.var = (self.var * self.count + b_var * n + delta**2 * self.count * n / total) / total
        self.count = total

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.clamp((x - self.mean) / torch.sqrt(self.var + self.eps), -self.clip, self.clip)
