"""Step a CgailEnv with a policy's deterministic mean actions: the one rollout loop of evaluation
(rollouts.py, fidelity.py), export and play (export.py), the push study (push.py) and the pins (pins.py).

Time is counted in control steps of the env (`env.cfg.control_hz`, 30 Hz for the shipped runs): step `t`
(0-based) takes the character from time t / hz to (t + 1) / hz seconds, i.e. from recorded frame t to
frame t + 1 when the reset state is frame 0.

This module imports no loader and no training module (the training loop imports fidelity.py, which
steps its envs here), only numpy and torch.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

if TYPE_CHECKING:
    from charctl.experiments.cgail.agent import Agent
    from charctl.experiments.cgail.env import CgailEnv, StepResult

# force(t) -> (world-frame wrench (N, nbody, 6) or None, physics substeps it is held for)
ForceSchedule = Callable[[int], tuple[np.ndarray | None, int]]


@torch.no_grad()
def mean_action(agent: Agent, env: CgailEnv) -> np.ndarray:
    """(N, 28) mean actions (PD-target offsets, the policy's action units) of `agent`'s policy on the
    env's current state and, for cGAIL, its command blend; computed on the device the policy sits on
    and returned as float64 on the host."""
    device = next(agent.model.parameters()).device
    obs = torch.as_tensor(env.state, dtype=torch.float32, device=device)
    cond = torch.as_tensor(env.command_blend(), dtype=torch.float32, device=device) if agent.conditional else None
    return agent.model.mean_action(obs, cond).float().cpu().numpy().astype(np.float64)


@dataclass(frozen=True)
class PolicyStep:
    """One control step taken by `policy_steps`."""

    t: int  # control step index: the step from t / hz to (t + 1) / hz s
    obs: np.ndarray  # (N, 133) disc observation o_t before the step (the first half of the step's pair)
    before: Any  # what `before_step(t)` returned (None without a `before_step`)
    result: StepResult  # env.step's result: result.pair_next is o_t+1, result.state the next policy state


def policy_steps(
    agent: Agent,
    env: CgailEnv,
    steps: int | None = None,
    *,
    before_step: Callable[[int], Any] | None = None,
    force: ForceSchedule | None = None,
) -> Iterator[PolicyStep]:
    """Step `env` with `agent`'s mean actions, yielding a `PolicyStep` after each control step.

    `steps`: the number of control steps (None: no end; stop by leaving the loop, which takes no
    further step). Before step t, in this order: `before_step(t)` (command changes; its return value
    is yielded as `PolicyStep.before`), a copy of `env.obs` is taken, `force(t)` gives the external
    wrench and its substeps (`env.step`'s `force`, `force_substeps`; default: none), and the mean
    action is computed from the env's state and command blend at that moment. Nothing here draws
    from any random generator; the env draws what its own step draws."""
    for t in itertools.count() if steps is None else range(steps):
        before = before_step(t) if before_step is not None else None
        obs = env.obs.copy()
        wrench, substeps = force(t) if force is not None else (None, 0)
        result = env.step(mean_action(agent, env), force=wrench, force_substeps=substeps)
        yield PolicyStep(t, obs, before, result)
