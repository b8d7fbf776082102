"""Conditional discriminator (style head D and class head C), its losses and the rewards.

Input φ = (o_t, o_t+1), normalised with statistics of the demonstration data (frozen).
All layers spectral-normalised (paper §5.3).
Losses (eq 4.2-4.6):
    L_style = E_M[(D - 1)^2] + E_pi[(D + 1)^2]
    L_class = CE(C(φ_M), clip label) + CE(C(φ_pi), c̄)       (soft target c̄ during transitions)
              or, with class_loss="ls", sum ||c̄ - softmax C||^2  (eq 6.2 ablation)
    L_gp    = (w_gp / 2) E_M[ ||∇_φ D(φ)||^2 ]
Rewards: r_S = clip(1 - 1/4 (1 - D)^2, 0, 1) (eq 4.7); r_C = 1 - min(1, ||softmax C - c̄||_1) (eq 4.8),
blended (1 - w) r_C(c_A) + w r_C(c_B) during a transition (eq 4.11).

Style head: ``shared`` (the paper) is one score D(φ) for every skill, so nothing asks the kick command for
kick-like style. ``per_skill`` (C·ASE's one style logit per skill label, CALM's latent-conditioned
discriminator) has one score D_k(φ) per skill from the shared trunk; the score for a command blend c̄ is
D(φ, c̄) = Σ_k c̄_k D_k(φ): data pairs use their clip's logit, policy pairs the logit of their command.
"""

from __future__ import annotations

import copy

import torch
import torch.nn.functional as F
from torch import nn
from torch.nn.utils import parametrize

from charctl.nn.mlp import ACTIVATIONS, RunningNorm

SN = nn.utils.parametrizations.spectral_norm
STYLE_HEADS = ("shared", "per_skill")


class Discriminator(nn.Module):
    def __init__(
        self,
        pair_dim: int,
        num_classes: int,
        hidden: list[int],
        conditional: bool = True,
        activation: str = "relu",
        style_head: str = "shared",
    ):
        super().__init__()
        self.norm = RunningNorm(pair_dim, clip=10.0)
        layers: list[nn.Module] = []
        d = pair_dim
        for h in hidden:
            layers += [SN(nn.Linear(d, h)), ACTIVATIONS[activation]()]
            d = h
        self.trunk = nn.Sequential(*layers)
        if style_head not in STYLE_HEADS:
            raise ValueError(f"unknown style head {style_head!r}; choose from {STYLE_HEADS}")
        self.per_skill = style_head == "per_skill"
        self.style_head = SN(nn.Linear(d, num_classes if self.per_skill else 1))
        self.conditional = conditional
        self.class_head = SN(nn.Linear(d, num_classes)) if conditional else None
        self.num_classes = num_classes

    def forward(
        self, pairs: torch.Tensor, normalized: bool = False, cond: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """(D score (B,), class logits (B, K) or None). `cond` (B, K): the command blend c̄ (or the clip's
        one-hot label) the per-skill style head scores the pairs for; the shared head ignores it."""
        x = pairs if normalized else self.norm(pairs)
        h = self.trunk(x)
        d = self.style_head(h)
        if self.per_skill:
            if cond is None:
                raise ValueError("a per-skill style head needs the command blend `cond` (B, K)")
            d = (d * cond.to(d.dtype)).sum(-1)
        else:
            d = d.squeeze(-1)
        if self.class_head is None:
            return d, None
        return d, self.class_head(h)


def frozen_copy(disc: Discriminator) -> Discriminator:
    """An inference copy of `disc` whose spectral-normalised layers are plain Linears holding their effective
    weights (W / sigma with the stored power-iteration vectors, as `disc.eval()` uses them), computed once
    here instead of at every call; no gradients. `disc` itself is not changed. The rollout's low-style
    check and the web graph score pairs with it."""
    out = copy.deepcopy(disc).eval()
    for parent in list(out.modules()):
        for name, child in list(parent.named_children()):
            if isinstance(child, nn.Linear) and parametrize.is_parametrized(child):
                with torch.no_grad():
                    plain = nn.Linear(child.in_features, child.out_features, device=child.bias.device)
                    plain.weight.copy_(child.weight)
                    plain.bias.copy_(child.bias)
                setattr(parent, name, plain)
    return out.requires_grad_(False)


def style_loss(d_data: torch.Tensor, d_policy: torch.Tensor) -> torch.Tensor:
    """LSGAN style loss (eq 4.4): data -> +1, policy -> -1 (least squares on the raw score)."""
    return ((d_data - 1.0) ** 2).mean() + ((d_policy + 1.0) ** 2).mean()


def wrong_skill_labels(
    labels: torch.Tensor, num_classes: int, generator: torch.Generator | None = None
) -> torch.Tensor:
    """(B,) a skill other than each of `labels`, uniformly (CALM's negatives: a demonstration pair scored
    for a skill it does not belong to is a fake for that skill's style logit). Needs num_classes >= 2."""
    shift = torch.randint(1, num_classes, labels.shape, generator=generator).to(labels.device)
    return (labels + shift) % num_classes


def class_loss(logits: torch.Tensor, target: torch.Tensor, kind: str = "ce") -> torch.Tensor:
    """Eq 4.5 (soft-label cross-entropy) or the least-squares ablation (eq 6.2). target: (B, K) probabilities."""
    if kind == "ce":
        return -(target * F.log_softmax(logits, dim=-1)).sum(-1).mean()
    if kind == "ls":
        return ((target - F.softmax(logits, dim=-1)) ** 2).sum(-1).mean()
    raise ValueError(f"unknown class loss {kind!r}")


def gradient_penalty(
    disc: Discriminator, pairs_normalized: torch.Tensor, w_gp: float, cond: torch.Tensor | None = None
) -> torch.Tensor:
    """(w_gp / 2) E[||∇_φ D(φ, c)||^2] on (normalised) data pairs, eq 4.6 (`cond`: their one-hot labels,
    used by a per-skill style head)."""
    x = pairs_normalized.detach().requires_grad_(True)
    d, _ = disc(x, normalized=True, cond=cond)
    (grad,) = torch.autograd.grad(d.sum(), x, create_graph=True)
    return 0.5 * w_gp * (grad**2).sum(-1).mean()


def style_reward(d: torch.Tensor) -> torch.Tensor:
    """Style reward from the discriminator score (eq 4.7): r_S = clip(1 - 1/4 (1 - D)^2, 0, 1), in [0, 1]."""
    return torch.clamp(1.0 - 0.25 * (1.0 - d) ** 2, 0.0, 1.0)


def class_reward(probs: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """r_C = 1 - min(1, ||C - c̄||_1) (eq 4.8)."""
    return 1.0 - torch.clamp((probs - target).abs().sum(-1), max=1.0)


def blended_class_reward(
    probs: torch.Tensor, cmd_a: torch.Tensor, cmd_b: torch.Tensor, w: torch.Tensor, num_classes: int, form: str = "l1"
) -> torch.Tensor:
    """Eq 4.11: (1 - w) r_C(c_A) + w r_C(c_B) with one-hot c_A, c_B.

    form ``l1`` is eq 4.8, r_C = 1 - min(1, ||C - c||_1) = max(0, 2 P(c) - 1) for a one-hot c: zero
    until the classifier gives the command more than half the probability. ``prob`` is the dense
    variant r_C = P(c), which pays for every step towards the commanded skill (docs/cgail.md, ablation).
    ``logratio`` is the skill-discovery reward log q(c | s, s') - log p(c) with the uniform prior
    p(c) = 1/K (DIAYN's form): r_C = log(K P(c)), clipped below at -1. It is 0 at chance, log K when the
    classifier is certain, and separates P(c) = 0.10 from 0.15 by 0.4 where ``prob`` gives 0.05 — the
    contrast ten skills need while the classifier is still unsure on policy motion.
    """
    if form not in ("l1", "prob", "logratio"):
        raise ValueError(f"unknown class reward form {form!r}")

    def reward_for(cmd: torch.Tensor) -> torch.Tensor:
        if form == "l1":
            return class_reward(probs, F.one_hot(cmd, num_classes).to(probs.dtype))
        p = probs.gather(-1, cmd.unsqueeze(-1)).squeeze(-1)
        return p if form == "prob" else torch.clamp(torch.log(num_classes * p.clamp_min(1e-12)), min=-1.0)

    return (1.0 - w) * reward_for(cmd_a) + w * reward_for(cmd_b)


class ReplayBuffer:
    """Ring buffer of policy pairs and their command blends (for the discriminator's policy half).

    Lives on `device` (the learner's); its state dict is always on the CPU, so checkpoints load anywhere."""

    def __init__(self, capacity: int, pair_dim: int, num_classes: int, device: str | torch.device = "cpu"):
        self.pairs = torch.zeros(capacity, pair_dim, device=device)
        self.cond = torch.zeros(capacity, num_classes, device=device)
        self.capacity, self.size, self.pos = capacity, 0, 0

    def add(self, pairs: torch.Tensor, cond: torch.Tensor) -> None:
        n = pairs.shape[0]
        if n >= self.capacity:
            pairs, cond, n = pairs[-self.capacity :], cond[-self.capacity :], self.capacity
        idx = (torch.arange(n, device=self.pairs.device) + self.pos) % self.capacity
        self.pairs[idx], self.cond[idx] = pairs, cond
        self.pos = int((self.pos + n) % self.capacity)
        self.size = min(self.capacity, self.size + n)

    def sample(self, n: int, generator: torch.Generator | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """n stored (pair, blend) rows, uniformly; the indices come from `generator` (a CPU generator)."""
        idx = torch.randint(0, max(self.size, 1), (n,), generator=generator).to(self.pairs.device)
        return self.pairs[idx], self.cond[idx]

    def state_dict(self) -> dict:
        n = self.size
        return {
            "pairs": self.pairs[:n].to("cpu", copy=True),
            "cond": self.cond[:n].to("cpu", copy=True),
            "pos": self.pos,
            "size": n,
        }

    def load_state_dict(self, s: dict) -> None:
        n = int(s["size"])
        self.pairs[:n], self.cond[:n] = s["pairs"], s["cond"]
        self.size, self.pos = n, int(s["pos"])
