"""The whole body over a timeline of hopper cycles: leg points, the upper-body balance model (eq 7-11) and
the joint angles, vectorised over a population axis N. Frames as in model.py's docstring; units: metres,
seconds, kilograms, radians."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from charctl.experiments.hopper_ga.character import Body, upper_fk, upper_segment_com
from charctl.experiments.hopper_ga.hopper import Cycle, d_from_bend, leg_lengths
from charctl.experiments.hopper_ga.settings import BALANCE_LIMIT, Params, Settings


# ---------------------------------------------------------------------------- timeline of cycles
@dataclass
class Timeline:
    """Frames of one or more cycles in world coordinates. Leg axis: 0 = right, 1 = left."""

    t: np.ndarray  # (N, K)
    dt: np.ndarray  # (N, K)
    mask: np.ndarray  # (N, K)
    xdot: np.ndarray  # (N, K) HIP speed of the frame's cycle
    hip: np.ndarray  # (N, K, 2) world (x, y)
    theta_c: np.ndarray  # (N, K, 2) right, left
    theta_l: np.ndarray  # (N, K, 2)
    target: np.ndarray  # (N, K, 2) eq 7 target COM (x, z) in the ground plane
    support: np.ndarray  # (N, K) 0 right stance, 1 left stance, -1 flight
    lift: np.ndarray  # (N,) first lift-off frame
    end: np.ndarray  # (N,) last frame
    l: np.ndarray  # (N,)


def single_cycle_timeline(c: Cycle, p: Params, s: Settings) -> Timeline:
    """The GA's evaluation window: one cycle, right leg idle, starting at the right foot x = 0."""
    w = s.body.hip_half_width
    tz = w + (-w - w) * c.target_w  # right foot (+w) -> left foot (-w)
    support = np.where(c.target_w > 0, -1, 0)
    return Timeline(
        t=c.t,
        dt=c.dt,
        mask=c.mask,
        xdot=np.broadcast_to(c.xdot[:, None], c.t.shape),
        hip=c.hip,
        theta_c=c.theta_c,
        theta_l=c.theta_l,
        target=np.stack([c.target_x, tz], -1),
        support=support,
        lift=c.lift,
        end=c.end,
        l=p.l,
    )


def repeat_cycles(cycles: list[Cycle], p: Params, s: Settings, first_right: bool = True) -> Timeline:
    """Chain cycles (N = 1 each) into a run, alternating the stance leg; the touchdown frame of
    one cycle is the first frame of the next. Used for export, the COM path and the limp test."""
    w = s.body.hip_half_width
    t_all, dt_all, xd_all, hip_all, tc_all, tl_all, tar_all, sup_all = [], [], [], [], [], [], [], []
    x_off, t_off = 0.0, 0.0
    for i, c in enumerate(cycles):
        if c.t.shape[0] != 1:
            raise ValueError("repeat_cycles takes single-individual cycles")
        n = int(c.end[0]) + 1
        start = 0 if i == 0 else 1
        right = (i % 2 == 0) == first_right
        z_i = w if right else -w
        sl = slice(start, n)
        order = [0, 1] if right else [1, 0]  # leg axis: idle/active -> right/left
        t_all.append(c.t[0, sl] + t_off)
        dt_all.append(c.dt[0, sl])
        xd_all.append(np.full(n - start, c.xdot[0]))
        hip_all.append(c.hip[0, sl] + [x_off, 0.0])
        tc_all.append(c.theta_c[0, sl][:, order])
        tl_all.append(c.theta_l[0, sl][:, order])
        tz = z_i + (-z_i - z_i) * c.target_w[0, sl]
        tar_all.append(np.stack([c.target_x[0, sl] + x_off, tz], -1))
        sup_all.append(np.where(c.target_w[0, sl] > 0, -1, 0 if right else 1))
        a_land = c.hip[0, n - 1, 0] + p.l[0] * np.sin(p.theta0[0])  # landing foot x (next cycle's origin)
        x_off += a_land
        t_off += c.t[0, n - 1]
    cat = lambda v: np.concatenate(v)[None]  # noqa: E731
    K = sum(len(v) for v in t_all)
    return Timeline(
        t=cat(t_all),
        dt=cat(dt_all),
        mask=np.ones((1, K), dtype=bool),
        xdot=cat(xd_all),
        hip=cat(hip_all),
        theta_c=cat(tc_all),
        theta_l=cat(tl_all),
        target=cat(tar_all),
        support=cat(sup_all),
        lift=cycles[0].lift.copy(),
        end=np.array([K - 1]),
        l=p.l.copy(),
    )


# ---------------------------------------------------------------------------- geometry of the whole body
@dataclass
class LegPoints:
    hip: np.ndarray  # (N, K, 2, 3) hip joints (right, left)
    knee: np.ndarray
    foot: np.ndarray
    thigh_dir: np.ndarray
    shank_dir: np.ndarray


def leg_points(tl: Timeline, s: Settings) -> LegPoints:
    """3-D hip, knee and foot positions of both legs (world, m)."""
    a, b = leg_lengths(tl.l, s)
    a4, b4 = a[:, None, None, None], b[:, None, None, None]
    w = s.body.hip_half_width
    N, K = tl.mask.shape
    hip = np.zeros((N, K, 2, 3))
    hip[..., 0] = tl.hip[..., 0, None]
    hip[..., 1] = tl.hip[..., 1, None]
    hip[..., 2] = [w, -w]
    ang = tl.theta_c + tl.theta_l
    thigh = np.stack([np.sin(ang), -np.cos(ang), np.zeros_like(ang)], -1)
    d = d_from_bend(tl.theta_l, a[:, None, None], b[:, None, None])[..., None]
    foot = hip + d * np.stack([np.sin(tl.theta_c), -np.cos(tl.theta_c), np.zeros_like(ang)], -1)
    knee = hip + a4 * thigh
    shank = (foot - knee) / b4
    return LegPoints(hip=hip, knee=knee, foot=foot, thigh_dir=thigh, shank_dir=shank)


def lower_mass_moment(tl: Timeline, legs: LegPoints, s: Settings) -> np.ndarray:
    """(N, K, 3) sum of M_i L_i (eq 8) over the pelvis and both legs."""
    body = s.body
    a, b = leg_lengths(tl.l, s)
    thigh_com = legs.hip + (body.thigh_com * a)[:, None, None, None] * legs.thigh_dir
    shank_com = legs.knee + (body.shank_com * b)[:, None, None, None] * legs.shank_dir
    pelvis = np.concatenate([tl.hip, np.zeros(tl.hip.shape[:-1] + (1,))], -1)
    return (
        body.pelvis_mass * pelvis
        + body.thigh_mass * (thigh_com[..., 0, :] + thigh_com[..., 1, :])
        + body.shank_mass * (shank_com[..., 0, :] + shank_com[..., 1, :])
    )


# ---------------------------------------------------------------------------- balance (eq 7-11)
@dataclass
class Balance:
    angles: np.ndarray  # (N, K, D) balance DOF angles (rad), order of body.dof_names
    com: np.ndarray  # (N, K, 3) whole-body COM (eq 8)
    code: np.ndarray  # (N,)


def dof_to_joint_angles(z: np.ndarray, body: Body) -> np.ndarray:
    """(..., D) DOF angles -> (..., J, 2) (phi_z, phi_x) per upper joint."""
    out = np.zeros(z.shape[:-1] + (len(body.names), 2))
    out[..., body.dof_joint, body.dof_axis] = z
    return out


def run_balance(tl: Timeline, eta: np.ndarray, s: Settings) -> Balance:
    """Trunk response of eq 9-11, integrated with eq 10 over the timeline (all rows at once).

    delta = CM_tar - CM_cur in the ground plane (x, z). Per DOF, zd = eta delta_x h / x_dot
    (sagittal, z axis) and xd = eta (-delta_z) h / x_dot (lateral, x axis) in the paper's
    convention; in the charctl right-handed frame (z = right) leaning forward is a negative
    rotation about +z and leaning right a positive rotation about +x, so the applied responses
    are -eta delta_x h / x_dot about z and +eta delta_z h / x_dot about x: both move the COM
    towards the target, as the paper intends. The body starts upright at rest.
    """
    body = s.body
    N, K = tl.mask.shape
    D = body.num_dofs
    legs = leg_points(tl, s)
    lower = lower_mass_moment(tl, legs, s)
    pelvis = np.concatenate([tl.hip, np.zeros((N, K, 1))], -1)
    sagittal = body.dof_axis == 0
    Z = np.zeros((N, K, D))
    com = np.empty((N, K, 3))

    def com_of(k: int, z: np.ndarray) -> np.ndarray:
        pos, rot = upper_fk(body, pelvis[:, k], dof_to_joint_angles(z, body))
        seg = upper_segment_com(body, pos, rot)
        upper = (body.seg_mass[None, :, None] * seg).sum(axis=1) if len(body.names) else 0.0
        return (lower[:, k] + upper) / body.mass

    z1 = np.zeros((N, D))
    z2 = np.zeros((N, D))
    z3 = np.zeros((N, D))
    com[:, 0] = com_of(0, z1)
    h_prev = np.full(N, s.h)
    for k in range(1, K):
        h_k = tl.dt[:, k]
        delta = tl.target[:, k - 1] - com[:, k - 1][:, [0, 2]]  # eq 9, (x, z)
        err = np.where(sagittal, -delta[:, :1], delta[:, 1:])  # eq 11 in the charctl frame
        resp = eta * err * (h_k / tl.xdot[:, k - 1])[:, None]
        v1 = (z1 - z2) / tl.dt[:, k - 1, None]
        v2 = (z2 - z3) / h_prev[:, None]
        acc = (v1 - v2) / tl.dt[:, k - 1, None]
        z_new = z1 + ((v1 + acc * h_k[:, None]) * h_k[:, None] + resp) / 2.0  # eq 10
        z_new = np.where(tl.mask[:, k, None], z_new, z1)
        Z[:, k] = z_new
        com[:, k] = com_of(k, z_new)
        h_prev = tl.dt[:, k - 1]
        z3, z2, z1 = z2, z1, z_new
    over = np.any(tl.mask[..., None] & ~(np.abs(Z) <= s.angle_limit), axis=(1, 2))
    return Balance(angles=Z, com=com, code=np.where(over, BALANCE_LIMIT, 0))


# ---------------------------------------------------------------------------- joint angles
def leg_joint_angles(tl: Timeline, legs: LegPoints) -> np.ndarray:
    """(N, K, 4) sagittal rotations (rad, about +z) of right hip, right knee, left hip, left knee.
    Hip = thigh angle from straight down (forward positive); knee = shank minus thigh (<= 0: flexion)."""
    thigh = tl.theta_c + tl.theta_l
    shank = np.arctan2(legs.shank_dir[..., 0], -legs.shank_dir[..., 1])
    knee = shank - thigh
    return np.stack([thigh[..., 0], knee[..., 0], thigh[..., 1], knee[..., 1]], -1)


def dof_inertia(l: np.ndarray, s: Settings) -> np.ndarray:
    """(N, 4 + D) rotational inertia I_i (kg m^2) of every joint DOF of eq 12, rest pose, rods."""
    body = s.body
    a, b = leg_lengths(l, s)
    mt, ms = body.thigh_mass, body.shank_mass
    I_hip = mt * (a * a / 12 + (body.thigh_com * a) ** 2) + ms * (b * b / 12 + (a + body.shank_com * b) ** 2)
    I_knee = ms * (b * b / 12 + (body.shank_com * b) ** 2)
    legs = np.stack([I_hip, I_knee, I_hip, I_knee], -1)
    return np.concatenate([legs, np.broadcast_to(body.dof_inertia, (l.shape[0], body.num_dofs))], -1)
