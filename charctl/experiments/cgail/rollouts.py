"""Rollouts of `charctl eval` for cgail (charctl/experiments/cgail/evaluate.py): a trained run whose policy
and discriminator sit on a torch device, and the episodes each evaluation mode records with it.

Policy and discriminator inference runs on the torch device of `device` (each run's config, or a
`device=cpu|cuda|auto` override on the command line); the simulator stays on the host, and only
actions, probabilities and rewards come back from the device. What is computed from the recordings is
in metrics.py, what is written in report.py.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from charctl.errors import CharctlError
from charctl.experiments.cgail.discriminator import blended_class_reward, style_reward
from charctl.experiments.cgail.drive import policy_steps
from charctl.experiments.cgail.env import CgailEnv
from charctl.experiments.cgail.policy import TrainedRun, load_trained_run, local_joint_rotations
from charctl.progress import TrainingProgress

EVAL_OVERRIDES = ("output_root", "device")  # the only key=value overrides `charctl eval cgail` takes


@dataclass
class SkillRollout:
    """Per-episode recordings of one commanded skill."""

    local_rot: list[np.ndarray]  # each (n_i, 15, 4) until the first fall
    probs: np.ndarray | None  # (n_total, K) classifier probabilities over all recorded pairs
    r_style: np.ndarray  # (n_total,)
    falls: int


@dataclass
class DeviceRun(TrainedRun):
    """A trained run whose policy and discriminator live on torch `device` (loaded on the CPU with
    `weights_only=True`, then moved). Inputs go to the device, results come back as numpy; the inherited
    `mean_action` (drive.mean_action) runs the policy on the device its parameters sit on."""

    device: str = "cpu"

    @torch.no_grad()
    def discriminate(self, pairs: np.ndarray, cond: np.ndarray) -> tuple[torch.Tensor, torch.Tensor | None]:
        """Discriminator score d (B,) and class logits (B, K) (None for AMP) of (B, 266) (o_t, o_t+1)
        pairs whose command blend was `cond` (B, K) (read by a per-skill style head), computed and left
        on the device."""
        dev = self.device
        c = torch.as_tensor(cond, dtype=torch.float32, device=dev)
        return self.agent.disc(torch.as_tensor(pairs, dtype=torch.float32, device=dev), cond=c)

    def discriminate_for(self, pairs: np.ndarray, skill: int) -> tuple[torch.Tensor, torch.Tensor | None]:
        """`discriminate` for pairs all commanded with `skill`."""
        return self.discriminate(pairs, np.eye(len(self.agent.skills))[np.full(len(pairs), skill)])


def split_eval_overrides(overrides: list[str]) -> tuple[str | None, list[str]]:
    """(the `device=` override resolved to a torch device, or None; the other overrides). Anything
    but output_root= / device=, a bad device name or an absent CUDA device is a one-line error, raised
    before any run is loaded."""
    other = [o for o in overrides if o.split("=", 1)[0] not in EVAL_OVERRIDES]
    if other:
        raise CharctlError(f"cgail eval takes only output_root=... and device=... overrides (got {' '.join(other)})")
    devices = [o.split("=", 1)[1] for o in overrides if o.split("=", 1)[0] == "device"]
    rest = [o for o in overrides if o.split("=", 1)[0] != "device"]
    return (eval_device(devices[-1]) if devices else None), rest


def eval_device(name: str) -> str:
    """The torch device `name` (auto | cpu | cuda | cuda:N) stands for: auto -> cuda when available,
    else cpu; a bad name or a missing CUDA device is a one-line CharctlError."""
    from charctl.config import resolve_device

    return resolve_device(str(name))


def load_eval_run(run_dir: str | Path, device: str | None = None, checkpoint: str | None = None) -> DeviceRun:
    """The run's agent with its policy and discriminator on torch `device` (None: the run's configured
    `device`, resolved). The checkpoint is read with `torch.load(weights_only=True,
    map_location="cpu")`: its random-number states must stay CPU ByteTensors for
    `torch.set_rng_state`; only the two inference networks move to the device."""
    tr = load_trained_run(run_dir, checkpoint)
    dev = device if device is not None else eval_device(str(tr.cfg.get("device", "auto")))
    tr.agent.model.to(dev)
    tr.agent.disc.to(dev)
    return DeviceRun(tr.run_dir, tr.cfg, tr.agent, device=dev)


@torch.no_grad()
def rollout_skill(tr: DeviceRun, skill: int, episodes: int, seconds: float, seed: int = 0) -> SkillRollout:
    """`episodes` envs commanded with `skill` (mean actions, RSI at frame 0, no switching)."""
    env = tr.held_env(np.full(episodes, skill), seconds + 1.0, seed=seed)
    steps = int(round(seconds * env.cfg.control_hz))
    alive = np.ones(episodes, dtype=bool)
    rots = [local_joint_rotations(env)]  # (N, 15, 4) per frame: the start, then after each step
    recorded = np.ones(episodes, dtype=np.int64)  # frames of `rots` each env keeps: until its first fall
    pairs, falls = [], 0
    for step in policy_steps(tr.agent, env, steps):
        res = step.result
        rec = alive.copy()
        pairs.append(np.concatenate([step.obs, res.pair_next], axis=1)[rec])
        fell = res.terminated & alive
        falls += int(fell.sum())
        alive &= ~res.terminated
        rots.append(local_joint_rotations(env))
        recorded += alive
        if not alive.any():
            break
    d, logits = tr.discriminate_for(np.concatenate(pairs), skill)

    probs = F.softmax(logits, -1).cpu().numpy() if logits is not None else None
    r_style = style_reward(d).cpu().numpy()
    rots = np.stack(rots, axis=1)  # (N, T + 1, 15, 4); alive only shrinks, so each env keeps a prefix
    return SkillRollout([r[:n] for r, n in zip(rots, recorded, strict=True)], probs, r_style, falls)


@torch.no_grad()
def survival_rollout(tr: DeviceRun, skill: int, episodes: int, seconds: float, seed: int = 0) -> dict:
    """`episodes` envs held on `skill` for `seconds` (mean actions, RSI at random clip frames and
    random headings, no command switches). Returns the fraction that never fell and, for cGAIL,
    the classifier's accuracy on the policy's pairs up to each env's first fall."""
    env = tr.make_env(episodes, seed=seed, switch_prob=0.0, episode_seconds=seconds + 1.0)
    env.forced_command = np.full(episodes, skill)
    env.reset(np.arange(episodes))
    alive = np.ones(episodes, dtype=bool)
    hits, total = torch.zeros((), dtype=torch.long, device=tr.device), 0  # hits stay on the device until the end
    for step in policy_steps(tr.agent, env, int(round(seconds * env.cfg.control_hz))):
        res = step.result
        if tr.agent.conditional:
            _, logits = tr.discriminate_for(np.concatenate([step.obs, res.pair_next], axis=1)[alive], skill)
            hits += (logits.argmax(-1) == skill).sum()
            total += int(alive.sum())
        alive &= ~res.terminated
    out = {"episodes": episodes, "seconds": seconds, "no_fall": float(alive.mean())}
    if tr.agent.conditional:
        out["class_acc_policy"] = int(hits) / max(total, 1)
    return out


@dataclass
class SwitchRecording:
    """The trials of one condition of the switch study (command A, then B at frame `t_switch`), T frames."""

    probs: np.ndarray  # (T, N, K) classifier probabilities of each step's pair
    r_style: np.ndarray  # (T, N)
    r_class: np.ndarray  # (T, N) control reward of the blended command
    alive_hist: np.ndarray  # (T, N) alive before each step
    alive: np.ndarray  # (N,) alive at the end
    alive_at_switch: np.ndarray  # (N,) alive when the command switched
    pos_after: np.ndarray  # (F, N, 15, 3) world bodies of the F frames after the switch (PERFORM window)
    rot_after: np.ndarray  # (F, N, 15, 4)

    def pair(self, p: int, trials: int) -> SwitchRecording:
        """Pair `p`'s `trials` envs only, of a batched `switch_rollout` (pair-major: envs p * trials to
        (p + 1) * trials - 1)."""
        envs = slice(p * trials, (p + 1) * trials)
        return SwitchRecording(
            self.probs[:, envs],
            self.r_style[:, envs],
            self.r_class[:, envs],
            self.alive_hist[:, envs],
            self.alive[envs],
            self.alive_at_switch[envs],
            self.pos_after[:, envs],
            self.rot_after[:, envs],
        )


def switch_at(env: CgailEnv, kb, t_switch: int, ramp: int) -> Callable[[int], tuple[np.ndarray, ...]]:
    """`before_step` of the switch study: at control step `t_switch` every env is commanded `kb` (one skill index,
    or (N,) one per env; ramped when `ramp` > 0); each step's command state (A, B, w, blend c̄), read before the
    step, is returned."""
    kb = np.broadcast_to(np.asarray(kb, dtype=np.int64), (env.N,)).copy()

    def before_step(t: int) -> tuple[np.ndarray, ...]:
        if t == t_switch:
            env.set_command(np.arange(env.N), kb, ramp=ramp > 0)
            env.forced_command = kb
        return env.prev_cmd.copy(), env.cmd.copy(), env.w.copy(), env.command_blend()

    return before_step


@torch.no_grad()
def switch_rollout(
    tr: DeviceRun,
    ka,
    kb,
    trials: int,
    ramp: int,
    t_switch: int,
    t_end: int,
    perform_frames: int,
    progress: TrainingProgress | None = None,
) -> SwitchRecording:
    """`trials` envs per pair commanded with skill `ka`, switched to `kb` at frame `t_switch` (over `ramp` frames,
    0: at once), recorded until frame `t_end`; bodies kept for the `perform_frames` after the switch. `ka`, `kb`:
    one pair of skill indices, or P pairs as (P,) arrays, all rolled out at once in P x `trials` envs, pair-major
    (`SwitchRecording.pair` cuts out one pair's trials). `progress`, when given, advances by one per control step."""
    hz = tr.cfg.env.control_hz
    episode_seconds = t_end / hz + 1.0
    ka, kb = (np.repeat(np.atleast_1d(np.asarray(k, dtype=np.int64)), trials) for k in (ka, kb))
    env = tr.held_env(ka, episode_seconds, seed=7, ramp_frames=ramp)
    probs, rs, rc, alive_hist, pos_after, rot_after = [], [], [], [], [], []
    alive = np.ones(env.N, dtype=bool)
    for step in policy_steps(tr.agent, env, t_end, before_step=switch_at(env, kb, t_switch, ramp)):
        t, res, (cmd_a, cmd_b, w, blend) = step.t, step.result, step.before
        if t == t_switch:
            alive_at_switch = alive.copy()
        d, logits = tr.discriminate(np.concatenate([step.obs, res.pair_next], axis=1), blend)
        p = F.softmax(logits, -1)
        r_c = blended_class_reward(
            p,
            torch.from_numpy(cmd_a).to(tr.device),
            torch.from_numpy(cmd_b).to(tr.device),
            torch.from_numpy(w).float().to(tr.device),
            len(tr.skill_names),
            tr.cfg.reward.class_form,
        )
        probs.append(p)  # device tensors; to the host once, after the episode
        rs.append(style_reward(d))
        rc.append(r_c)
        alive_hist.append(alive.copy())
        alive &= ~res.terminated
        if t_switch <= t < t_switch + perform_frames:  # bodies after the step, for the peaks
            pos_after.append(env.sim.body_pos.copy())
            rot_after.append(env.sim.body_quat_xyzw.copy())
        if progress is not None:
            progress.update(1)
    probs, rs, rc = (torch.stack(x).cpu().numpy() for x in (probs, rs, rc))
    return SwitchRecording(
        probs, rs, rc, np.array(alive_hist), alive, alive_at_switch, np.array(pos_after), np.array(rot_after)
    )
