"""Early termination on a low style reward (reward.low_style_threshold; docs/cgail.md, "Fidelity recipe").

ProtoMotions' AMP ends an episode once the discriminator's reward has stayed low for several control
steps, against the "stand still" optimum: without it, a pose the discriminator rejects still pays every
step it survives, so standing is safer than a kick. Here an episode ends (a termination, no bootstrap,
not counted as a fall) when r_S of its pairs, scored for its own command, stayed below `threshold` for
`steps` consecutive control steps.

The rollout scores the pairs with a snapshot of the discriminator (`sync` at each iteration's start),
because with the overlapped loop the training discriminator is updated in another thread meanwhile.
"""

from __future__ import annotations

import torch

from charctl.experiments.cgail.discriminator import Discriminator, frozen_copy, style_reward


class LowStyleTermination:
    def __init__(self, disc: Discriminator, num_envs: int, threshold: float, steps: int):
        self.disc = frozen_copy(disc)  # spectral norms computed once per snapshot, not per step
        self.threshold, self.steps = float(threshold), int(steps)
        self.low = torch.zeros(num_envs, dtype=torch.long, device=next(disc.parameters()).device)

    def sync(self, disc: Discriminator) -> None:
        """Take the training discriminator's current parameters (call while no update is running)."""
        self.disc = frozen_copy(disc)

    @torch.no_grad()
    def update(self, pairs: torch.Tensor, cond: torch.Tensor, done: torch.Tensor) -> torch.Tensor:
        """(N,) bool: envs whose episode this step's pairs (N, 266) under command blend `cond` (N, K)
        end. `done` (N,) bool: episodes that ended anyway this step (their counts restart)."""
        d, _ = self.disc(pairs, cond=cond)
        low = style_reward(d) < self.threshold
        self.low = torch.where(low, self.low + 1, torch.zeros_like(self.low))
        end = (self.low >= self.steps) & ~done
        self.low[done | end] = 0
        return end
