"""Batched multi-skill imitation environment on the foundation simulator (docs/cgail.md).

Per env: the commanded skill B, the previous one A and the ramp weight w (eq 4.10:
c̄ = (1 - w) c_A + w c_B, w rising linearly over `ramp_frames`), the step count and, for
locomotion skills, a heading goal. Reset = reference-state initialisation (RSI) from a random
frame of the commanded skill's clip, turned by a random yaw and moved to the origin. An episode
ends on a fall (a body other than the feet touches the ground), on a simulator blow-up (the
batch resets that env and counts it), on a large pose error against the clip's timed reference
(reward.pose_error_threshold) or at `episode_seconds` (truncation).

The rules themselves (state parts, rewards, pose error, reference clock, episode ends, fall rates,
command switches, the ramp, the reference's restart and grace steps) are `rules.py` and `features.py`,
shared with the on-device env (`env_torch.py`); this class holds the per-env arrays on numpy and
applies them, and keeps the resets (by index) and the random numbers.
"""

from __future__ import annotations

import numpy as np

from charctl.config import plain_section
from charctl.experiments.cgail import start_frames
from charctl.experiments.cgail.env_rules import env_reference_check
from charctl.experiments.cgail.features import (
    DISC_OBS_DIM,
    disc_obs,
    heading_frame,
    policy_state,
    sim_kinematics,
)
from charctl.experiments.cgail.rules import (
    advance_ramp,
    advance_reference,
    count_down_grace,
    episode_end,
    goal_features,
    goal_reference_frame,
    goal_reward,
    phase_features,
    pose_key_error,
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
from charctl.motion import rotations as R
from charctl.sim.batch import BatchedHumanoid, SimSettings


class CgailEnv:
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
    ):
        self.skills = skills
        self.tracking = tracking  # phase in the state, reference frame advanced every step
        # training only (reward.pose_error_threshold): end episodes that leave the clip's timed reference
        self.pose_threshold, self.pose_grace = float(pose_error_threshold), int(pose_error_grace_steps)
        self.root_scale = root_height_scale(self.pose_threshold, float(root_height_threshold))
        self.yaw_scale = yaw_scale(self.pose_threshold, float(yaw_error_threshold))  # 0: no heading check
        self.goal_window = int(goal_reference_window)  # 0: heading-goal skills scored against the closest frame
        self.reference_reward = bool(reference_reward)  # r_track against that reference (reward.w_track)
        self.cfg = env_cfg = plain_section(env_cfg)  # typed fields, cheap reads in the step loop
        # env.phase_obs: the timed reference's phase in the state of the adversarial policy (training and evaluation)
        self.phase_obs = bool(getattr(env_cfg, "phase_obs", False)) and not tracking
        self.timed_reference = self.pose_threshold > 0 or self.phase_obs  # reference advanced, restarting at frame 0
        self.K = len(skills)
        self.conditional = conditional
        self.rng = np.random.default_rng(seed)
        self.sim = BatchedHumanoid(
            env_cfg.num_envs,
            SimSettings.of(env_cfg),
        )
        self.N = env_cfg.num_envs
        self.max_steps = int(round(env_cfg.episode_seconds * env_cfg.control_hz))
        self._per_env_arrays()
        self.forced_command: np.ndarray | None = None  # evaluation: fixed command per env (-1 = random)
        self.start_frame: int | None = None  # evaluation: RSI from this clip frame instead of a random one
        self.random_yaw = True  # RSI turns the character by a random yaw (training); off for evaluation
        self.has_goal = np.array([s.heading_goal for s in skills])
        self.speed = np.array([s.mean_speed for s in skills])
        self.rest = np.zeros(self.sim.layout.nu)
        self.clip_frames = np.array([len(sk.obs) for sk in skills])
        self.clip_loops = np.array([sk.loop for sk in skills])
        self.state_dim = state_dim(tracking or self.phase_obs)
        self.obs_dim = self.state_dim
        self.fall_count = 0
        # per-skill recent failure rate: falls and pose-error ends (env.skill_fall_weight)
        self.fall_rate = np.full(self.K, 0.5)
        # env.start_failure_weight: failures per skill and reference frame, and each start frame's lead window
        self.frame_failures = np.zeros((self.K, int(self.clip_frames.max())))
        self.rsi_frames = np.array([len(sk.qpos) for sk in skills])
        self._lead = start_frames.lead_window_index(self.clip_frames, self.clip_loops, self.cfg.start_failure_lead)
        self._state = np.zeros((self.N, self.state_dim))
        self._obs = np.zeros((self.N, DISC_OBS_DIM))
        self.reset(np.arange(self.N))

    def _per_env_arrays(self) -> None:
        """The per-env bookkeeping arrays (N,), filled by `reset`."""
        self.cmd = np.zeros(self.N, dtype=np.int64)  # B: current command
        self.prev_cmd = np.zeros(self.N, dtype=np.int64)  # A: previous command
        self.w = np.ones(self.N)  # ramp weight
        self.steps = np.zeros(self.N, dtype=np.int64)
        self.goal_angle = np.zeros(self.N)  # world yaw of the heading goal (radians about +y)
        self.ref_frame = np.zeros(self.N, dtype=np.int64)  # reference clip frame at the current phase
        self.ref_active = np.ones(self.N, dtype=bool)  # pose-error check: reference valid (off during a switch)
        self.ref_grace = np.zeros(self.N, dtype=np.int64)  # pose-error check: steps left without a check
        self.yaw_err = np.zeros(self.N)  # reward.yaw_error_threshold: heading gained on the reference (rad)
        self.episode_return_goal = np.zeros(self.N)

    # ------------------------------------------------------------------ commands
    def command_blend(self) -> np.ndarray:
        """(N, K) c̄_t = (1 - w) onehot(A) + w onehot(B)."""
        c = np.zeros((self.N, self.K))
        rows = np.arange(self.N)
        c[rows, self.prev_cmd] += 1.0 - self.w
        c[rows, self.cmd] += self.w
        return c

    def set_command(self, ids: np.ndarray, skill: np.ndarray | int, ramp: bool = True) -> None:
        """Switch envs `ids` (distinct) to `skill`; with `ramp` the blend goes A -> B over ramp_frames
        (`rules.switch_commands` on those rows; new heading goals where the command changed)."""
        ids = np.atleast_1d(np.asarray(ids))
        new = np.broadcast_to(np.asarray(skill), ids.shape)
        rows = (self.cmd[ids], self.prev_cmd[ids], self.w[ids], self.ref_active[ids])
        frames = self.cfg.ramp_frames if ramp else 0
        *rows, changed = switch_commands(*rows, np.ones(ids.shape, dtype=bool), new, frames)
        self.cmd[ids], self.prev_cmd[ids], self.w[ids], self.ref_active[ids] = rows
        self._new_goal(ids[changed])

    def _advance_ramp(self) -> None:
        self.w = advance_ramp(self.w, self.cfg.ramp_frames)

    def _new_goal(self, ids: np.ndarray) -> None:
        if len(ids) == 0:
            return
        heading = R.yaw_about_y(self.sim.body_quat_rows(ids)[:, 0])
        spread = np.radians(self.cfg.goal_max_angle_deg)
        self.goal_angle[ids] = heading + self.rng.uniform(-spread, spread, size=len(ids))

    # ------------------------------------------------------------------ reset
    def reset(self, ids: np.ndarray) -> None:
        """RSI of envs `ids` from a random frame of their (new) commanded skill."""
        ids = np.asarray(ids, dtype=np.int64)
        if ids.size == 0:
            return
        skill = self._sample_skills(len(ids))
        if self.forced_command is not None:
            forced = self.forced_command[ids]
            skill = np.where(forced >= 0, forced, skill)
        self.cmd[ids] = skill
        self.prev_cmd[ids] = skill
        self.w[ids] = 1.0
        self.steps[ids] = 0
        self.ref_active[ids] = True
        self.ref_grace[ids] = 0
        self.yaw_err[ids] = 0.0
        qpos = np.empty((len(ids), self.sim.layout.nq))
        qvel = np.empty((len(ids), self.sim.layout.nv))
        weighted = self._failure_weighted_frames(skill)
        for k in np.unique(skill):  # <= K groups, vectorised inside
            m = skill == k
            data = self.skills[k]
            frames = (
                weighted[m] if weighted is not None else self.rng.integers(0, len(data.qpos) - 1, size=int(m.sum()))
            )
            if self.start_frame is not None:
                frames[:] = min(self.start_frame, len(data.qpos) - 1)
            qpos[m] = data.qpos[frames]
            qvel[m] = data.qvel[frames]
            self.ref_frame[ids[m]] = frames
        yaw = self.rng.uniform(-np.pi, np.pi, size=len(ids)) if self.random_yaw else np.zeros(len(ids))
        turn = R.heading_quat(yaw)
        qpos[:, [0, 2]] = 0.0
        root = R.wxyz_to_xyzw(qpos[:, 3:7])
        qpos[:, 3:7] = R.xyzw_to_wxyz(R.multiply(turn, root))
        qvel[:, :3] = R.rotate(turn, qvel[:, :3])  # world linear velocity turns; angular is body-local
        self.sim.set_state(ids, qpos, qvel)
        self._new_goal(ids)
        k = sim_kinematics(self.sim, ids)  # only the reset rows
        self._state[ids], self._obs[ids] = self._features(k, ids)

    def _failure_weighted_frames(self, skill: np.ndarray) -> np.ndarray | None:
        """(n,) start frames for envs commanded `skill` (n,) drawn by `start_frames` (env.start_failure_weight),
        or None for uniform RSI (the weight 0: the random stream is then the one uniform RSI always drew)."""
        weight = self.cfg.start_failure_weight
        if weight <= 0:
            return None
        u = self.rng.random(len(skill))
        return start_frames.draw_start_frames(self.frame_failures, self._lead, self.rsi_frames, weight, skill, u)

    # ------------------------------------------------------------------ observation
    def _goal_features(self, k, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(n, 2) cos/sin of the goal direction relative to the heading of envs `rows` (0 without a goal)."""
        return goal_features(self.goal_angle[rows], R.yaw_about_y(k.body_rot[:, 0]), self.has_goal[self.cmd[rows]])

    def _phase_features(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(n, 2) cos/sin of the reference clip phase of envs `rows` (tracking baseline, env.phase_obs). With
        env.phase_obs it is (0, 0) for skills with a heading goal and while the reference waits for a ramp."""
        cmd = self.cmd[rows]
        shown = (~self.has_goal[cmd] & self.ref_active[rows]) if self.phase_obs else None
        return phase_features(self.ref_frame[rows], self.clip_frames[cmd], shown)

    def _features(self, k, rows: np.ndarray | slice = slice(None)) -> tuple[np.ndarray, np.ndarray]:
        """(policy state, disc obs) of envs `rows` whose kinematics are `k`, sharing one heading frame."""
        f = heading_frame(k)
        parts = [policy_state(k, f), self._goal_features(k, rows)]
        if self.tracking or self.phase_obs:
            parts.append(self._phase_features(rows))
        return np.concatenate(parts, axis=1), disc_obs(k, f)

    def _advance_phase(self, restart: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Step every env's reference frame (a looping clip wraps); returns (reference obs (N, 133) at the new
        frame, (N,) clip ended). A non-looping clip ends at its last frame (the tracking baseline truncates
        there) or, with `restart` (the pose-error reference), starts again at frame 0 with grace steps."""
        cmd = self.cmd
        self.ref_frame, ended, again = advance_reference(
            self.ref_frame, self.clip_loops[cmd], self.clip_frames[cmd], restart
        )
        if restart:
            self.ref_grace = count_down_grace(self.ref_grace, again, self.pose_grace)
        return self._reference_obs(), ended

    def _reference_obs(self, frames: np.ndarray | None = None) -> np.ndarray:
        """(N, 133) the commanded clip's disc observation at every env's reference frame (or at `frames`)."""
        frames = self.ref_frame if frames is None else frames
        ref = np.empty((self.N, DISC_OBS_DIM))
        for s in np.unique(self.cmd):  # <= K groups, vectorised inside
            m = self.cmd == s
            ref[m] = self.skills[s].obs[frames[m]]
        return ref

    def _pose_error(self, obs: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """((N,) m, (N, 133)): `reference_pose_error` against the timed reference `ref`, except for skills with a
        heading goal (locomotion), scored against their clip's closest frame (`rules.goal_reference_frame`: the
        whole clip, or with reward.goal_reference_window a few frames on from the last one): a walk at a cadence
        of its own is no error. In-place looping clips (jump, dances, spinkick) keep the timed reference, so standing in
        one of their poses is an error once the clip moves on. Returns the reference each env was scored
        against as well."""
        err, ref = reference_pose_error(obs, ref, self.root_scale), ref.copy()
        synced = self.ref_active & (self.ref_grace == 0)
        for s in np.unique(self.cmd[self.has_goal[self.cmd]]):
            m = np.flatnonzero(self.cmd == s)
            clip = self.skills[s].obs
            each = pose_key_error(pose_keys(obs[m])[:, None], pose_keys(clip)[None], self.root_scale)  # (n, T) m
            n = np.full(len(m), len(clip))
            best = goal_reference_frame(
                each, self.ref_frame[m], np.full(len(m), self.skills[s].loop), n, self.goal_window, synced[m]
            )
            err[m], ref[m] = each[np.arange(len(m)), best], clip[best]
            if self.goal_window > 0:  # reward.goal_reference_window: the reference moves on from the matched frame
                self.ref_frame[m] = best
        return err, ref

    def _restart_reference_after_ramp(self) -> None:
        """Envs whose command ramp has just finished: the new clip's reference starts at frame 0."""
        self.ref_frame, self.ref_grace, self.ref_active = restart_after_ramp(
            self.ref_frame, self.ref_grace, self.ref_active, self.w, self.pose_grace
        )

    @property
    def state(self) -> np.ndarray:
        return self._state

    @property
    def obs(self) -> np.ndarray:
        return self._obs

    # ------------------------------------------------------------------ step
    def step(self, actions: np.ndarray, force: np.ndarray | None = None, force_substeps: int = 0) -> StepResult:
        """Apply PD targets rest + action_scale * actions for one control step.

        `force` (N, nbody, 6) is an external world-frame push held for the first
        `force_substeps` physics substeps (push-robustness tests)."""
        targets = self.rest + self.cfg.action_scale * actions
        unstable = self.sim.step(targets, force=force, force_substeps=force_substeps)
        k = sim_kinematics(self.sim)
        clip_ended = np.zeros(self.N, dtype=bool)
        r_track = np.zeros(self.N)
        if self.tracking:  # the phase in the state is the new one
            ref, clip_ended = self._advance_phase()
        elif self.timed_reference:
            ref, _ = self._advance_phase(restart=True)
        final_state, pair_next = self._features(k)
        if self.tracking:
            r_track = tracking_reward(pair_next, ref)
        r_goal = self._goal_reward(k)
        fell = self.sim.non_foot_ground_contact(self.cfg.fall_tolerance)
        pose_ended, scored = np.zeros(self.N, dtype=bool), None
        if self.pose_threshold > 0:
            r_track, pose_ended, scored = env_reference_check(self, pair_next, ref, r_track, fell, unstable)
        self.steps += 1
        terminated, truncated = episode_end(fell, unstable, pose_ended, self.steps, self.max_steps, clip_ended)
        self.fall_count += int(fell.sum())
        if self.cfg.start_failure_weight > 0:  # where in its clip each failing env was (not during a command ramp)
            args = (self.cmd, self.ref_frame, terminated & self.ref_active, self.cfg.start_failure_halflife)
            self.frame_failures = start_frames.update_frame_failures(self.frame_failures, *args)
        done = np.flatnonzero(terminated | truncated)
        if done.size:
            # a pose-error termination counts as a failure of the skill, like a fall (env.skill_fall_weight)
            self.fall_rate = update_fall_rates(
                self.fall_rate, self.cmd, terminated | truncated, fell | pose_ended, self.cfg.skill_fall_halflife
            )
        state, obs = final_state.copy(), pair_next.copy()
        self._state, self._obs = state, obs
        self._advance_ramp()
        if self.timed_reference:
            self._restart_reference_after_ramp()
        if done.size:
            self.reset(done)
        self._maybe_switch(np.setdiff1d(np.arange(self.N), done))  # the envs that did not just reset
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

    def _goal_reward(self, k) -> np.ndarray:
        """r_G in [0, 1] (`rules.goal_reward`): 1 for skills without a heading goal."""
        cmd = self.cmd
        return goal_reward(self.goal_angle, k.com_vel, self.speed[cmd], self.has_goal[cmd], self.cfg.goal_sharpness)

    def _maybe_switch(self, ids: np.ndarray) -> None:
        if self.K < 2 or self.cfg.switch_prob <= 0 or ids.size == 0 or self.forced_command is not None:
            return
        ids = ids[self.rng.random(ids.size) < self.cfg.switch_prob]
        if ids.size:
            self.set_command(ids, self._sample_skills(ids.size))

    def _sample_skills(self, n: int) -> np.ndarray:
        """(n,) commands: uniform, or partly fall-weighted (env.skill_fall_weight)."""
        if self.cfg.skill_fall_weight <= 0 or self.K < 2:
            return self.rng.integers(0, self.K, size=n)
        p = skill_probabilities(self.fall_rate, self.cfg.skill_fall_weight)
        return self.rng.choice(self.K, size=n, p=p)
