"""The cgail environment on the device: `CgailEnv`'s rules on MuJoCo Warp with torch tensors (env.backend=warp).

Same episode logic as `env.CgailEnv` (docs/cgail.md): the commanded skill B, the previous one A and
the ramp weight w (eq 4.10), heading goals for locomotion skills, reference-state initialisation
(RSI) from a random frame of the commanded clip turned by a random yaw and moved to the origin,
the tracking baseline's reference phase, episode ends on a fall / a blow-up / the time limit.
Every per-env quantity is a tensor on the simulation device and every branch that depends on
data is a mask (`torch.where`), so a control step issues no host round trip: resets run for a
(possibly all-false) mask each step, with RSI candidates drawn for every env and written only
where the mask is set. Random numbers come from a torch generator on the device (seeded), so the
two backends give equally distributed, not identical, episodes.

Units and frames: radians (yaw about world +y, PD targets), metres, m/s; world y-up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from charctl.config import plain_section
from charctl.experiments.cgail.env import GOAL_DIM, PHASE_DIM
from charctl.experiments.cgail.features_torch import (
    DISC_OBS_DIM,
    STATE_DIM,
    Kinematics,
    disc_obs,
    episode_end,
    goal_reward,
    policy_state,
    sim_kinematics,
    tracking_reward,
)
from charctl.experiments.cgail.skills import SkillData
from charctl.motion import rotations_torch as RT
from charctl.sim.batch import SimSettings


@dataclass
class DeviceStepResult:
    """One control step of all envs, tensors on the device (fields as `env.StepResult`)."""

    state: torch.Tensor  # (N, state_dim) next policy state (after resets)
    obs: torch.Tensor  # (N, 133) next disc obs (after resets)
    pair_next: torch.Tensor  # (N, 133) o_t+1 of the transition just taken (before resets)
    final_state: torch.Tensor  # (N, state_dim) s_t+1 before resets (truncation bootstrapping)
    r_goal: torch.Tensor  # (N,)
    r_track: torch.Tensor  # (N,) tracking reward (0 when not tracking)
    terminated: torch.Tensor  # (N,) bool: fall or blow-up
    truncated: torch.Tensor  # (N,) bool: time limit or end of a non-looping reference clip
    unstable: torch.Tensor  # (N,) bool: simulator blow-up this step


def _pad(arrays: list[np.ndarray], device: torch.device, dtype=torch.float32) -> torch.Tensor:
    """(K, max_len, ...) tensor of per-skill arrays, each padded with its last row."""
    longest = max(len(a) for a in arrays)
    out = np.stack([np.concatenate([a, np.repeat(a[-1:], longest - len(a), axis=0)]) for a in arrays])
    return torch.as_tensor(out, dtype=dtype, device=device)


class CgailDeviceEnv:
    """Batched multi-skill imitation env on `WarpBatchedHumanoid`; the public surface of `CgailEnv`
    (state, obs, command_blend, cmd, prev_cmd, w, steps, step, reset, set_command) with tensors."""

    on_device = True

    def __init__(
        self,
        skills: list[SkillData],
        env_cfg,
        seed: int = 0,
        conditional: bool = True,
        tracking: bool = False,
        device: str | torch.device = "cpu",
        sim=None,
    ):
        from charctl.sim.warp_batch import WarpBatchedHumanoid

        self.skills = skills
        self.cfg = env_cfg = plain_section(env_cfg)  # typed fields, cheap reads in the step loop
        self.tracking = tracking
        self.conditional = conditional
        self.K = len(skills)
        self.N = int(env_cfg.num_envs)
        self.device = dev = torch.device(device)
        self.generator = torch.Generator(device=dev).manual_seed(int(seed))
        self.sim = sim or WarpBatchedHumanoid(
            self.N,
            SimSettings(physics_hz=env_cfg.physics_hz, control_hz=env_cfg.control_hz, armature=env_cfg.armature),
            device=dev,
        )
        self.device = dev = self.sim.device
        self.max_steps = int(round(env_cfg.episode_seconds * env_cfg.control_hz))
        f32 = dict(dtype=torch.float32, device=dev)
        i64 = dict(dtype=torch.long, device=dev)
        # per-skill tables on the device
        self.rsi_qpos = _pad([s.qpos for s in skills], dev)  # (K, T, nq)
        self.rsi_qvel = _pad([s.qvel for s in skills], dev)  # (K, T, nv)
        self.ref_obs = _pad([s.obs for s in skills], dev)  # (K, T, 133)
        self.clip_frames = torch.as_tensor([len(s.obs) for s in skills], **i64)
        self.rsi_frames = torch.as_tensor([len(s.qpos) for s in skills], **i64)
        self.clip_loops = torch.as_tensor([s.loop for s in skills], dtype=torch.bool, device=dev)
        self.has_goal = torch.as_tensor([s.heading_goal for s in skills], dtype=torch.bool, device=dev)
        self.speed = torch.as_tensor([s.mean_speed for s in skills], **f32)
        self.rest = torch.zeros(self.sim.layout.nu, **f32)
        # per-env state
        self.cmd = torch.zeros(self.N, **i64)  # B: current command
        self.prev_cmd = torch.zeros(self.N, **i64)  # A: previous command
        self.w = torch.ones(self.N, **f32)  # ramp weight
        self.steps = torch.zeros(self.N, **i64)
        self.goal_angle = torch.zeros(self.N, **f32)  # world yaw of the heading goal (radians about +y)
        self.ref_frame = torch.zeros(self.N, **i64)
        self.forced_command: torch.Tensor | None = None  # evaluation: fixed command per env (-1 = random)
        self.start_frame: int | None = None
        self.random_yaw = True
        self.state_dim = STATE_DIM + GOAL_DIM + (PHASE_DIM if tracking else 0)
        self.obs_dim = self.state_dim
        self._falls = torch.zeros((), **i64)
        self._state = torch.zeros(self.N, self.state_dim, **f32)
        self._obs = torch.zeros(self.N, DISC_OBS_DIM, **f32)
        self.reset(torch.ones(self.N, dtype=torch.bool, device=dev))

    # ------------------------------------------------------------------ random numbers
    def _rand(self) -> torch.Tensor:
        return torch.rand(self.N, generator=self.generator, device=self.device)

    def _randint(self, high: torch.Tensor | int) -> torch.Tensor:
        """(N,) integers uniform in [0, high) (high a scalar or per-env tensor >= 1)."""
        return torch.floor(self._rand() * high).long().clamp(min=0)

    # ------------------------------------------------------------------ commands
    def command_blend(self) -> torch.Tensor:
        """(N, K) c̄_t = (1 - w) onehot(A) + w onehot(B)."""
        w = self.w[:, None]
        return (1.0 - w) * F.one_hot(self.prev_cmd, self.K).float() + w * F.one_hot(self.cmd, self.K).float()

    def set_command(self, mask, skill, ramp: bool = True) -> None:
        """Switch the envs in `mask` ((N,) bool, or integer ids) to `skill` ((N,) or scalar); with `ramp`
        the blend goes A -> B over ramp_frames."""
        mask = self.sim.as_mask(mask)
        new = torch.as_tensor(skill, dtype=torch.long, device=self.device).expand(self.N)
        changed = mask & (new != self.cmd)
        dominant = torch.where(self.w >= 0.5, self.cmd, self.prev_cmd)
        self.prev_cmd = torch.where(changed, dominant, self.prev_cmd)
        self.cmd = torch.where(mask, new, self.cmd)
        start = 0.0 if (ramp and self.cfg.ramp_frames > 0) else 1.0
        self.w = torch.where(changed, torch.full_like(self.w, start), self.w)
        self._new_goal(changed, self.sim.body_quat_xyzw[:, 0])

    def _advance_ramp(self) -> None:
        if self.cfg.ramp_frames > 0:
            self.w = torch.clamp(self.w + 1.0 / self.cfg.ramp_frames, max=1.0)
        else:
            self.w = torch.ones_like(self.w)

    def _new_goal(self, mask: torch.Tensor, root_rot: torch.Tensor) -> None:
        spread = math.radians(self.cfg.goal_max_angle_deg)
        goal = RT.yaw_about_y(root_rot) + (2.0 * self._rand() - 1.0) * spread
        self.goal_angle = torch.where(mask, goal, self.goal_angle)

    # ------------------------------------------------------------------ reset
    def reset(self, mask) -> None:
        """RSI of the envs in `mask` ((N,) bool or integer ids) from a random frame of a random skill
        (or the forced one); candidates are drawn for every env, written where the mask is set."""
        mask = self.sim.as_mask(mask)
        skill = self._randint(self.K)
        if self.forced_command is not None:
            forced = self.forced_command.to(self.device)
            skill = torch.where(forced >= 0, forced, skill)
        n_rsi = self.rsi_frames[skill]
        frames = torch.minimum(self._randint(n_rsi - 1), n_rsi - 2).clamp(min=0)  # [0, T - 1) as numpy's integers
        if self.start_frame is not None:
            frames = torch.minimum(torch.full_like(frames, int(self.start_frame)), n_rsi - 1)
        qpos = self.rsi_qpos[skill, frames].clone()
        qvel = self.rsi_qvel[skill, frames].clone()
        yaw = (2.0 * self._rand() - 1.0) * math.pi if self.random_yaw else torch.zeros(self.N, device=self.device)
        turn = RT.heading_quat(yaw)
        qpos[:, 0] = 0.0
        qpos[:, 2] = 0.0
        root = RT.wxyz_to_xyzw(qpos[:, 3:7])
        qpos[:, 3:7] = RT.xyzw_to_wxyz(RT.multiply(turn, root))
        qvel[:, :3] = RT.rotate(turn, qvel[:, :3])  # world linear velocity turns; angular is body-local
        self.sim.set_state(mask, qpos, qvel)
        self.cmd = torch.where(mask, skill, self.cmd)
        self.prev_cmd = torch.where(mask, skill, self.prev_cmd)
        self.w = torch.where(mask, torch.ones_like(self.w), self.w)
        self.steps = torch.where(mask, torch.zeros_like(self.steps), self.steps)
        self.ref_frame = torch.where(mask, frames, self.ref_frame)
        k = sim_kinematics(self.sim)
        self._new_goal(mask, k.body_rot[:, 0])
        m = mask[:, None]
        self._state = torch.where(m, self._policy_state(k), self._state)
        self._obs = torch.where(m, disc_obs(k), self._obs)

    # ------------------------------------------------------------------ observation
    def _goal_features(self, k: Kinematics) -> torch.Tensor:
        rel = self.goal_angle - RT.yaw_about_y(k.body_rot[:, 0])
        g = torch.stack([torch.cos(rel), torch.sin(rel)], dim=1)
        return g * self.has_goal[self.cmd][:, None]

    def _phase_features(self) -> torch.Tensor:
        """(N, 2) cos/sin of the reference clip phase (tracking baseline)."""
        phase = 2.0 * math.pi * self.ref_frame / torch.clamp(self.clip_frames[self.cmd] - 1, min=1)
        return torch.stack([torch.cos(phase), torch.sin(phase)], dim=1).float()

    def _policy_state(self, k: Kinematics) -> torch.Tensor:
        parts = [policy_state(k), self._goal_features(k)]
        if self.tracking:
            parts.append(self._phase_features())
        return torch.cat(parts, dim=1)

    def _advance_phase(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Step every env's reference frame; returns (reference obs at the new frame, clip ended)."""
        last = self.clip_frames[self.cmd] - 1
        loop = self.clip_loops[self.cmd]
        nxt = self.ref_frame + 1
        self.ref_frame = torch.where(loop, nxt % torch.clamp(last, min=1), torch.minimum(nxt, last))
        ended = ~loop & (nxt >= last)
        return self.ref_obs[self.cmd, self.ref_frame], ended

    @property
    def state(self) -> torch.Tensor:
        return self._state

    @property
    def obs(self) -> torch.Tensor:
        return self._obs

    @property
    def fall_count(self) -> int:
        """Falls so far (reading it synchronises with the device)."""
        return int(self._falls)

    # ------------------------------------------------------------------ step
    def step(self, actions: torch.Tensor, force=None, force_substeps: int = 0) -> DeviceStepResult:
        """Apply PD targets rest + action_scale * actions (radians) for one control step; `force`
        (N, nbody, 6) world-frame push held for the first `force_substeps` physics substeps."""
        targets = self.rest + self.cfg.action_scale * torch.as_tensor(actions, dtype=torch.float32, device=self.device)
        unstable = self.sim.step(targets, force=force, force_substeps=force_substeps)
        k = sim_kinematics(self.sim)
        pair_next = disc_obs(k)
        if self.tracking:
            ref, clip_ended = self._advance_phase()
            r_track = tracking_reward(pair_next, ref)
        else:
            clip_ended = torch.zeros(self.N, dtype=torch.bool, device=self.device)
            r_track = torch.zeros(self.N, device=self.device)
        final_state = self._policy_state(k)
        r_goal = goal_reward(
            self.goal_angle, k.com_vel, self.speed[self.cmd], self.has_goal[self.cmd], self.cfg.goal_sharpness
        )
        fell = self.sim.non_foot_ground_contact(self.cfg.fall_tolerance)
        self.steps = self.steps + 1
        terminated, truncated = episode_end(fell, unstable, self.steps, self.max_steps, clip_ended)
        self._falls += fell.sum()
        done = terminated | truncated
        self._state, self._obs = final_state, pair_next
        self._advance_ramp()
        self.reset(done)
        self._maybe_switch(~done)
        return DeviceStepResult(
            self._state, self._obs, pair_next, final_state, r_goal, r_track, terminated, truncated, unstable
        )

    def _maybe_switch(self, mask: torch.Tensor) -> None:
        if self.K < 2 or self.cfg.switch_prob <= 0 or self.forced_command is not None:
            return
        switch = mask & (self._rand() < self.cfg.switch_prob)
        self.set_command(switch, self._randint(self.K))
