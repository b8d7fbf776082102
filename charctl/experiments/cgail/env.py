"""Batched multi-skill imitation environment on the foundation simulator (docs/cgail.md), one implementation
for numpy on the CPU and torch on a GPU.

Per env: the commanded skill B, the previous one A and the ramp weight w (eq 4.10:
c̄ = (1 - w) c_A + w c_B, w rising linearly over `ramp_frames`), the step count and, for
locomotion skills, a heading goal. Reset = reference-state initialisation (RSI) from a random
frame of the commanded skill's clip, turned by a random yaw and moved to the origin. An episode
ends on a fall (a body other than the feet touches the ground), on a simulator blow-up (the
batch resets that env and counts it), on a large pose error against the clip's timed reference
(reward.pose_error_threshold) or at `episode_seconds` (truncation).

The rules themselves (state parts, rewards, pose error, reference clock, episode ends, fall rates,
command switches, the ramp, the reference's restart and grace steps) are `rules.py` and `features.py`,
written once against the array API; this class holds the per-env arrays and applies them. What differs
between the array libraries (the simulator it reads, the random numbers, how a subset of the envs is
selected) is `env_arrays.py`:

* `CgailEnv(skills, env_cfg, ...)`: numpy over C MuJoCo (env.backend=cpu and evaluation);
* `CgailEnv(..., device=..., sim=...)` / `CgailDeviceEnv`: torch on the simulator's device, MuJoCo Warp
  (env.backend=warp) or C MuJoCo seen as tensors (env.backend=torch, `charctl.sim.torch_view`). Every
  branch that depends on data is a mask there, so a GPU control step issues no host round trip. The two
  draw equally distributed, not identical, random numbers.

Units and frames: radians (yaw about world +y, PD targets), metres, m/s; world y-up.
"""

from __future__ import annotations

import math

import numpy as np

from charctl.config import plain_section
from charctl.experiments.cgail import start_frames
from charctl.experiments.cgail.env_arrays import arrays_for, simulator
from charctl.experiments.cgail.env_rows import IndexRows, MaskRows
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
    state_dim,
    switch_commands,
    tracking_reward,
    update_fall_rates,
    yaw_scale,
)
from charctl.experiments.cgail.skills import SkillData
from charctl.experiments.cgail.step_result import StepResult
from charctl.motion.array_compat import namespace, rotations_for

# Evaluation envs start from the clips: the weighted starts are a training rule (env config keys set to these values
# by `policy.TrainedRun.make_env` without rules and by the fidelity evaluation's env).
EVALUATION_STARTS = {"start_failure_weight": 0.0}


class CgailEnv:
    """N humanoids imitating K skills (the module docstring): numpy over C MuJoCo, or torch on a tensor simulator."""

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
        device=None,
        sim=None,
    ):
        """`device` / `sim`: both None for numpy over a new C MuJoCo batch; a torch simulator (`sim`) or a device
        for MuJoCo Warp (`device`) for torch. The rule keywords come from `env_rules.env_rules`."""
        self.skills = skills
        self.cfg = env_cfg = plain_section(env_cfg)  # typed fields, cheap reads in the step loop
        self.tracking = tracking  # phase in the state, reference frame advanced every step
        # training only (reward.pose_error_threshold): end episodes that leave the clip's timed reference
        self.pose_threshold, self.pose_grace = float(pose_error_threshold), int(pose_error_grace_steps)
        self.root_scale = root_height_scale(self.pose_threshold, float(root_height_threshold))
        self.yaw_scale = yaw_scale(self.pose_threshold, float(yaw_error_threshold))  # 0: no heading check
        self.goal_window = int(goal_reference_window)  # 0: heading-goal skills scored against the closest frame
        self.reference_reward = bool(reference_reward)  # r_track against that reference (reward.w_track)
        # env.phase_obs: the timed reference's phase in the state of the adversarial policy (training and evaluation)
        self.phase_obs = bool(getattr(env_cfg, "phase_obs", False)) and not tracking
        self.timed_reference = self.pose_threshold > 0 or self.phase_obs  # reference advanced, restarting at frame 0
        self.conditional = conditional
        self.K = len(skills)
        self.N = int(env_cfg.num_envs)
        self.sim = simulator(env_cfg, device, sim)
        self.arrays = a = arrays_for(self.sim, seed)
        self.on_device, self.device, self.dtype = a.on_device, a.device, a.dtype
        self.max_steps = int(round(env_cfg.episode_seconds * env_cfg.control_hz))
        self._load_skill_tables(skills)
        self.rest = a.zeros(self.sim.layout.nu, a.dtype)
        self.state_dim = state_dim(tracking or self.phase_obs)
        self.obs_dim = self.state_dim
        self._init_env_state()
        self.reset(a.array([True] * self.N, a.bool_dtype))

    # the row form of the array library (its random state, for checkpoints, is `self.arrays.random_state()`)
    @property
    def compact_rows(self) -> bool:
        """A data-dependent subset as integer ids (True: numpy, torch on the CPU) or a mask (torch on a GPU)."""
        return self.arrays.compact_rows

    @compact_rows.setter
    def compact_rows(self, value: bool) -> None:
        self.arrays.compact_rows = bool(value)

    def _load_skill_tables(self, skills: list[SkillData]) -> None:
        """Per-skill tables: RSI states and reference observations (padded to the longest clip with its last
        row), clip lengths, looping, heading goals and mean speeds (m/s)."""
        a = self.arrays
        self.rsi_qpos = a.tables([s.qpos for s in skills])  # (K, T, nq)
        self.rsi_qvel = a.tables([s.qvel for s in skills])  # (K, T, nv)
        self.ref_obs = a.tables([s.obs for s in skills])  # (K, T, 133)
        self.ref_keys = pose_keys(self.ref_obs)  # (K, T, 13): what the pose error compares
        xp = namespace(self.ref_keys)
        # (K, 13, T_goal) frames last, up to the longest heading-goal clip: the closest-frame search of those skills
        # (past a clip's end the table repeats its last frame, so the shorter search finds the same frames)
        goal_frames = max([len(s.obs) for s in skills if s.heading_goal], default=1)
        self.goal_keys_t = xp.asarray(xp.permute_dims(self.ref_keys[:, :goal_frames], (0, 2, 1)), copy=True)
        i64 = namespace(self.ref_keys).int64
        self.clip_frames = a.array([len(s.obs) for s in skills], i64)
        self.rsi_frames = a.array([len(s.qpos) for s in skills], i64)
        self.clip_loops = a.array([s.loop for s in skills], a.bool_dtype)
        self.has_goal = a.array([s.heading_goal for s in skills], a.bool_dtype)
        self.speed = a.array([s.mean_speed for s in skills], a.dtype)
        clips = np.array([len(s.obs) for s in skills]), np.array([s.loop for s in skills])
        lead = start_frames.lead_window_index(*clips, self.cfg.start_failure_lead)
        self._lead = tuple(a.array(x, i64) for x in lead)  # each start frame's lead window

    def _init_env_state(self) -> None:
        """The per-env state before the first reset: commands, ramp weights, step counts, heading goals,
        reference frames and checks, failure rates per skill, evaluation overrides, the state / observation."""
        a, N = self.arrays, self.N
        i64, f = namespace(self.ref_keys).int64, a.float_dtype
        f64 = namespace(self.ref_keys).float64
        self.cmd = a.zeros(N, i64)  # B: current command
        self.prev_cmd = a.zeros(N, i64)  # A: previous command
        self.w = a.array([1.0] * N, f)  # ramp weight
        self.steps = a.zeros(N, i64)
        self.goal_angle = a.zeros(N, f)  # world yaw of the heading goal (radians about +y)
        self.ref_frame = a.zeros(N, i64)  # reference clip frame at the current phase
        self.ref_active = a.array([True] * N, a.bool_dtype)  # pose-error check: reference valid (off during a switch)
        self.ref_grace = a.zeros(N, i64)  # pose-error check: steps left without a check
        self.yaw_err = a.zeros(N, f)  # reward.yaw_error_threshold: heading gained on the reference (rad)
        self.fall_rate = a.array([0.5] * self.K, f64)  # per-skill recent failure rate (env.skill_fall_weight)
        # env.start_failure_weight: failures per skill and reference frame (start_frames.py)
        self.frame_failures = a.zeros((self.K, max(len(s.obs) for s in self.skills)), f64)
        self.forced_command = None  # evaluation: fixed command per env (-1 = random)
        self.start_frame: int | None = None  # evaluation: RSI from this clip frame instead of a random one
        self.random_yaw = True  # RSI turns the character by a random yaw (training); off for evaluation
        self._falls = a.zeros((), i64)
        self._state = a.zeros((N, self.state_dim), a.net_dtype)
        self._obs = a.zeros((N, DISC_OBS_DIM), a.net_dtype)

    # ------------------------------------------------------------------ commands
    def command_blend(self):
        """(N, K) c̄_t = (1 - w) onehot(A) + w onehot(B)."""
        xp = namespace(self.cmd)
        skills = self.arrays.array(list(range(self.K)), self.cmd.dtype)[None, :]
        w = self.w[:, None]
        a, b = (xp.astype(c[:, None] == skills, self.w.dtype) for c in (self.prev_cmd, self.cmd))
        return (1.0 - w) * a + w * b

    def set_command(self, ids, skill, ramp: bool = True) -> None:
        """Switch the envs `ids` to `skill`: distinct integer ids with one skill per id or one for all, or an (N,)
        bool mask with one skill per env or one for all. With `ramp` the blend goes A -> B over ramp_frames."""
        xp = namespace(self.cmd)
        skill = self.arrays.array(skill, self.cmd.dtype)
        if getattr(ids, "dtype", None) in (bool, self.arrays.bool_dtype):  # a mask
            mask = self.arrays.array(ids, self.arrays.bool_dtype)
            new = xp.where(mask, xp.broadcast_to(skill, (self.N,)), self.cmd)
        else:
            rows = self.arrays.rows(ids)
            mask = rows.put(self.arrays.zeros(self.N, self.arrays.bool_dtype), True)
            new = rows.put(self.cmd, xp.broadcast_to(skill, rows.ids.shape))
        self._command(mask, new, ramp)

    def _command(self, mask, new, ramp: bool = True) -> None:
        """Command the envs in the (N,) bool `mask` to `new` (N,) (`rules.switch_commands`; new heading goals where
        the command changed)."""
        frames = self.cfg.ramp_frames if ramp else 0
        self.cmd, self.prev_cmd, self.w, self.ref_active, changed = switch_commands(
            self.cmd, self.prev_cmd, self.w, self.ref_active, mask, new, frames
        )
        self._new_goal(changed)

    def _advance_ramp(self) -> None:
        self.w = advance_ramp(self.w, self.cfg.ramp_frames)

    def _new_goal(self, mask) -> None:
        """New heading goals (world yaw, rad) for the envs in `mask`: within goal_max_angle_deg of their heading."""
        rows = self.arrays.draw_rows(mask)
        if isinstance(rows, IndexRows) and len(rows.ids) == 0:
            return
        offset = self.arrays.symmetric(rows, math.radians(self.cfg.goal_max_angle_deg))
        root = self.arrays.root_quat(rows)
        self.goal_angle = rows.put(self.goal_angle, rotations_for(root).yaw_about_y(root) + offset)

    # ------------------------------------------------------------------ reset
    def reset(self, ids) -> None:
        """RSI of the envs `ids` ((n,) integer ids or an (N,) bool mask) from a random frame of a random skill
        (or the forced one); `env_arrays` draws the random numbers."""
        rows = self.arrays.rows(ids)
        draws = self.arrays.reset_draws(self, rows)
        if draws is None:
            return
        skill, frames, yaw, goal_offset = draws
        qpos = self.rsi_qpos[skill, frames]  # advanced indexing: copies
        qvel = self.rsi_qvel[skill, frames]
        R = rotations_for(qpos)
        turn = R.heading_quat(yaw)
        qpos[:, 0] = 0.0
        qpos[:, 2] = 0.0
        root = R.wxyz_to_xyzw(qpos[:, 3:7])
        qpos[:, 3:7] = R.xyzw_to_wxyz(R.multiply(turn, root))
        qvel[:, :3] = R.rotate(turn, qvel[:, :3])  # world linear velocity turns; angular is body-local
        self.sim.set_state(rows.ids, qpos, qvel)
        self.cmd = rows.put(self.cmd, skill)
        self.prev_cmd = rows.put(self.prev_cmd, skill)
        self.w = rows.put(self.w, 1.0)
        self.steps = rows.put(self.steps, 0)
        self.ref_frame = rows.put(self.ref_frame, frames)
        self.ref_active = rows.put(self.ref_active, True)
        self.ref_grace = rows.put(self.ref_grace, 0)
        self.yaw_err = rows.put(self.yaw_err, 0.0)
        k = self.arrays.kinematics(None if isinstance(rows, MaskRows) else rows)
        self.goal_angle = rows.put(self.goal_angle, R.yaw_about_y(k.body_rot[:, 0]) + goal_offset)
        state, obs = self._features(k, rows)
        self._state = rows.put(self._state, self.arrays.to_net(state))
        self._obs = rows.put(self._obs, self.arrays.to_net(obs))

    def _sample_skills(self, n: int):
        """(n,) commands: uniform, or partly fall-weighted (env.skill_fall_weight; `rules.skill_probabilities`)."""
        return self.arrays.skills(n, self.K, self.fall_rate, self.cfg.skill_fall_weight)

    # ------------------------------------------------------------------ observation
    def _features(self, k: Kinematics, rows=None):
        """(policy state (n, state_dim), disc obs (n, 133)) of the envs `rows` (an `IndexRows`/`MaskRows`, integer
        ids, or None / a slice for all) whose kinematics are `k`: the shared features (`features.py`, `rules.py`)
        with one heading frame, the heading goal and, for the tracking baseline or env.phase_obs, the clip phase."""
        pick = rows.pick if isinstance(rows, (IndexRows, MaskRows)) else (lambda x: x if rows is None else x[rows])
        f = heading_frame(k)
        cmd = pick(self.cmd)
        parts = [policy_state(k, f), goal_features(pick(self.goal_angle), f.heading, self.has_goal[cmd])]
        if self.tracking or self.phase_obs:  # env.phase_obs: (0, 0) with a heading goal or while a ramp runs
            shown = (~self.has_goal[cmd] & pick(self.ref_active)) if self.phase_obs else None
            phase = phase_features(pick(self.ref_frame), self.clip_frames[cmd], shown)
            parts.append(self.arrays.to_net(phase) if self.on_device else phase)  # float32 on torch, as it was
        xp = namespace(parts[0])
        return xp.concat(parts, axis=1), disc_obs(k, f)

    def _advance_phase(self, restart: bool = False):
        """Step every env's reference frame (`rules.advance_reference`; a looping clip wraps); returns (reference
        obs (N, 133) at the new frame, (N,) clip ended). A non-looping clip ends at its last frame (the tracking
        baseline truncates there) or, with `restart` (the pose-error reference), starts again at frame 0 with
        grace steps."""
        cmd = self.cmd
        self.ref_frame, ended, again = advance_reference(
            self.ref_frame, self.clip_loops[cmd], self.clip_frames[cmd], restart
        )
        if restart:
            self.ref_grace = count_down_grace(self.ref_grace, again, self.pose_grace)
        return self._reference_obs(), ended

    def _reference_obs(self, frames=None):
        """(N, 133) the commanded clip's disc observation at every env's reference frame (or at `frames`)."""
        return self.ref_obs[self.cmd, self.ref_frame if frames is None else frames]

    def _pose_error(self, obs, ref):
        """((N,) m, (N, 133)): `reference_pose_error` against the timed reference `ref`, except for skills with a
        heading goal (locomotion), scored against their clip's closest frame (`rules.goal_reference_frame`: the
        whole clip, or with reward.goal_reference_window a few frames on from the last one): a walk at a cadence
        of its own is no error. In-place looping clips (jump, dances, spinkick) keep the timed reference, so
        standing in one of their poses is an error once the clip moves on. Returns the reference each env was
        scored against as well."""
        timed = reference_pose_error(obs, ref, self.root_scale)
        rows = self.arrays.rows(self.has_goal[self.cmd])
        cmd = rows.pick(self.cmd)
        each = pose_key_error_frames(pose_keys(rows.pick(obs)), self.goal_keys_t[cmd], self.root_scale)  # (n, T_goal)
        synced = rows.pick(self.ref_active & (self.ref_grace == 0))
        advanced = rows.pick(self.ref_frame)
        clip_frames = self.clip_frames[cmd]
        best = goal_reference_frame(each, advanced, self.clip_loops[cmd], clip_frames, self.goal_window, synced)
        if self.goal_window > 0:  # reward.goal_reference_window: the reference moves on from the matched frame
            self.ref_frame = rows.put(self.ref_frame, best)
        xp = namespace(each)
        closest = xp.take_along_axis(each, best[:, None], axis=1)[:, 0]
        return rows.put(timed, closest), rows.put(ref, self.ref_obs[cmd, best])

    def _restart_reference_after_ramp(self) -> None:
        """Envs whose command ramp has just finished: the new clip's reference starts at frame 0."""
        self.ref_frame, self.ref_grace, self.ref_active = restart_after_ramp(
            self.ref_frame, self.ref_grace, self.ref_active, self.w, self.pose_grace
        )

    @property
    def state(self):
        """(N, state_dim) policy state."""
        return self._state

    @property
    def obs(self):
        """(N, 133) discriminator observation."""
        return self._obs

    @property
    def fall_count(self) -> int:
        """Falls so far (reading it synchronises with the device)."""
        return int(self._falls)

    # ------------------------------------------------------------------ step
    def step(self, actions, force=None, force_substeps: int = 0) -> StepResult:
        """Apply PD targets rest + action_scale * actions (radians) for one control step; `force`
        (N, nbody, 6) is an external world-frame push held for the first `force_substeps` physics substeps."""
        a = self.arrays
        targets = self.rest + self.cfg.action_scale * a.array(actions, a.dtype)
        unstable = self.sim.step(targets, force=force, force_substeps=force_substeps)
        k = a.kinematics()
        zeros = a.zeros(self.N, a.float_dtype)
        clip_ended = no_pose_end = a.zeros(self.N, a.bool_dtype)
        if self.tracking:  # the phase in the state is the new one
            ref, clip_ended = self._advance_phase()
        elif self.timed_reference:
            ref, _ = self._advance_phase(restart=True)
        final_state, pair_next = self._features(k)
        r_track = tracking_reward(pair_next, ref) if self.tracking else zeros
        cmd = self.cmd
        r_goal = goal_reward(self.goal_angle, k.com_vel, self.speed[cmd], self.has_goal[cmd], self.cfg.goal_sharpness)
        fell = self.sim.non_foot_ground_contact(self.cfg.fall_tolerance)
        pose_ended, scored = no_pose_end, None
        if self.pose_threshold > 0:
            r_track, pose_ended, scored = env_reference_check(self, pair_next, ref, r_track, fell, unstable)
        self.steps = self.steps + 1
        terminated, truncated = episode_end(fell, unstable, pose_ended, self.steps, self.max_steps, clip_ended)
        self._falls = self._falls + fell.sum()
        done = terminated | truncated
        if self.cfg.start_failure_weight > 0:  # where in its clip each failing env was (not during a command ramp)
            args = (self.cmd, self.ref_frame, terminated & self.ref_active, self.cfg.start_failure_halflife)
            self.frame_failures = start_frames.update_frame_failures(self.frame_failures, *args)
        if a.on_device or bool(done.any()):  # no ended episode leaves the rates as they are
            # a pose-error end counts as a failure of the skill, like a fall (logged as fall_rate/<skill>)
            self.fall_rate = update_fall_rates(
                self.fall_rate, self.cmd, done, fell | pose_ended, self.cfg.skill_fall_halflife
            )
        # the networks' inputs (float32 on torch; the numpy rollout casts them)
        self._state, self._obs = final_state, pair_next = a.to_net(final_state), a.to_net(pair_next)
        self._advance_ramp()
        if self.timed_reference:
            self._restart_reference_after_ramp()
        self.reset(done)
        self._maybe_switch(~done)  # the envs that did not just reset
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

    def _maybe_switch(self, mask) -> None:
        """Switch each env in `mask` to a random command with probability env.switch_prob."""
        if self.K < 2 or self.cfg.switch_prob <= 0 or self.forced_command is not None:
            return
        switch, new = self.arrays.switches(self, mask)
        if not self.on_device and not switch.any():
            return
        self._command(switch, new)


def CgailDeviceEnv(skills: list[SkillData], env_cfg, device="cpu", sim=None, **kwargs) -> CgailEnv:
    """The torch env: on `sim` (e.g. a `TorchBatchedHumanoid`, env.backend=torch) or on MuJoCo Warp on `device`."""
    return CgailEnv(skills, env_cfg, device=device, sim=sim, **kwargs)
