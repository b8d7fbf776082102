"""Policy state s_t and discriminator observation o_t (docs/cgail.md, §5.1-5.2), from kinematic arrays.

The same functions serve the simulator (exact velocities from MuJoCo) and the motion clips
(finite differences), so data and policy samples share one definition, and they are written once
for numpy and torch arrays alike (the array API via `array_compat`): the CPU backend passes
numpy arrays (fastest there), the on-device backend (env.backend=warp) and the web graph torch
tensors, so the two backends cannot drift. Everything is in the
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

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from charctl.motion import rotations as R
from charctl.motion.array_compat import Array, namespace, rotations_for
from charctl.motion.skeleton import END_EFFECTORS, load_skeleton

STATE_DIM = 241
DISC_OBS_DIM = 133


@dataclass
class Kinematics:
    """World-frame kinematic arrays of a batch of characters (leading dim N): numpy arrays or torch
    tensors (all of one kind), y-up, SI units."""

    body_pos: Array  # (N, 15, 3) body frame origins, m
    body_rot: Array  # (N, 15, 4) xyzw
    lin_vel: Array  # (N, 15, 3) m/s of the body frame origins
    ang_vel: Array  # (N, 15, 3) rad/s
    com: Array  # (N, 3) whole-body centre of mass, m
    com_vel: Array  # (N, 3) m/s
    body_mat: Array | None = None  # (N, 15, 3, 3) rotation matrices of body_rot, when already computed


def heading_inverse(root_rot: Array) -> Array:
    """(N, 4) quaternion removing the root's heading (rotation by -yaw about +y)."""
    RX = rotations_for(root_rot)
    return RX.heading_quat(-RX.yaw_about_y(root_rot))


@functools.lru_cache(maxsize=1)
def _skeleton_indices() -> dict[str, np.ndarray]:
    """Skeleton index arrays: end effectors, the clip joints' bodies and their parents."""
    skel = load_skeleton()
    joints = np.asarray(skel.clip_joint_bodies)
    return {
        "ee": np.array([skel.index(n) for n in END_EFFECTORS]),
        "joints": joints,
        "parents": np.asarray(skel.parents)[joints],
    }


@functools.lru_cache(maxsize=8)
def _torch_indices(device: str) -> dict[str, Any]:
    import torch

    return {k: torch.as_tensor(v, device=device) for k, v in _skeleton_indices().items()}


def _indices(x: Array) -> dict[str, Any]:
    """`_skeleton_indices` as arrays of `x`'s library (and device)."""
    return _skeleton_indices() if isinstance(x, np.ndarray) else _torch_indices(str(x.device))


@dataclass
class HeadingFrame:
    """Quantities both feature vectors need, computed once per batch (heading frame, see module doc).

    Rotations are applied as 3x3 matrices (batched matmul): one quaternion-to-matrix conversion of
    every body serves the body rotations of the state and the local joint rotations of o."""

    h_t: Array  # (N, 3, 3) transpose of the matrix removing the root's yaw: v_heading = v @ h_t
    body_mat: Array  # (N, 15, 3, 3) world rotation matrices of the bodies
    root: Array  # (N, 3) world root position
    rel: Array  # (N, 15, 3) body positions relative to the root, heading frame
    lin: Array  # (N, 15, 3) body linear velocities, heading frame
    heading: Array | None = None  # (N,) the root's yaw about +y (rad) that h_t removes

    def rotate(self, v: Array) -> Array:
        """(N, 3) or (N, B, 3) world vectors in the heading frame."""
        if v.ndim == 2:
            return (v[:, None, :] @ self.h_t)[:, 0]
        return v @ self.h_t


def heading_frame(k: Kinematics) -> HeadingFrame:
    """The shared heading-frame terms of a batch (reuses `k.body_mat` when the caller has it)."""
    RX = rotations_for(k.body_pos)
    root = k.body_pos[:, 0]
    heading = RX.yaw_about_y(k.body_rot[:, 0])
    h_t = RX.to_matrix(RX.heading_quat(-heading)).swapaxes(-1, -2)  # heading_inverse, keeping the yaw
    rel = (k.body_pos - root[:, None]) @ h_t
    body_mat = RX.to_matrix(k.body_rot) if k.body_mat is None else k.body_mat
    return HeadingFrame(h_t, body_mat, root, rel, k.lin_vel @ h_t, heading)


def _first_two_columns(m: Array) -> Array:
    """(..., 3, 3) rotation matrices -> (..., 6): their first two columns (the 6-D rotation features)."""
    return namespace(m).concat([m[..., :, 0], m[..., :, 1]], axis=-1)


def policy_state(k: Kinematics, f: HeadingFrame | None = None) -> Array:
    """(N, 241) policy state in the heading frame (`f`: the batch's heading frame if already computed)."""
    ee = _indices(k.body_pos)["ee"]
    f = heading_frame(k) if f is None else f
    N = k.body_pos.shape[0]
    h = f.h_t.swapaxes(-1, -2)  # the heading matrix itself
    rot = _first_two_columns(h[:, None] @ f.body_mat)
    parts = [
        f.root[:, 1:2],
        f.rel[:, 1:].reshape(N, -1),
        rot.reshape(N, -1),
        f.lin.reshape(N, -1),
        f.rotate(k.ang_vel).reshape(N, -1),
        f.rotate(k.com - f.root),
        f.rotate(k.com_vel),
        f.rel[:, ee].reshape(N, -1),
    ]
    return namespace(f.rel).concat(parts, axis=1)


def disc_obs(k: Kinematics, f: HeadingFrame | None = None) -> Array:
    """(N, 133) discriminator observation o_t in the heading frame (no command in it)."""
    ix = _indices(k.body_pos)
    ee = ix["ee"]
    f = heading_frame(k) if f is None else f
    N = k.body_pos.shape[0]
    local = f.body_mat[:, ix["parents"]].swapaxes(-1, -2) @ f.body_mat[:, ix["joints"]]  # R_parent^T R_child
    parts = [
        f.root[:, 1:2],
        f.lin[:, 0],
        f.rotate(k.ang_vel[:, 0]),
        _first_two_columns(local).reshape(N, -1),
        f.lin[:, 1:].reshape(N, -1),
        f.rel[:, ee].reshape(N, -1),
    ]
    return namespace(f.rel).concat(parts, axis=1)


def state_and_obs(k: Kinematics) -> tuple[Array, Array]:
    """(policy_state(k), disc_obs(k)) with their shared heading-frame terms computed once."""
    f = heading_frame(k)
    return policy_state(k, f), disc_obs(k, f)


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


def sim_kinematics(sim, rows: np.ndarray | slice = slice(None)) -> Kinematics:
    """Kinematics of envs `rows` (default all) of a BatchedHumanoid after a step (exact MuJoCo velocities)."""
    pos = sim.body_pos_rows(rows)
    rot = sim.body_quat_rows(rows)
    lin, ang = sim.body_velocities_rows(rows, pos)
    com = sim.subtree_com[rows][:, 1]
    mass = sim.model.body_subtreemass[1]
    # COM velocity = mass-weighted body COM velocities; body COM = frame origin + rotated local offset
    skel = load_skeleton()
    body_mat = R.to_matrix(rot)
    offset = np.matmul(body_mat, skel.com_local[:, :, None])[..., 0]  # body COM - frame origin, world
    com_vel_bodies = lin + R.cross(ang, offset)
    com_vel = np.einsum("nbi,b->ni", com_vel_bodies, skel.masses) / mass
    return Kinematics(pos, rot, lin, ang, com.copy(), com_vel, body_mat)
