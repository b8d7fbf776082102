"""cgail rollouts: `rollout_steps` control steps of every env with one batched policy forward per
step, recorded as a `Rollout` (policy storage, discriminator pairs, commands, goal and tracking
rewards, truncation bootstraps, episode counters). The CPU env (numpy) and the device env
(env.backend=warp, everything stays on the device) have a collector each."""

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
        if getattr(env, "on_device", False):  # env.backend=warp: everything stays on the device
            return _collect_rollout_device(agent, env, steps, deterministic, terminate)
        return _collect_rollout(agent, env, steps, deterministic, terminate)
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


def _collect_rollout(
    agent: Agent, env: CgailEnv, steps: int, deterministic: bool, terminate: LowStyleTermination | None = None
) -> Rollout:
    """`collect_rollout` for the CPU env (`CgailEnv`): numpy arrays go to the learner's device each step."""
    N = env.N
    dev = torch.device(agent.device)  # the CPU env's numpy arrays go to the learner's device (no-op on the CPU)
    ro = _empty_rollout(agent, steps, N, env.state_dim, dev)
    for t in range(steps):
        obs = torch.as_tensor(env.state, dtype=torch.float32, device=dev)
        blend = torch.as_tensor(env.command_blend(), dtype=torch.float32, device=dev)
        cond = blend if agent.conditional else None
        action, logp, value = agent.model.act(obs, cond, deterministic=deterministic)
        o_t = env.obs.copy()
        ro.cmd_a[t], ro.cmd_b[t], ro.w[t], ro.cond[t] = (
            torch.from_numpy(env.prev_cmd),
            torch.from_numpy(env.cmd),
            torch.from_numpy(env.w),
            blend,
        )
        steps_before = env.steps.copy()
        res = env.step(action.cpu().numpy().astype(np.float64))
        ro.pairs[t] = torch.from_numpy(np.concatenate([o_t, res.pair_next], axis=1))
        ro.r_goal[t] = torch.from_numpy(res.r_goal)
        ro.r_track[t] = torch.from_numpy(res.r_track)
        done = res.terminated | res.truncated
        if terminate is not None:
            done = _end_low_style_episodes(ro, t, env, terminate, blend, done)
        if res.truncated.any():
            _bootstrap_truncated(agent, ro, t, res, blend)
        ro.storage.add(obs, cond, action, logp, value, torch.zeros(N, device=dev), torch.from_numpy(done).to(dev))
        _count_episode_ends(ro, res, done, steps_before)
    return ro


def _end_low_style_episodes(
    ro: Rollout, t: int, env: CgailEnv, terminate: LowStyleTermination, blend: torch.Tensor, done: np.ndarray
) -> np.ndarray:
    """Episodes whose style reward stayed low end here (reset, no bootstrap): `done` with them added."""
    ended = terminate.update(ro.pairs[t], blend, torch.from_numpy(done).to(ro.pairs.device)).cpu().numpy()
    if ended.any():
        env.reset(np.flatnonzero(ended))
        done = done | ended
        ro.style_ends += int(ended.sum())
    return done


def _bootstrap_truncated(agent: Agent, ro: Rollout, t: int, res, blend: torch.Tensor) -> None:
    """gamma * V(final state) of the envs truncated at step `t`, into `ro.bootstrap[t]`."""
    dev = ro.bootstrap.device
    idx = np.flatnonzero(res.truncated)
    fs = torch.as_tensor(res.final_state[idx], dtype=torch.float32, device=dev)
    with torch.no_grad():
        v_final = agent.model.value(fs, blend[idx] if agent.conditional else None)
    ro.bootstrap[t, torch.as_tensor(idx, device=dev)] = agent.cfg.ppo.gamma * v_final


def _count_episode_ends(ro: Rollout, res, done: np.ndarray, steps_before: np.ndarray) -> None:
    """Episode lengths of the envs `done` this step, and the unstable, fall and pose-error counters."""
    ro.episode_lengths += list(steps_before[done] + 1)
    ro.unstable += int(res.unstable.sum())
    pose_ended = res.pose_ended if res.pose_ended is not None else np.zeros(len(done), dtype=bool)
    ro.falls += int((res.terminated & ~res.unstable & ~pose_ended).sum())
    ro.pose_ends += int(pose_ended.sum())


def _collect_rollout_device(
    agent: Agent, env, steps: int, deterministic: bool, terminate: LowStyleTermination | None = None
) -> Rollout:
    """`_collect_rollout` for the torch env (`env.CgailEnv` on torch: env.backend=warp or torch): every buffer lives on
    the env's device and the loop never reads a value back to the host (the low-style termination resets
    by mask). Truncated envs' final states
    are kept and bootstrapped with one critic forward after the loop (same parameters as during the
    loop, so the same values); episode lengths and counters are read once per rollout."""
    N = env.N
    dev = env.device
    ro = _empty_rollout(agent, steps, N, env.state_dim, dev)
    final_states = torch.zeros(steps, N, env.state_dim, device=dev)
    truncated = torch.zeros(steps, N, dtype=torch.bool, device=dev)
    ended = torch.zeros(steps, N, dtype=torch.bool, device=dev)
    ep_len = torch.zeros(steps, N, dtype=torch.long, device=dev)
    unstable = torch.zeros((), dtype=torch.long, device=dev)
    falls = torch.zeros((), dtype=torch.long, device=dev)
    pose_ends = torch.zeros((), dtype=torch.long, device=dev)
    style_ends = torch.zeros((), dtype=torch.long, device=dev)
    zeros = torch.zeros(N, device=dev)
    no_pose_end = torch.zeros(N, dtype=torch.bool, device=dev)
    for t in range(steps):
        obs = env.state
        blend = env.command_blend()
        cond = blend if agent.conditional else None
        action, logp, value = agent.model.act(obs, cond, deterministic=deterministic)
        o_t = env.obs
        ro.cmd_a[t], ro.cmd_b[t], ro.w[t], ro.cond[t] = env.prev_cmd, env.cmd, env.w, blend
        steps_before = env.steps
        res = env.step(action)
        ro.pairs[t] = torch.cat([o_t, res.pair_next], dim=1)
        ro.r_goal[t], ro.r_track[t] = res.r_goal, res.r_track
        done = res.terminated | res.truncated
        if terminate is not None:  # low style for too long: reset now (the mask may be all false)
            low = terminate.update(ro.pairs[t], blend, done)
            if not env.compact_rows or bool(low.any()):  # on the CPU a host read is cheaper than an empty reset
                env.reset(low)
            done = done | low
            style_ends += low.sum()
        final_states[t], truncated[t], ended[t] = res.final_state, res.truncated, done
        ep_len[t] = steps_before + 1
        ro.storage.add(obs, cond, action, logp, value, zeros, done)
        pose_ended = res.pose_ended if res.pose_ended is not None else no_pose_end
        unstable += res.unstable.sum()
        falls += (res.terminated & ~res.unstable & ~pose_ended).sum()
        pose_ends += pose_ended.sum()
    if bool(truncated.any()):  # the rollout's only host reads: this, the lengths and the two counters
        with torch.no_grad():
            v_final = agent.model.value(final_states[truncated], ro.cond[truncated] if agent.conditional else None)
        ro.bootstrap[truncated] = agent.cfg.ppo.gamma * v_final
    ro.episode_lengths, ro.unstable, ro.falls = ep_len[ended].tolist(), int(unstable), int(falls)
    ro.pose_ends, ro.style_ends = int(pose_ends), int(style_ends)
    return ro
