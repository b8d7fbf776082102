"""Policy state s_t and discriminator observation o_t (docs/cgail.md, §5.1-5.2), from kinematic arrays.

The same functions serve the simulator (exact velocities from MuJoCo) and the motion clips
(finite differences), so data and policy samples share one definition. Everything is in the
character's heading frame: the root's yaw about +y is removed, so +x is the facing direction,
y is up and +z the character's right (the paper's frame with z forward is this one turned by
90 degrees about y; only the axis naming differs). Units: metres, m/s, rad/s.

    state (241 + 2 goal = 243):  root height 1 | body positions rel. root 14x3 | body rotations 15x6
        (first two columns of each rotation matrix) | body linear velocities 15x3 | body angular
        velocities 15x3 | COM rel. root 3 | COM velocity 3 | end-effector positions rel. root 4x3
    disc obs o (133):  root height 1 | root linear velocity 3 | root angular velocity 3 | local joint
        rotations of the 12 clip joints 12x6 | joint (body) linear velocities 14x3 | end-effector
        positions rel. root 4x3
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from charctl.motion import rotations as R
from charctl.motion.skeleton import END_EFFECTORS, load_skeleton

STATE_DIM = 241
DISC_OBS_DIM = 133


@dataclass
class Kinematics:
    """World-frame kinematic arrays of a batch of characters (leading dim N)."""

    body_pos: np.ndarray  # (N, 15, 3) body frame origins
    body_rot: np.ndarray  # (N, 15, 4) xyzw
    lin_vel: np.ndarray  # (N, 15, 3)
    ang_vel: np.ndarray  # (N, 15, 3)
    com: np.ndarray  # (N, 3)
    com_vel: np.ndarray  # (N, 3)


def heading_inverse(root_rot: np.ndarray) -> np.ndarray:
    """(N, 4) quaternion removing the root's heading (rotation by -yaw about +y)."""
    return R.heading_quat(-R.yaw_about_y(root_rot))


def _rot6(q: np.ndarray) -> np.ndarray:
    """(..., 4) -> (..., 6): first two columns of the rotation matrix."""
    m = R.to_matrix(q)
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def _indices():
    skel = load_skeleton()
    ee = np.array([skel.index(n) for n in END_EFFECTORS])
    return skel, ee


def policy_state(k: Kinematics) -> np.ndarray:
    """(N, 241) policy state in the heading frame."""
    skel, ee = _indices()
    N = k.body_pos.shape[0]
    hinv = heading_inverse(k.body_rot[:, 0])
    h_b = np.broadcast_to(hinv[:, None], (N, skel.num_bodies, 4))
    root = k.body_pos[:, 0]
    rel = R.rotate(h_b, k.body_pos - root[:, None])
    rot = _rot6(R.multiply(h_b, k.body_rot))
    lin = R.rotate(h_b, k.lin_vel)
    ang = R.rotate(h_b, k.ang_vel)
    com = R.rotate(hinv, k.com - root)
    com_v = R.rotate(hinv, k.com_vel)
    parts = [
        root[:, 1:2],
        rel[:, 1:].reshape(N, -1),
        rot.reshape(N, -1),
        lin.reshape(N, -1),
        ang.reshape(N, -1),
        com,
        com_v,
        rel[:, ee].reshape(N, -1),
    ]
    return np.concatenate(parts, axis=1)


def disc_obs(k: Kinematics) -> np.ndarray:
    """(N, 133) discriminator observation o_t in the heading frame (no command in it)."""
    skel, ee = _indices()
    N = k.body_pos.shape[0]
    hinv = heading_inverse(k.body_rot[:, 0])
    h_b = np.broadcast_to(hinv[:, None], (N, skel.num_bodies, 4))
    root = k.body_pos[:, 0]
    lin = R.rotate(h_b, k.lin_vel)
    ang_root = R.rotate(hinv, k.ang_vel[:, 0])
    joints = skel.clip_joint_bodies
    parents = skel.parents[joints]
    local = R.multiply(R.conjugate(k.body_rot[:, parents]), k.body_rot[:, joints])
    rel = R.rotate(h_b, k.body_pos - root[:, None])
    parts = [
        root[:, 1:2],
        lin[:, 0],
        ang_root,
        _rot6(local).reshape(N, -1),
        lin[:, 1:].reshape(N, -1),
        rel[:, ee].reshape(N, -1),
    ]
    return np.concatenate(parts, axis=1)


def clip_kinematics(clip) -> Kinematics:
    """Kinematics of every frame of a clip (finite-difference velocities)."""
    from charctl.motion.clip import finite_difference

    com = clip.com()
    return Kinematics(
        clip.body_pos,
        clip.body_rot,
        clip.body_linear_velocity(),
        clip.world_angular_velocity(),
        com,
        finite_difference(com, clip.dt),
    )


def sim_kinematics(sim) -> Kinematics:
    """Kinematics of a BatchedHumanoid after a step (exact MuJoCo velocities)."""
    lin, ang = sim.body_velocities()
    com = sim.com()
    mass = sim.model.body_subtreemass[1]
    # COM velocity = mass-weighted body COM velocities; body COM = frame origin + rotated local offset
    skel = load_skeleton()
    body_com = sim.body_pos + R.rotate(sim.body_quat_xyzw, np.broadcast_to(skel.com_local, sim.body_pos.shape))
    com_vel_bodies = lin + np.cross(ang, body_com - sim.body_pos)
    com_vel = np.einsum("nbi,b->ni", com_vel_bodies, skel.masses) / mass
    return Kinematics(sim.body_pos.copy(), sim.body_quat_xyzw, lin, ang, com.copy(), com_vel)
