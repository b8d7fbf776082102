"""Rollout storage for on-policy training and generalised advantage estimation."""

from __future__ import annotations

import torch


def compute_gae(
    rewards: torch.Tensor,
    values: torch.Tensor,
    dones: torch.Tensor,
    last_values: torch.Tensor,
    gamma: float,
    lam: float,
) -> tuple[torch.Tensor, torch.Tensor]:
    """GAE(gamma, lambda) over a (T, N) rollout.

    delta_t = r_t + gamma * V_{t+1} * (1 - d_t) - V_t;  A_t = delta_t + gamma * lam * (1 - d_t) * A_{t+1}.
    `dones` marks the last step of an episode (terminal or truncated); truncation bootstrapping
    is folded into the reward by the caller (r += gamma * V(s_final)). Returns (advantages, returns).
    """
    T = rewards.shape[0]
    adv = torch.zeros_like(rewards)
    next_adv = torch.zeros_like(last_values)
    next_value = last_values
    for t in reversed(range(T)):  # a recursion over time: sequential by definition, vectorised over envs
        not_done = 1.0 - dones[t].float()
        delta = rewards[t] + gamma * next_value * not_done - values[t]
        next_adv = delta + gamma * lam * not_done * next_adv
        adv[t] = next_adv
        next_value = values[t]
    return adv, adv + values


class RolloutStorage:
    """(T, N) buffers of one rollout: obs, optional conditioning, actions, log-probs, values, rewards, dones."""

    def __init__(
        self, steps: int, envs: int, obs_dim: int, act_dim: int, cond_dim: int = 0, device: str | torch.device = "cpu"
    ):
        z = lambda *s: torch.zeros(*s, device=device)  # noqa: E731
        self.obs = z(steps, envs, obs_dim)
        self.cond = z(steps, envs, cond_dim)
        self.actions = z(steps, envs, act_dim)
        self.log_probs = z(steps, envs)
        self.values = z(steps, envs)
        self.rewards = z(steps, envs)
        self.dones = z(steps, envs)
        self.advantages = z(steps, envs)
        self.returns = z(steps, envs)
        self.steps, self.envs, self.t = steps, envs, 0

    def add(self, obs, cond, actions, log_probs, values, rewards, dones) -> None:
        t = self.t
        self.obs[t], self.actions[t], self.log_probs[t], self.values[t] = obs, actions, log_probs, values
        if cond is not None:
            self.cond[t] = cond
        self.rewards[t], self.dones[t] = rewards, dones
        self.t += 1

    @property
    def full(self) -> bool:
        return self.t >= self.steps

    def finish(self, last_values: torch.Tensor, gamma: float, lam: float) -> None:
        self.advantages, self.returns = compute_gae(self.rewards, self.values, self.dones, last_values, gamma, lam)

    def clear(self) -> None:
        self.t = 0

    def flat(self) -> dict[str, torch.Tensor]:
        """All buffers flattened to (T*N, ...)."""
        n = self.steps * self.envs
        return {
            k: getattr(self, k).reshape(n, *getattr(self, k).shape[2:])
            for k in ("obs", "cond", "actions", "log_probs", "values", "advantages", "returns")
        }
