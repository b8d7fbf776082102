"""Torch implementation of the cgail features, rewards and episode ends, for the on-device (MuJoCo Warp) path.

The single definition of what the policy sees, what the discriminator sees, the tracking and goal
rewards and when an episode ends, as batched torch ops that run on the simulation's device
without a host round trip. The C (numpy) backend keeps `features.py` / `env.py`: numpy is faster
there even over copy-free `torch.from_numpy` views of MuJoCo's arrays, because torch's per-call overhead
dominates at these batch sizes (docs/cgail.md, "Throughput (CPU)"; `scripts/bench_cgail_torch_cpu.py`).
`tests/test_gpu_path.py` holds the two implementations equal on the same inputs (float64: to 1e-12;
float32: to float32 rounding).

Frames and units as in `features.py`: heading frame (the root's yaw about +y removed: +x facing,
y up, +z the character's right), metres, m/s, rad/s; quaternions xyzw.

    state (241):  root height 1 | body positions rel. root 14x3 | body rotations 15x6 | body linear
        velocities 15x3 | body angular velocities 15x3 | COM rel. root 3 | COM velocity 3 |
        end-effector positions rel. root 4x3
    disc obs o (133):  root height 1 | root linear velocity 3 | root angular velocity 3 | local joint
        rotations of the 12 clip joints 12x6 | body linear velocities 14x3 | end-effector positions 4x3
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import torch

from charctl.experiments.cgail.env import (
    _OBS_EE,
    _OBS_ROOT_H,
    _OBS_ROOT_V,
    _OBS_ROT,
    _OBS_VEL,
    TRACK_SCALES,
    TRACK_WEIGHTS,
)
from charctl.experiments.cgail.features import DISC_OBS_DIM, STATE_DIM
from charctl.motion import rotations_torch as RT
from charctl.motion.skeleton import END_EFFECTORS, load_skeleton

__all__ = [
    "DISC_OBS_DIM",
    "STATE_DIM",
    "Kinematics",
    "disc_obs",
    "episode_end",
    "goal_reward",
    "policy_state",
    "sim_kinematics",
    "tracking_reward",
]


@dataclass
class Kinematics:
    """World-frame kinematic tensors of a batch of characters (leading dim N), y-up, SI units."""

    body_pos: torch.Tensor  # (N, 15, 3) body frame origins, m
    body_rot: torch.Tensor  # (N, 15, 4) xyzw
    lin_vel: torch.Tensor  # (N, 15, 3) m/s of the body frame origins
    ang_vel: torch.Tensor  # (N, 15, 3) rad/s
    com: torch.Tensor  # (N, 3) whole-body centre of mass, m
    com_vel: torch.Tensor  # (N, 3) m/s


@functools.lru_cache(maxsize=8)
def _indices(device: str) -> dict[str, torch.Tensor]:
    """Skeleton index tensors on `device` (end effectors, clip joints and their parents, masses, COM offsets)."""
    skel = load_skeleton()
    joints = np.asarray(skel.clip_joint_bodies)
    dev = torch.device(device)
    return {
        "ee": torch.as_tensor(np.array([skel.index(n) for n in END_EFFECTORS]), device=dev),
        "joints": torch.as_tensor(joints, device=dev),
        "parents": torch.as_tensor(np.asarray(skel.parents)[joints], device=dev),
        "masses": torch.as_tensor(skel.masses, dtype=torch.float64, device=dev),
        "com_local": torch.as_tensor(skel.com_local, dtype=torch.float64, device=dev),
    }


def _idx(t: torch.Tensor) -> dict[str, torch.Tensor]:
    return _indices(str(t.device))


def heading_inverse(root_rot: torch.Tensor) -> torch.Tensor:
    """(N, 4) quaternion removing the root's heading (rotation by -yaw about +y)."""
    return RT.heading_quat(-RT.yaw_about_y(root_rot))


def _rot6(q: torch.Tensor) -> torch.Tensor:
    """(..., 4) -> (..., 6): first two columns of the rotation matrix."""
    m = RT.to_matrix(q)
    return torch.cat([m[..., :, 0], m[..., :, 1]], dim=-1)


def policy_state(k: Kinematics) -> torch.Tensor:
    """(N, 241) policy state in the heading frame (see the module docstring for the layout)."""
    ee = _idx(k.body_pos)["ee"]
    N = k.body_pos.shape[0]
    hinv = heading_inverse(k.body_rot[:, 0])
    h_b = hinv[:, None].expand(N, k.body_pos.shape[1], 4)
    root = k.body_pos[:, 0]
    rel = RT.rotate(h_b, k.body_pos - root[:, None])
    rot = _rot6(RT.multiply(h_b, k.body_rot))
    lin = RT.rotate(h_b, k.lin_vel)
    ang = RT.rotate(h_b, k.ang_vel)
    com = RT.rotate(hinv, k.com - root)
    com_v = RT.rotate(hinv, k.com_vel)
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
    return torch.cat(parts, dim=1)


def disc_obs(k: Kinematics) -> torch.Tensor:
    """(N, 133) discriminator observation o_t in the heading frame (no command in it)."""
    ix = _idx(k.body_pos)
    N = k.body_pos.shape[0]
    hinv = heading_inverse(k.body_rot[:, 0])
    h_b = hinv[:, None].expand(N, k.body_pos.shape[1], 4)
    root = k.body_pos[:, 0]
    lin = RT.rotate(h_b, k.lin_vel)
    ang_root = RT.rotate(hinv, k.ang_vel[:, 0])
    local = RT.multiply(RT.conjugate(k.body_rot[:, ix["parents"]]), k.body_rot[:, ix["joints"]])
    rel = RT.rotate(h_b, k.body_pos - root[:, None])
    parts = [
        root[:, 1:2],
        lin[:, 0],
        ang_root,
        _rot6(local).reshape(N, -1),
        lin[:, 1:].reshape(N, -1),
        rel[:, ix["ee"]].reshape(N, -1),
    ]
    return torch.cat(parts, dim=1)


def sim_kinematics(sim) -> Kinematics:
    """Kinematics of a `WarpBatchedHumanoid` after a step (exact MuJoCo velocities), on its device.

    COM velocity = mass-weighted velocities of the body centres of mass (frame origin + rotated
    local COM offset), as in `features.sim_kinematics`.
    """
    lin, ang = sim.body_velocities()
    pos, rot = sim.body_pos, sim.body_quat_xyzw
    ix = _idx(pos)
    com_local = ix["com_local"].to(pos.dtype)
    masses = ix["masses"].to(pos.dtype)
    offset = RT.rotate(rot, com_local.expand(pos.shape))
    com_vel_bodies = lin + torch.cross(ang, offset, dim=-1)
    com_vel = torch.einsum("nbi,b->ni", com_vel_bodies, masses) / sim.total_mass
    return Kinematics(pos, rot, lin, ang, sim.com().clone(), com_vel)


def tracking_reward(obs: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    """(N,) DeepMimic-style tracking reward in [0, 1] between simulated and reference disc observations
    (N, 133); the formula, weights and scales of `env.tracking_reward` (docs/cgail.md)."""

    def sq(sl: slice) -> torch.Tensor:
        return ((obs[:, sl] - ref[:, sl]) ** 2).sum(dim=1)

    w, k = TRACK_WEIGHTS, TRACK_SCALES
    root = torch.exp(-k["root_height"] * sq(_OBS_ROOT_H) - k["root_vel"] * sq(_OBS_ROOT_V))
    return (
        w["pose"] * torch.exp(-k["pose"] * sq(_OBS_ROT))
        + w["vel"] * torch.exp(-k["vel"] * sq(_OBS_VEL))
        + w["ee"] * torch.exp(-k["ee"] * sq(_OBS_EE))
        + w["root"] * root
    )


def goal_reward(
    goal_angle: torch.Tensor,
    com_vel: torch.Tensor,
    target_speed: torch.Tensor,
    has_goal: torch.Tensor,
    sharpness: float,
) -> torch.Tensor:
    """(N,) heading-goal reward r_G in [0, 1]: exp(-sharpness (v* - d . v_xz)^2) with d the goal's
    horizontal direction (world yaw `goal_angle` radians about +y -> (cos, -sin) in x-z), v the COM
    velocity (m/s) and v* the skill's mean speed (m/s); 1 for skills without a heading goal."""
    along = torch.cos(goal_angle) * com_vel[:, 0] - torch.sin(goal_angle) * com_vel[:, 2]
    r = torch.exp(-sharpness * (target_speed - along) ** 2)
    return torch.where(has_goal, r, torch.ones_like(r))


def episode_end(
    fell: torch.Tensor, unstable: torch.Tensor, steps: torch.Tensor, max_steps: int, clip_ended: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """(terminated, truncated) bool masks: a fall (a non-foot body on the ground) or a simulator blow-up
    terminates; reaching `max_steps` control steps (`steps` counted after this step) or the end of a
    non-looping reference clip truncates, unless the step also terminated."""
    terminated = fell | unstable
    truncated = ((steps >= max_steps) | clip_ended) & ~terminated
    return terminated, truncated
