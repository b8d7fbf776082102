"""The cgail environment in torch: `CgailEnv`'s rules on MuJoCo Warp (env.backend=warp) or, on the CPU, over
C MuJoCo's arrays seen as tensors (env.backend=torch, `charctl.sim.torch_view.TorchBatchedHumanoid`).

Same episode logic as `env.CgailEnv` (docs/cgail.md); the rules themselves are `features.py`, `rules.py` and
`start_frames.py`, shared with the CPU env.
Every per-env quantity is a tensor on the simulation device and every branch that depends on
data is a mask (`torch.where`), so a control step issues no host round trip: resets run for a
(possibly all-false) mask each step, with RSI candidates drawn for every env and written only
where the mask is set. On the CPU (env.backend=torch, or Warp's CPU device), where reading a mask
costs nothing, the work for such a subset runs on its rows only (`compact_rows`, `env_rows.py`: the resets and
the closest-frame search of the pose error, as the numpy env does), with the same random numbers drawn.
Random numbers come from a torch generator on the device (seeded), so the two backends give equally
distributed, not identical, episodes.

Units and frames: radians (yaw about world +y, PD targets), metres, m/s; world y-up.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from charctl.config import plain_section
from charctl.experiments.cgail import start_frames
from charctl.experiments.cgail.env_rows import IndexRows, MaskRows, pad_skill_tables
from charctl.experiments.cgail.env_rules import env_reference_check
from charctl.experiments.cgail.features import DISC_OBS_DIM, Kinematics, disc_obs, heading_frame, policy_state
from charctl.experiments.cgail.rules import (
    advance_ramp,
    advance_reference,
    count_down_grace,
    episode_end,
    goal_features,
    goal_reference_frame,
    goal_reward,
    phase_features,
    pose_key_error_frames,
    pose_keys,
    reference_pose_error,
    restart_after_ramp,
    root_height_scale,
    skill_probabilities,
    state_dim,
    switch_commands,
    tracking_reward,
    update_fall_rates,
    yaw_scale,
)
from charctl.experiments.cgail.skills import SkillData
from charctl.experiments.cgail.step_result import StepResult
from charctl.experiments.cgail.warp_kinematics import sim_kinematics
from charctl.motion import rotations_torch as RT
from charctl.sim.batch import SimSettings


class CgailDeviceEnv:
    """Batched multi-skill imitation env on `WarpBatchedHumanoid` (default) or `sim` (e.g. a
    `TorchBatchedHumanoid`); the public surface of `CgailEnv` (state, obs, command_blend, cmd, prev_cmd,
    w, steps, step, reset, set_command) with tensors. Features and rules run in the simulator's float
    dtype (`sim.dtype`, float32 when absent); `state` and `obs` are float32 (the networks' inputs)."""

    on_device = True

    def __init__(
        self,
        skills: list[SkillData],
        env_cfg,
        seed: int = 0,
        conditional: bool = True,
        tracking: bool = False,
        pose_error_threshold: float = 0.0,
        pose_error_grace_steps: int = 10,
        root_height_threshold: float = 0.0,
        yaw_error_threshold: float = 0.0,
        goal_reference_window: int = 0,
        reference_reward: bool = False,
        device: str | torch.device = "cpu",
        sim=None,
    ):
        from charctl.sim.warp_batch import WarpBatchedHumanoid

        self.skills = skills
        self.cfg = env_cfg = plain_section(env_cfg)  # typed fields, cheap reads in the step loop
        self.tracking = tracking  # phase in the state, reference frame advanced every step
        # as CgailEnv: the pose-error check against the clip's timed reference, r_track there, env.phase_obs
        self.pose_threshold, self.pose_grace = float(pose_error_threshold), int(pose_error_grace_steps)
        self.root_scale = root_height_scale(self.pose_threshold, float(root_height_threshold))
        self.yaw_scale = yaw_scale(self.pose_threshold, float(yaw_error_threshold))  # 0: no heading check
        self.goal_window = int(goal_reference_window)  # 0: heading-goal skills scored against the closest frame
        self.reference_reward = bool(reference_reward)
        self.phase_obs = bool(getattr(env_cfg, "phase_obs", False)) and not tracking
        self.timed_reference = self.pose_threshold > 0 or self.phase_obs  # reference advanced, restarting at frame 0
        self.conditional = conditional
        self.K = len(skills)
        self.N = int(env_cfg.num_envs)
        self.device = dev = torch.device(device)
        self.generator = torch.Generator(device=dev).manual_seed(int(seed))
        self.sim = sim or WarpBatchedHumanoid(
            self.N,
            SimSettings.of(env_cfg),
            device=dev,
        )
        self.device = dev = self.sim.device
        # the simulator's float dtype: float32 on MuJoCo Warp, float64 over C MuJoCo (env.backend=torch,
        # `charctl.sim.torch_view`); features and rules run in it, the policy state and disc obs are float32
        self.dtype = getattr(self.sim, "dtype", torch.float32)
        # on the CPU (reading a mask there is free) the work for a data-dependent subset of the envs runs on those
        # rows only, as in the numpy env: the resets (the kinematics and features of every env cost as much as a
        # step's) and the closest-frame search of the pose error; on a GPU it stays in mask form (no host round trip)
        self.compact_rows = dev.type == "cpu"
        self.max_steps = int(round(env_cfg.episode_seconds * env_cfg.control_hz))
        self._load_skill_tables(skills)
        self.rest = torch.zeros(self.sim.layout.nu, dtype=self.dtype, device=dev)
        self.state_dim = state_dim(tracking or self.phase_obs)
        self.obs_dim = self.state_dim
        self._init_env_state()
        self.reset(torch.ones(self.N, dtype=torch.bool, device=dev))

    def _init_env_state(self) -> None:
        """The per-env state on the device before the first reset: commands, ramp weights, step counts,
        heading goals, reference frames and checks, fall rates per skill, evaluation overrides, and
        the state / observation buffers (zeros; `reset` of every env fills them)."""
        dev = self.device
        f32 = dict(dtype=torch.float32, device=dev)
        i64 = dict(dtype=torch.long, device=dev)
        self.cmd = torch.zeros(self.N, **i64)  # B: current command
        self.prev_cmd = torch.zeros(self.N, **i64)  # A: previous command
        self.w = torch.ones(self.N, **f32)  # ramp weight
        self.steps = torch.zeros(self.N, **i64)
        self.goal_angle = torch.zeros(self.N, **f32)  # world yaw of the heading goal (radians about +y)
        self.ref_frame = torch.zeros(self.N, **i64)  # reference clip frame at the current phase
        self.ref_active = torch.ones(self.N, dtype=torch.bool, device=dev)  # reference valid (off during a switch)
        self.ref_grace = torch.zeros(self.N, **i64)  # pose-error check: steps left without a check
        self.yaw_err = torch.zeros(self.N, **f32)  # reward.yaw_error_threshold: heading gained on the reference (rad)
        self.fall_rate = torch.full((self.K,), 0.5, dtype=torch.float64, device=dev)  # env.skill_fall_weight
        # env.start_failure_weight: failures per skill and reference frame (start_frames.py)
        self.frame_failures = torch.zeros(
            self.K, int(self.clip_frames.max()), dtype=torch.float64, device=dev
        )  # by frame
        self.forced_command: torch.Tensor | None = None  # evaluation: fixed command per env (-1 = random)
        self.start_frame: int | None = None
        self.random_yaw = True
        self._falls = torch.zeros((), **i64)
        self._state = torch.zeros(self.N, self.state_dim, **f32)
        self._obs = torch.zeros(self.N, DISC_OBS_DIM, **f32)

    def _load_skill_tables(self, skills: list[SkillData]) -> None:
        """Per-skill tables on the device: RSI states and reference observations (padded to the longest clip
        with its last row), clip lengths, looping, heading goals and mean speeds (m/s)."""
        dev, dt = self.device, self.dtype
        self.rsi_qpos = pad_skill_tables([s.qpos for s in skills], dev, dt)  # (K, T, nq)
        self.rsi_qvel = pad_skill_tables([s.qvel for s in skills], dev, dt)  # (K, T, nv)
        self.ref_obs = pad_skill_tables([s.obs for s in skills], dev, dt)  # (K, T, 133)
        self.ref_keys = pose_keys(self.ref_obs)  # (K, T, 13): what the pose error compares
        self.ref_keys_t = self.ref_keys.transpose(1, 2).contiguous()  # (K, 13, T): frames last (closest-frame search)
        self.clip_frames = torch.as_tensor([len(s.obs) for s in skills], dtype=torch.long, device=dev)
        self.rsi_frames = torch.as_tensor([len(s.qpos) for s in skills], dtype=torch.long, device=dev)
        self.clip_loops = torch.as_tensor([s.loop for s in skills], dtype=torch.bool, device=dev)
        self.has_goal = torch.as_tensor([s.heading_goal for s in skills], dtype=torch.bool, device=dev)
        self.speed = torch.as_tensor([s.mean_speed for s in skills], dtype=dt, device=dev)
        lead = start_frames.lead_window_index(
            self.clip_frames.cpu(), self.clip_loops.cpu(), self.cfg.start_failure_lead
        )
        self._lead = tuple(torch.as_tensor(a, device=dev) for a in lead)  # each start frame's lead window

    # ------------------------------------------------------------------ random numbers
    def _rand(self) -> torch.Tensor:
        """(N,) uniform in [0, 1), in the simulator's dtype."""
        return torch.rand(self.N, generator=self.generator, device=self.device, dtype=self.dtype)

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
        the blend goes A -> B over ramp_frames (`rules.switch_commands`; new heading goals where it changed)."""
        mask = self.sim.as_mask(mask)
        new = torch.as_tensor(skill, dtype=torch.long, device=self.device).expand(self.N)
        frames = self.cfg.ramp_frames if ramp else 0
        self.cmd, self.prev_cmd, self.w, self.ref_active, changed = switch_commands(
            self.cmd, self.prev_cmd, self.w, self.ref_active, mask, new, frames
        )
        self._new_goal(changed, self.sim.body_quat_xyzw[:, 0])

    def _advance_ramp(self) -> None:
        self.w = advance_ramp(self.w, self.cfg.ramp_frames)

    def _new_goal(self, mask: torch.Tensor, root_rot: torch.Tensor) -> None:
        self.goal_angle = torch.where(mask, self._goal(root_rot, self._rand()), self.goal_angle)

    def _goal(self, root_rot: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        """Heading goals (world yaw, rad) within goal_max_angle_deg of the heading of `root_rot`, from uniforms `u`."""
        spread = math.radians(self.cfg.goal_max_angle_deg)
        return RT.yaw_about_y(root_rot) + (2.0 * u - 1.0) * spread

    # ------------------------------------------------------------------ reset
    def reset(self, mask) -> None:
        """RSI of the envs in `mask` ((N,) bool or integer ids) from a random frame of a random skill
        (or the forced one). The random numbers are drawn for every env whatever the mask (the generator's
        stream does not depend on it); the reset envs' state is written in mask form or, on the CPU
        (`compact_rows`), for their rows only, with the same values."""
        mask = self.sim.as_mask(mask)
        skill = self._sample_skills()
        if self.forced_command is not None:
            forced = self.forced_command.to(self.device)
            skill = torch.where(forced >= 0, forced, skill)
        n_rsi = self.rsi_frames[skill]
        frames = torch.minimum(self._randint(n_rsi - 1), n_rsi - 2).clamp(min=0)  # [0, T - 1) as numpy's integers
        if self.cfg.start_failure_weight > 0:  # a share drawn towards the frames where episodes end (start_frames.py)
            weight, u = self.cfg.start_failure_weight, self._rand().double()
            frames = start_frames.draw_start_frames(self.frame_failures, self._lead, self.rsi_frames, weight, skill, u)
        if self.start_frame is not None:
            frames = torch.minimum(torch.full_like(frames, int(self.start_frame)), n_rsi - 1)
        yaw = (
            (2.0 * self._rand() - 1.0) * math.pi
            if self.random_yaw
            else torch.zeros(self.N, dtype=self.dtype, device=self.device)
        )
        goal_u = self._rand()  # the heading goals' draw
        rows = IndexRows(mask) if self.compact_rows else MaskRows(mask)
        if self.compact_rows and rows.ids.numel() == 0:
            return  # nothing to write (the mask form writes every row's old value back)
        skill, frames = rows.pick(skill), rows.pick(frames)
        qpos = self.rsi_qpos[skill, frames]  # advanced indexing: copies
        qvel = self.rsi_qvel[skill, frames]
        turn = RT.heading_quat(rows.pick(yaw))
        qpos[:, 0] = 0.0
        qpos[:, 2] = 0.0
        root = RT.wxyz_to_xyzw(qpos[:, 3:7])
        qpos[:, 3:7] = RT.xyzw_to_wxyz(RT.multiply(turn, root))
        qvel[:, :3] = RT.rotate(turn, qvel[:, :3])  # world linear velocity turns; angular is body-local
        self.sim.set_state(rows.ids, qpos, qvel)
        self.cmd = rows.put(self.cmd, skill)
        self.prev_cmd = rows.put(self.prev_cmd, skill)
        self.w = rows.put(self.w, 1.0)
        self.steps = rows.put(self.steps, 0)
        self.ref_frame = rows.put(self.ref_frame, frames)
        self.ref_active = rows.put(self.ref_active, True)
        self.ref_grace = rows.put(self.ref_grace, 0)
        self.yaw_err = rows.put(self.yaw_err, 0.0)
        k = sim_kinematics(self.sim, None if isinstance(rows, MaskRows) else rows.ids)
        self.goal_angle = rows.put(self.goal_angle, self._goal(k.body_rot[:, 0], rows.pick(goal_u)))
        state, obs = self._features(k, rows.pick)
        self._state = rows.put(self._state, state.float())
        self._obs = rows.put(self._obs, obs.float())

    # ------------------------------------------------------------------ observation
    def _features(self, k: Kinematics, pick=lambda x: x) -> tuple[torch.Tensor, torch.Tensor]:
        """(policy state (n, state_dim), disc obs (n, 133)): the shared features (`features.py`, `rules.py`)
        with one heading frame, the heading goal and, for the tracking baseline, the clip phase; of every env
        or, for a reset, of the rows `pick` takes from per-env tensors (`k` is of those rows)."""
        f = heading_frame(k)
        cmd = pick(self.cmd)
        parts = [policy_state(k, f), goal_features(pick(self.goal_angle), f.heading, self.has_goal[cmd])]
        if self.tracking or self.phase_obs:  # env.phase_obs: (0, 0) with a heading goal or while a ramp runs
            shown = (~self.has_goal[cmd] & pick(self.ref_active)) if self.phase_obs else None
            parts.append(phase_features(pick(self.ref_frame), self.clip_frames[cmd], shown).float())
        return torch.cat(parts, dim=1), disc_obs(k, f)

    def _advance_phase(self, restart: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
        """Step every env's reference frame (`rules.advance_reference`); returns (reference obs (N, 133) at the
        new frame, (N,) clip ended). With `restart` a non-looping clip starts again at 0 with grace steps."""
        cmd = self.cmd
        self.ref_frame, ended, again = advance_reference(
            self.ref_frame, self.clip_loops[cmd], self.clip_frames[cmd], restart
        )
        if restart:
            self.ref_grace = count_down_grace(self.ref_grace, again, self.pose_grace)
        return self.ref_obs[cmd, self.ref_frame], ended

    def _pose_error(self, obs: torch.Tensor, ref: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """((N,) m, (N, 133)) as `CgailEnv._pose_error`: against the timed reference `ref`, or, for skills with
        a heading goal, against their clip's closest frame (every env is scored both ways; a mask picks)."""
        timed = reference_pose_error(obs, ref, self.root_scale)
        goal = self.has_goal[self.cmd]
        rows = IndexRows(goal) if self.compact_rows else MaskRows(goal)
        cmd = rows.pick(self.cmd)
        # (n, T); padding repeats frames
        each = pose_key_error_frames(pose_keys(rows.pick(obs)), self.ref_keys_t[cmd], self.root_scale)
        if self.goal_window <= 0:
            closest, best = each.min(dim=1)
            return rows.put(timed, closest), rows.put(ref, self.ref_obs[cmd, best])
        # reward.goal_reference_window: the reference moves on from the matched frame
        synced = rows.pick(self.ref_active & (self.ref_grace == 0))
        advanced = rows.pick(self.ref_frame)
        best = goal_reference_frame(
            each, advanced, self.clip_loops[cmd], self.clip_frames[cmd], self.goal_window, synced
        )
        self.ref_frame = rows.put(self.ref_frame, best)
        closest = each.gather(1, best[:, None])[:, 0]
        return rows.put(timed, closest), rows.put(ref, self.ref_obs[cmd, best])

    def _restart_reference_after_ramp(self) -> None:
        """Envs whose command ramp has just finished: the new clip's reference starts at frame 0."""
        self.ref_frame, self.ref_grace, self.ref_active = restart_after_ramp(
            self.ref_frame, self.ref_grace, self.ref_active, self.w, self.pose_grace
        )

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
    def step(self, actions: torch.Tensor, force=None, force_substeps: int = 0) -> StepResult:
        """Apply PD targets rest + action_scale * actions (radians) for one control step; `force`
        (N, nbody, 6) world-frame push held for the first `force_substeps` physics substeps."""
        targets = self.rest + self.cfg.action_scale * torch.as_tensor(actions, dtype=self.dtype, device=self.device)
        unstable = self.sim.step(targets, force=force, force_substeps=force_substeps)
        k = sim_kinematics(self.sim)
        zeros = torch.zeros(self.N, device=self.device)
        clip_ended = no_pose_end = torch.zeros(self.N, dtype=torch.bool, device=self.device)
        if self.tracking:  # the phase in the state is the new one
            ref, clip_ended = self._advance_phase()
        elif self.timed_reference:
            ref, _ = self._advance_phase(restart=True)
        final_state, pair_next = self._features(k)
        r_track = tracking_reward(pair_next, ref) if self.tracking else zeros
        r_goal = goal_reward(
            self.goal_angle, k.com_vel, self.speed[self.cmd], self.has_goal[self.cmd], self.cfg.goal_sharpness
        )
        fell = self.sim.non_foot_ground_contact(self.cfg.fall_tolerance)
        pose_ended, scored = no_pose_end, None
        if self.pose_threshold > 0:
            r_track, pose_ended, scored = env_reference_check(self, pair_next, ref, r_track, fell, unstable)
        self.steps = self.steps + 1
        terminated, truncated = episode_end(fell, unstable, pose_ended, self.steps, self.max_steps, clip_ended)
        self._falls += fell.sum()
        done = terminated | truncated
        if self.cfg.start_failure_weight > 0:  # where in its clip each failing env was (not during a command ramp)
            args = (self.cmd, self.ref_frame, terminated & self.ref_active, self.cfg.start_failure_halflife)
            self.frame_failures = start_frames.update_frame_failures(self.frame_failures, *args)
        # a pose-error end counts as a failure of the skill, like a fall; kept whatever env.skill_fall_weight, as the
        # numpy env does (logged as fall_rate/<skill>); an all-false `done` leaves the rates as they are
        self.fall_rate = update_fall_rates(
            self.fall_rate, self.cmd, done, fell | pose_ended, self.cfg.skill_fall_halflife
        )
        # the networks' inputs in float32 (a no-op on MuJoCo Warp; over C MuJoCo the cast the numpy path makes)
        self._state, self._obs = final_state, pair_next = final_state.float(), pair_next.float()
        self._advance_ramp()
        if self.timed_reference:
            self._restart_reference_after_ramp()
        self.reset(done)
        self._maybe_switch(~done)
        return StepResult(
            self._state,
            self._obs,
            pair_next,
            final_state,
            r_goal,
            r_track,
            terminated,
            truncated,
            unstable,
            pose_ended,
            scored,
        )

    def _maybe_switch(self, mask: torch.Tensor) -> None:
        if self.K < 2 or self.cfg.switch_prob <= 0 or self.forced_command is not None:
            return
        switch = mask & (self._rand() < self.cfg.switch_prob)
        self.set_command(switch, self._sample_skills())

    def _sample_skills(self) -> torch.Tensor:
        """(N,) commands: uniform, or partly fall-weighted (env.skill_fall_weight; `rules.skill_probabilities`)."""
        if self.cfg.skill_fall_weight <= 0 or self.K < 2:
            return self._randint(self.K)
        p = skill_probabilities(self.fall_rate, self.cfg.skill_fall_weight)
        return torch.multinomial(p, self.N, replacement=True, generator=self.generator)
