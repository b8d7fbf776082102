"""Batched single-rigid-body walker (paper §3-§7): N boxes stepped together with numpy + the QP.

Simulation decision (docs/srb.md): charctl's own integrator, not a MuJoCo free body. The SRB's
only forces are the QP's contact forces (at kinematic foot points on the ground), gravity and
an optional push, so a physics engine would add nothing but a second contact model that could
disagree with the QP; the integrator is semi-implicit Euler on (v, w) then (p, q) with the
exponential map for the rotation, one QP solve per substep (tests/test_srb.py checks free fall,
torque-free rotation and standing against closed forms).

Per control step (1 / clip fps seconds), for every environment:
  1. swing feet are placed from the COM at t and the action (paper §6),
  2. the QP turns the PD accelerations into contact forces, the body is integrated (push added
     as an external force the QP does not know about),
  3. the reference frame advances, with late touch-down (the reference waits) and early
     touch-down (the reference jumps to the foot's touch-down frame) handling (paper §6),
  4. reward and termination (paper §5.2, §5.3), then finished environments are reset.

State (20, paper §5.1): COM height; the body rotation in its heading frame (xyzw, 4); linear
and angular velocity in the heading frame (6); per foot (right, left): its ground midpoint
relative to the COM in the heading frame (3) and, for a swing foot, the heading of the COM minus
the foot's yaw (1, 0 in stance); the phase of the reference cycle in [0, 1).
Action (10): right/left foot (x, z) offsets (m, heading frame), desired relative linear velocity
(m/s) and angular velocity (rad/s) in the reference's heading frame, each times its scale.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from charctl.errors import CharctlError
from charctl.experiments.srb.params import EnvParams
from charctl.experiments.srb.qp import N_POINTS, QPBatch, QPParams, solve_batch
from charctl.experiments.srb.reference import (
    Reference,
    box_half_extents,
    build_reference,
    composite_inertia,
    sole_points_local,
)
from charctl.motion import rotations as R

OBS_DIM = 20
ACT_DIM = 10
UP = np.array([0.0, 1.0, 0.0])


@dataclass(frozen=True)
class Body:
    """The box: mass (kg), inertia in the body (pelvis) frame (kg m^2), render half extents (m)."""

    mass: float
    inertia: np.ndarray
    half_extents: np.ndarray
    foot_half_length: float  # m, heel-to-toe half distance of the contact points


def make_body(clip, mass: float, frame: int = 0) -> Body:
    """The humanoid's composite inertia in `clip`'s pose `frame`, scaled to `mass` (paper §4); a one-line
    error for a frame the clip does not have (body.inertia_pose_frame)."""
    if not 0 <= frame < clip.num_frames:
        raise CharctlError(
            f"body.inertia_pose_frame={frame} is outside clip {clip.name!r} (frames 0..{clip.num_frames - 1})"
        )
    inertia, m_full, _ = composite_inertia(clip, frame)
    inertia = inertia * (mass / m_full)
    sole = sole_points_local(clip.skeleton, "right_ankle")
    return Body(mass, inertia, box_half_extents(np.diag(inertia), mass), float(0.5 * np.linalg.norm(sole[1] - sole[0])))


def reference_and_body(cfg) -> tuple[Reference, Body]:
    """The reference of cfg.reference.clip and the box made from its pose; a one-line error for a clip srb
    cannot follow (unknown, too short, a foot that never lifts off or never touches down)."""
    from charctl.motion.library import load_clip

    clip = load_clip(cfg.reference.clip)
    rc = cfg.reference
    reference = build_reference(clip, rc.contact_height, rc.contact_speed, rc.min_phase_frames)
    return reference, make_body(clip, cfg.body.mass, cfg.body.inertia_pose_frame)


def preflight(cfg) -> None:
    """`charctl train`'s check before the run directory is made: the reference and the box build (the env
    builds them again)."""
    reference_and_body(cfg)


def heading_of(rot: np.ndarray) -> np.ndarray:
    return R.yaw_about_y(rot)


def wrap_angle(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def to_heading(yaw: np.ndarray, v: np.ndarray) -> np.ndarray:
    """World vectors (N, ..., 3) into the heading frame of yaw (N,) radians."""
    return R.rotate_yaw(-yaw, v)


def from_heading(yaw: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Heading-frame vectors (N, ..., 3) into the world frame."""
    return R.rotate_yaw(yaw, v)


class SRBEnv:
    """N single-rigid-body walkers tracking one reference. All arrays are (N, ...) numpy."""

    def __init__(
        self,
        cfg,
        num_envs: int,
        seed: int = 0,
        reference: Reference | None = None,
        body: Body | None = None,
        auto_reset: bool = True,
        max_steps: int | None = None,
    ):
        if reference is None or body is None:
            made_reference, made_body = reference_and_body(cfg)
            reference, body = reference or made_reference, body or made_body
        self.ref, self.body = reference, body
        self.p = EnvParams.from_cfg(cfg)
        self.num_envs = num_envs
        self.rng = np.random.default_rng(seed)
        self.auto_reset = auto_reset
        self.max_steps = int(max_steps if max_steps is not None else cfg.termination.max_steps)
        self.dt = self.ref.dt
        t = cfg.tracking
        self.qp = QPParams(
            mass=self.body.mass,
            mu=float(cfg.body.friction),
            w_linear=float(t.w_linear),
            w_angular=float(t.w_angular),
            force_reg=float(t.force_reg),
            torque_limit=float(t.torque_limit),
            torque_reg=float(t.torque_reg),
        )
        a = cfg.action
        self.action_scale = np.array([a.foot_scale] * 4 + [a.lin_vel_scale] * 3 + [a.ang_vel_scale] * 3, dtype=float)
        n = num_envs
        self.pos, self.vel = np.zeros((n, 3)), np.zeros((n, 3))
        self.rot, self.ang_vel = np.tile(R.IDENTITY, (n, 1)), np.zeros((n, 3))
        self.frame = np.zeros(n, dtype=int)
        self.steps = np.zeros(n, dtype=int)
        self.delay = np.zeros(n, dtype=int)
        self.foot_pos = np.zeros((n, 2, 3))
        self.foot_yaw = np.zeros((n, 2))
        self.stance = np.ones((n, 2), dtype=bool)
        self.last_forces = np.zeros((n, N_POINTS, 3))
        self.last_tau = np.zeros((n, 3))
        self.episode_return = np.zeros(n)
        self.stats = {"qp_solves": 0, "qp_failures": 0, "late_touchdowns": 0, "early_touchdowns": 0}
        self.reset()

    # ------------------------------------------------------------------ reset / observation
    def reset(self, idx: np.ndarray | None = None, frames: np.ndarray | None = None) -> np.ndarray:
        """Put environments `idx` (default all) on the reference at `frames` (default: uniform in the cycle)."""
        idx = np.arange(self.num_envs) if idx is None else np.asarray(idx)
        if idx.size == 0:
            return self.observe()
        if frames is None:
            frames = self.rng.integers(0, self.ref.cycle, size=idx.size)
        frames = np.broadcast_to(np.asarray(frames, dtype=int), idx.shape)
        s = self.ref.state(frames)
        self.pos[idx], self.vel[idx], self.rot[idx], self.ang_vel[idx] = s["pos"], s["vel"], s["rot"], s["ang_vel"]
        self.frame[idx] = frames
        self.steps[idx] = 0
        self.delay[idx] = 0
        k, i = self.ref.split(frames)
        self.foot_pos[idx] = (
            R.rotate_yaw(self.ref.cycle_yaws[k], self.ref.foot_mid[i]) + self.ref.cycle_shifts[k][:, None, :]
        )
        self.foot_yaw[idx] = self.ref.foot_yaw[i] + self.ref.cycle_yaws[k][:, None]
        self.stance[idx] = self.ref.stance[i]
        self.episode_return[idx] = 0.0
        return self.observe()

    def observe(self) -> np.ndarray:
        """(N, 20) state of paper §5.1 (see the module docstring)."""
        yaw = heading_of(self.rot)
        obs = np.empty((self.num_envs, 20))
        obs[:, 0] = self.pos[:, 1]
        obs[:, 1:5] = R.multiply(R.heading_quat(-yaw), self.rot)
        obs[:, 5:8] = to_heading(yaw, self.vel)
        obs[:, 8:11] = to_heading(yaw, self.ang_vel)
        feet = to_heading(yaw, self.foot_pos - self.pos[:, None, :])
        swing_dyaw = np.where(self.stance, 0.0, wrap_angle(yaw[:, None] - self.foot_yaw))
        obs[:, 11:14], obs[:, 14] = feet[:, 0], swing_dyaw[:, 0]
        obs[:, 15:18], obs[:, 18] = feet[:, 1], swing_dyaw[:, 1]
        obs[:, 19] = self.ref.phase(self.frame)
        return obs

    # ------------------------------------------------------------------ pieces of a step
    def contact_points(self) -> np.ndarray:
        """(N, 4, 3) world contact points [right heel, right toe, left heel, left toe] on the ground."""
        h = self.body.foot_half_length
        fwd = np.stack(
            [np.cos(self.foot_yaw), np.zeros_like(self.foot_yaw), -np.sin(self.foot_yaw)], axis=-1
        )  # (N, 2, 3)
        pts = np.stack([self.foot_pos - h * fwd, self.foot_pos + h * fwd], axis=2)  # (N, 2, 2, 3)
        pts[..., 1] = 0.0
        return pts.reshape(self.num_envs, N_POINTS, 3)

    def place_swing_feet(self, foot_action: np.ndarray, target_frames: np.ndarray) -> None:
        """Paper §6: a swing foot = COM_t + R_y(heading_t) (local offset); stance feet stay put."""
        yaw = heading_of(self.rot)
        i = target_frames % self.ref.cycle
        act = np.zeros((self.num_envs, 2, 3))
        act[..., 0], act[..., 2] = foot_action[:, [0, 2]], foot_action[:, [1, 3]]
        if self.p.foot_mode == "reference":
            local = self.ref.foot_local[i] + act
            fyaw = yaw[:, None] + wrap_angle(self.ref.foot_yaw[i] - self.ref.root_yaw[i][:, None])
        else:  # paper: k = (-0.07, 0, 0) right / (0.07, 0, 0) left on its lateral axis; ours is z (right = +z)
            local = act + np.array([[0.0, 0.0, self.p.foot_offset], [0.0, 0.0, -self.p.foot_offset]])
            fyaw = np.repeat(yaw[:, None], 2, axis=1)
        world = self.pos[:, None, :] + from_heading(yaw, local)
        world[..., 1] = 0.0
        swing = ~self.stance
        self.foot_pos[swing] = world[swing]
        self.foot_yaw[swing] = fyaw[swing]

    def desired_acceleration(self, target: dict, rel_vel: np.ndarray, rel_ang: np.ndarray) -> np.ndarray:
        """(N, 6) q_dd_d = clamp(a (p_d - p) + b (v_d - v)) for [linear, angular] (paper §7).

        v_d = reference velocity + the action's relative velocity (reference heading frame);
        the orientation error is log(q_d q^-1) (world rotation vector)."""
        p = self.p
        v_d = target["vel"] + from_heading(target["yaw"], rel_vel)
        w_d = target["ang_vel"] + from_heading(target["yaw"], rel_ang)
        rot_err = R.log_map(R.multiply(target["rot"], R.conjugate(self.rot)))
        acc = np.empty((self.num_envs, 6))
        acc[:, :3] = p.kp * (target["pos"] - self.pos) + p.kd * (v_d - self.vel)
        acc[:, 3:] = p.kp * rot_err + p.kd * (w_d - self.ang_vel)
        return np.clip(acc, p.acc_min, p.acc_max)

    def world_inertia(self) -> np.ndarray:
        m = R.to_matrix(self.rot)
        return m @ self.body.inertia @ m.transpose(0, 2, 1)

    def advance_body(
        self, acc_des: np.ndarray, points: np.ndarray, active: np.ndarray, push: np.ndarray | None, h: float
    ) -> dict:
        """One QP solve and one semi-implicit Euler step of length h (s). `push` (N, 3) N, world."""
        batch = QPBatch(
            points=points,
            active=active,
            com=self.pos,
            inertia=self.world_inertia(),
            ang_vel=self.ang_vel,
            acc_des=acc_des,
        )
        out = solve_batch(batch, self.qp, self.p.solver)
        lin = out["qdd"][:, :3] if push is None else out["qdd"][:, :3] + push / self.body.mass
        self.vel += h * lin
        self.pos += h * self.vel
        self.ang_vel += h * out["qdd"][:, 3:]
        self.rot = R.normalize(R.multiply(R.exp_map(self.ang_vel * h), self.rot))
        self.stats["qp_solves"] += self.num_envs
        self.stats["qp_failures"] += int((out["flags"] < 0).sum())
        return out

    def advance_reference(self) -> None:
        """Move every environment to its next reference frame, with paper §6's touch-down rules."""
        ref, p = self.ref, self.p
        new = self.frame + 1
        sched = ref.stance[new % ref.cycle]
        touch = ~self.stance & sched
        lift = self.stance & ~sched
        if p.td_enabled:
            y_ref = ref.state(new)["pos"][:, 1]
            late = touch.any(axis=1) & (self.pos[:, 1] > y_ref + p.late_margin) & (self.delay < p.max_delay)
        else:
            late = np.zeros(self.num_envs, dtype=bool)
        go = ~late
        self.stance[go] = (self.stance | touch)[go] & ~lift[go]
        self.frame[go] = new[go]
        self.delay[go] = 0
        self.delay[late] += 1
        self.stats["late_touchdowns"] += int(late.sum())
        if p.td_enabled:
            self._early_touchdown(go)

    def _early_touchdown(self, moved: np.ndarray) -> None:
        """A swing foot whose COM sank below the touch-down height in the late part of its swing
        lands now: the reference jumps to that foot's touch-down frame (paper §6)."""
        ref, p = self.ref, self.p
        i = self.frame % ref.cycle
        low = self.pos[:, 1] < ref.touchdown_height - p.early_margin
        early = (moved & low)[:, None] & ~self.stance & ~ref.stance[i] & (ref.swing_progress[i] >= p.early_min_swing)
        if not early.any():
            return
        envs = np.flatnonzero(early.any(axis=1))
        foot = np.argmax(early[envs], axis=1)
        ahead = ref.next_touchdown[i[envs], foot] - i[envs]
        self.frame[envs] += ahead
        self.stance[envs] = ref.stance[self.frame[envs] % ref.cycle]
        self.stance[envs, foot] = True
        if p.zero_vertical_velocity:
            self.vel[envs, 1] = np.maximum(self.vel[envs, 1], 0.0)
        self.stats["early_touchdowns"] += int(envs.size)

    # ------------------------------------------------------------------ reward / termination
    def terminated(self) -> np.ndarray:
        """Paper §5.3: COM height outside [min(0.7 y_ref, 0.2), 2.0] or tilt above 70 degrees."""
        p = self.p
        y_ref = self.ref.state(self.frame)["pos"][:, 1]
        lo = np.minimum(p.min_height_ratio * y_ref, p.min_height_abs)
        y = self.pos[:, 1]
        return (y < lo) | (y > p.max_height) | (R.up_y(self.rot) < np.cos(p.max_tilt))

    def mimic_terms(self, before: dict, frame0: np.ndarray) -> dict[str, np.ndarray]:
        """Weighted squared errors of paper §5.2's pose, end-effector and velocity terms for the step
        just taken (SRB from t to t+1 vs the reference from frame0 to frame0 + 1)."""
        ref, p = self.ref, self.p
        r0, r1 = ref.state(frame0), ref.state(frame0 + 1)
        yaw0, ryaw0 = heading_of(before["rot"]), r0["yaw"]
        d_srb = to_heading(yaw0, self.pos - before["pos"])
        d_ref = to_heading(ryaw0, r1["pos"] - r0["pos"])
        d_err = np.sum((d_srb - d_ref) ** 2, -1)
        q_srb = R.multiply(R.heading_quat(-yaw0), self.rot)
        q_ref = R.multiply(R.heading_quat(-ryaw0), r1["rot"])
        pose = p.k_disp * d_err + p.k_rot * R.angle_between(q_srb, q_ref) ** 2
        pts = to_heading(yaw0, before["points"] - before["pos"][:, None, :]).reshape(-1, 2, 2, 3)
        err = np.sum((pts - ref.sole_local[frame0 % ref.cycle]) ** 2, -1).sum(-1)  # (N, 2)
        ee = p.k_ee * (np.sum(np.where(before["stance"], err, 0.0), -1) + d_err)
        v_srb = to_heading(heading_of(self.rot), self.pos - before["pos"]) / self.dt
        v_ref = to_heading(r1["yaw"], r1["pos"] - r0["pos"]) / self.dt
        vel = p.k_vel * np.sum((v_srb - v_ref) ** 2, -1)
        return {"pose": pose, "ee": ee, "vel": vel}

    # ------------------------------------------------------------------ step
    def step(
        self, action: np.ndarray, push: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        """Advance all environments one control step.

        `action` (N, 10) policy units; `push` (N, 3) world force (N) held over the step, unknown to
        the QP. Returns (obs, reward, terminated, truncated, info); with auto_reset, finished
        environments restart and info["final_obs"] holds their last observation.
        """
        a = np.asarray(action, dtype=float) * self.action_scale
        before = {"pos": self.pos.copy(), "rot": self.rot.copy(), "stance": self.stance.copy()}
        frame0 = self.frame.copy()
        target = self.ref.state(frame0 + 1)
        self.place_swing_feet(a[:, :4], frame0 + 1)
        points = self.contact_points()
        before["points"] = points
        active = np.repeat(self.stance, 2, axis=1)
        h = self.dt / self.p.substeps
        for _ in range(self.p.substeps):
            acc_des = self.desired_acceleration(target, a[:, 4:7], a[:, 7:10])
            out = self.advance_body(acc_des, points, active, push, h)
        self.last_forces, self.last_tau = out["forces"], out["tau"]
        self.advance_reference()
        self.steps += 1
        terminal = self.terminated()
        truncated = ~terminal & (self.steps >= self.max_steps)
        terms = self.mimic_terms(before, frame0)
        mimic = -(terms["pose"] + terms["ee"] + terms["vel"])
        reward = np.maximum(0.0, self.p.w_stand * (~terminal) + self.p.w_mimic * mimic)
        self.episode_return += reward
        info: dict = {"terms": terms, "done_idx": np.zeros(0, dtype=int)}
        done = terminal | truncated
        obs = self.observe()
        if done.any():
            idx = np.flatnonzero(done)
            info["final_obs"] = obs[idx].copy()
            info["done_idx"] = idx
            info["episode_return"] = self.episode_return[idx].copy()
            info["episode_length"] = self.steps[idx].copy()
            if self.auto_reset:
                self.reset(idx)
                obs = self.observe()
        return obs, reward, terminal, truncated, info
