"""cgail rollouts: `rollout_steps` control steps of every env with one batched policy forward per
step, recorded as a `Rollout` (policy storage, discriminator pairs, commands, goal and tracking
rewards, truncation bootstraps, episode counters), from the env in either array library (numpy on the CPU,
torch on the simulator's device) with one collector."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from charctl.experiments.cgail.agent import Agent
from charctl.experiments.cgail.env import CgailEnv
from charctl.experiments.cgail.termination import LowStyleTermination
from charctl.rl.storage import RolloutStorage


@dataclass
class Rollout:
    storage: RolloutStorage
    pairs: torch.Tensor  # (T, N, 266)
    cond: torch.Tensor  # (T, N, K) command blend c̄_t
    cmd_a: torch.Tensor  # (T, N)
    cmd_b: torch.Tensor
    w: torch.Tensor
    r_goal: torch.Tensor  # (T, N)
    r_track: torch.Tensor  # (T, N) tracking reward (zeros unless reward.kind=tracking)
    bootstrap: torch.Tensor  # (T, N) gamma * V(s_final) on truncation
    episode_lengths: list
    unstable: int
    falls: int
    style_ends: int = 0  # episodes ended by a low style reward (reward.low_style_threshold)
    pose_ends: int = 0  # episodes ended by a large pose error (reward.pose_error_threshold)


def collect_rollout(
    agent: Agent,
    env: CgailEnv,
    steps: int,
    deterministic: bool = False,
    terminate: LowStyleTermination | None = None,
) -> Rollout:
    """Step all envs `steps` times with one batched policy forward per step.

    The per-step policy forward is small (num_envs rows): it runs on one torch thread, which
    avoids thread wake-up latency that costs more than the matmul itself on a busy machine;
    MuJoCo's batch threads do the parallel work here.
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return _collect(agent, env, steps, deterministic, terminate)
    finally:
        torch.set_num_threads(threads)


def _empty_rollout(agent: Agent, steps: int, N: int, state_dim: int, dev: torch.device) -> Rollout:
    """A `Rollout` of `steps` x `N` zeros on `dev` with no episode ended yet, for a collector to fill."""
    K = agent.num_skills
    return Rollout(
        storage=RolloutStorage(steps, N, state_dim, 28, K if agent.conditional else 0, device=dev),
        pairs=torch.zeros(steps, N, agent.disc.norm.mean.shape[0], device=dev),
        cond=torch.zeros(steps, N, K, device=dev),
        cmd_a=torch.zeros(steps, N, dtype=torch.long, device=dev),
        cmd_b=torch.zeros(steps, N, dtype=torch.long, device=dev),
        w=torch.zeros(steps, N, device=dev),
        r_goal=torch.zeros(steps, N, device=dev),
        r_track=torch.zeros(steps, N, device=dev),
        bootstrap=torch.zeros(steps, N, device=dev),
        episode_lengths=[],
        unstable=0,
        falls=0,
    )


def _collect(
    agent: Agent, env: CgailEnv, steps: int, deterministic: bool, terminate: LowStyleTermination | None = None
) -> Rollout:
    """`collect_rollout` of either array library of the env: the torch env's tensors stay on its device (the loop
    never reads a value back to the host; the low-style termination resets by mask); the numpy env's arrays are
    wrapped as tensors on the learner's device each step (no copy on the CPU), the actions go back as numpy.
    Truncated envs' final states are kept and bootstrapped with one critic forward after the loop (same
    parameters as during the loop, so the same values); episode lengths and counters are read once per rollout."""
    N = env.N
    dev = env.device if env.on_device else torch.device(agent.device)
    if env.on_device:
        tensor, to_env = (lambda x, dtype=None: x if dtype is None else x.to(dtype)), (lambda x: x)
    else:
        tensor = lambda x, dtype=None: torch.as_tensor(x, dtype=dtype, device=dev)  # noqa: E731
        to_env = lambda x: x.detach().cpu().numpy().astype(np.float64)  # noqa: E731
    ro = _empty_rollout(agent, steps, N, env.state_dim, dev)
    final_states = torch.zeros(steps, N, env.state_dim, device=dev)
    truncated = torch.zeros(steps, N, dtype=torch.bool, device=dev)
    ended = torch.zeros(steps, N, dtype=torch.bool, device=dev)
    ep_len = torch.zeros(steps, N, dtype=torch.long, device=dev)
    counts = torch.zeros(4, dtype=torch.long, device=dev)  # unstable, falls, pose ends, style ends
    zeros = torch.zeros(N, device=dev)
    no_pose_end = torch.zeros(N, dtype=torch.bool, device=dev)
    for t in range(steps):
        obs = tensor(env.state, torch.float32)
        blend = tensor(env.command_blend(), torch.float32)
        cond = blend if agent.conditional else None
        action, logp, value = agent.model.act(obs, cond, deterministic=deterministic)
        o_t = tensor(env.obs)
        ro.cmd_a[t], ro.cmd_b[t], ro.w[t], ro.cond[t] = tensor(env.prev_cmd), tensor(env.cmd), tensor(env.w), blend
        steps_before = tensor(env.steps)
        res = env.step(to_env(action))
        ro.pairs[t] = torch.cat([o_t, tensor(res.pair_next)], dim=1)
        ro.r_goal[t], ro.r_track[t] = tensor(res.r_goal), tensor(res.r_track)
        terminated, unstable = tensor(res.terminated), tensor(res.unstable)
        done = terminated | tensor(res.truncated)
        if terminate is not None:  # low style for too long: reset now (the mask may be all false)
            low = terminate.update(ro.pairs[t], blend, done)
            if not env.compact_rows or bool(low.any()):  # on the CPU a host read is cheaper than an empty reset
                env.reset(low if env.on_device else low.cpu().numpy())
            done = done | low
            counts[3] += low.sum()
        final_states[t], truncated[t], ended[t] = tensor(res.final_state, torch.float32), tensor(res.truncated), done
        ep_len[t] = steps_before + 1
        ro.storage.add(obs, cond, action, logp, value, zeros, done)
        pose_ended = tensor(res.pose_ended) if res.pose_ended is not None else no_pose_end
        counts[0] += unstable.sum()
        counts[1] += (terminated & ~unstable & ~pose_ended).sum()
        counts[2] += pose_ended.sum()
    if bool(truncated.any()):  # the rollout's only host reads: this, the lengths and the counters
        with torch.no_grad():
            v_final = agent.model.value(final_states[truncated], ro.cond[truncated] if agent.conditional else None)
        ro.bootstrap[truncated] = agent.cfg.ppo.gamma * v_final
    ro.episode_lengths = ep_len[ended].tolist()
    ro.unstable, ro.falls, ro.pose_ends, ro.style_ends = (int(c) for c in counts.tolist())
    return ro
