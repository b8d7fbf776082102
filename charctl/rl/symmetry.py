"""A left/right mirror of a policy's inputs and actions, and the symmetry (mirror) loss of PPO.

The mirror is linear and given as index permutations with signs: mirrored x = x[..., perm] * sign. An
experiment builds it from its own layouts (cgail: `charctl.experiments.cgail.symmetry`); this module only
applies it. The command vector is permuted (a skill whose clip is the mirror of another's swaps with it),
and the loss is taken only on the samples whose command lies wholly on such mirrored pairs: for them the
mirrored state under the partner command is a state of the same task, so the mirrored action is the right
answer there (Yu, Turk and Liu 2018, "Learning symmetric and low-energy locomotion"; rsl_rl's mirror loss).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch


@dataclass(frozen=True)
class Mirror:
    """Index permutations and signs of the mirror of the policy state, the command and the action.

    `obs_perm`, `obs_sign` (obs_dim,); `cond_perm` (K,) each skill's mirror partner (itself if none);
    `cond_paired` (K,) bool, the skills that have a partner; `act_perm`, `act_sign` (act_dim,).
    Numpy arrays: `to(device)` gives the torch copy that `obs`, `cond`, `actions` and `applies` use."""

    obs_perm: np.ndarray | torch.Tensor
    obs_sign: np.ndarray | torch.Tensor
    cond_perm: np.ndarray | torch.Tensor
    cond_paired: np.ndarray | torch.Tensor
    act_perm: np.ndarray | torch.Tensor
    act_sign: np.ndarray | torch.Tensor

    def to(self, device: str | torch.device) -> Mirror:
        """The same mirror as torch tensors on `device` (permutations int64, signs float32, paired bool)."""

        def t(x, dtype):
            return torch.as_tensor(np.asarray(x), dtype=dtype, device=device)

        i64, f32 = torch.int64, torch.float32
        return Mirror(
            t(self.obs_perm, i64),
            t(self.obs_sign, f32),
            t(self.cond_perm, i64),
            t(self.cond_paired, torch.bool),
            t(self.act_perm, i64),
            t(self.act_sign, f32),
        )

    def obs(self, obs: torch.Tensor) -> torch.Tensor:
        """(..., obs_dim) mirrored policy states (raw, before the policy's normaliser)."""
        return obs[..., self.obs_perm] * self.obs_sign

    def cond(self, cond: torch.Tensor) -> torch.Tensor:
        """(..., K) command vectors (one-hot or a blend) with each skill's weight moved to its partner."""
        out = torch.empty_like(cond)
        out[..., self.cond_perm] = cond
        return out

    def actions(self, actions: torch.Tensor) -> torch.Tensor:
        """(..., act_dim) mirrored actions."""
        return actions[..., self.act_perm] * self.act_sign

    def applies(self, cond: torch.Tensor) -> torch.Tensor:
        """(...,) bool: the command's weight lies wholly on skills with a mirror partner (within 1e-6)."""
        return (cond * self.cond_paired.to(cond.dtype)).sum(-1) > 1.0 - 1e-6


def mirror_loss(mirrored_mean: torch.Tensor, mean: torch.Tensor, mirror: Mirror) -> torch.Tensor:
    """Mean squared difference (action units^2, averaged over samples and action dimensions) between the
    action means on the mirrored inputs and the mirror of the action means on the inputs themselves. The
    target is detached (as rsl_rl does), so each sample pulls its partner's output towards its own mirror
    image; a policy that is symmetric on these samples scores 0. Empty batches score 0."""
    if mean.shape[0] == 0:
        return mean.new_zeros(())
    return (mirrored_mean - mirror.actions(mean).detach()).square().mean()
