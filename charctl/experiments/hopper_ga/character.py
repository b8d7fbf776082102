"""The 11-joint character (paper Fig 2.1) as flat numpy tables, and its forward kinematics.

Joints: root (pelvis, at the hopper's HIP), chest, neck, right/left shoulder, right/left elbow
(the upper body, moved by the balance model) and right/left hip, right/left knee (the legs,
moved by the hopper). World frame: y up, the character runs along +x, right side is +z.
Rotations of a joint are R = Rz(phi_z) @ Rx(phi_x) in the parent's frame, radians.

Everything here is vectorised over a population axis N; the FK walks the hierarchy level by
level (3 levels for the default upper body), never joint by joint.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

LEG_DOFS = ("right_hip", "right_knee", "left_hip", "left_knee")  # sagittal (z) rotations driven by the hopper
AXIS_NAMES = ("z", "x")


@dataclass(frozen=True)
class Body:
    """Constant tables of the character (kg, m). Upper-body joint j has parent index parent[j]
    (-1 = the pelvis), `offset` in the parent's frame and a segment of `length` along `direction`."""

    mass: float  # kg, total
    pelvis_mass: float  # kg
    hip_half_width: float  # m
    thigh_mass: float  # kg per leg
    shank_mass: float  # kg per leg
    thigh_com: float
    shank_com: float
    names: tuple[str, ...]  # upper-body joints
    parent: np.ndarray  # (J,) int
    offset: np.ndarray  # (J, 3)
    direction: np.ndarray  # (J, 3) unit
    length: np.ndarray  # (J,)
    seg_mass: np.ndarray  # (J,) kg
    com: np.ndarray  # (J,) fraction along the segment
    levels: tuple[np.ndarray, ...]  # joint indices per depth level (parents first)
    dof_joint: np.ndarray  # (D,) balance DOF -> upper joint index
    dof_axis: np.ndarray  # (D,) 0 = z (sagittal, eq 10-11 zd_b), 1 = x (lateral, xd_b)
    dof_inertia: np.ndarray  # (D,) kg m^2, subtree inertia about the DOF axis in the rest pose

    @property
    def dof_names(self) -> list[str]:
        return [f"{self.names[j]}.{AXIS_NAMES[a]}" for j, a in zip(self.dof_joint, self.dof_axis)]

    @property
    def num_dofs(self) -> int:
        return int(self.dof_joint.shape[0])


def body_from_config(char) -> Body:
    """Build the tables from `cfg.character` (fractions of the total mass -> kg)."""
    upper = list(char.upper)
    names = tuple(s.name for s in upper)
    parent = np.array([-1 if s.parent == "root" else names.index(s.parent) for s in upper], dtype=int)
    depth = np.zeros(len(upper), dtype=int)
    for j, p in enumerate(parent):  # parents precede children (checked by Config.cross_checks); setup only
        depth[j] = 0 if p < 0 else depth[p] + 1
    levels = tuple(np.flatnonzero(depth == d) for d in range(int(depth.max()) + 1)) if len(upper) else ()
    direction = np.array([s.direction for s in upper], dtype=float).reshape(-1, 3)
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-12)
    dof_joint, dof_axis = [], []
    for j, s in enumerate(upper):
        for ch in s.axes:
            dof_joint.append(j)
            dof_axis.append(AXIS_NAMES.index(ch))
    M = float(char.mass)
    body = Body(
        mass=M,
        pelvis_mass=char.pelvis_mass * M,
        hip_half_width=float(char.hip_half_width),
        thigh_mass=char.thigh_mass * M,
        shank_mass=char.shank_mass * M,
        thigh_com=float(char.thigh_com),
        shank_com=float(char.shank_com),
        names=names,
        parent=parent,
        offset=np.array([s.offset for s in upper], dtype=float).reshape(-1, 3),
        direction=direction,
        length=np.array([s.length for s in upper], dtype=float),
        seg_mass=np.array([s.mass for s in upper], dtype=float) * M,
        com=np.array([s.com for s in upper], dtype=float),
        levels=levels,
        dof_joint=np.array(dof_joint, dtype=int),
        dof_axis=np.array(dof_axis, dtype=int),
        dof_inertia=np.zeros(0),
    )
    object.__setattr__(body, "dof_inertia", _rest_inertia(body))
    return body


def _rest_inertia(body: Body) -> np.ndarray:
    """Inertia (kg m^2) of each balance DOF's subtree about its axis, rest pose, segments as rods."""
    J = len(body.names)
    pos, rot = upper_fk(body, np.zeros((1, 3)), np.zeros((1, J, 2)))
    pos, rot = pos[0], rot[0]
    seg_com = pos + body.direction * (body.com * body.length)[:, None]
    sub = np.eye(J, dtype=bool)  # sub[j, s]: s is in the subtree of j
    for j in range(J - 1, -1, -1):  # setup only
        if body.parent[j] >= 0:
            sub[body.parent[j]] |= sub[j]
    out = []
    for j, a in zip(body.dof_joint, body.dof_axis):
        axis = np.eye(3)[2 if a == 0 else 0]
        r = seg_com[sub[j]] - pos[j]
        m = body.seg_mass[sub[j]]
        L = body.length[sub[j]]
        cos = body.direction[sub[j]] @ axis
        out.append(np.sum(m * (np.sum(r * r, 1) - (r @ axis) ** 2) + m * L**2 / 12.0 * (1.0 - cos**2)))
    return np.array(out)


# ---------------------------------------------------------------------------- small batched linear algebra
def rot_zx(phi: np.ndarray) -> np.ndarray:
    """(..., 2) angles (phi_z, phi_x) -> (..., 3, 3) R = Rz(phi_z) @ Rx(phi_x)."""
    cz, sz = np.cos(phi[..., 0]), np.sin(phi[..., 0])
    cx, sx = np.cos(phi[..., 1]), np.sin(phi[..., 1])
    zero = np.zeros_like(cz)
    rows = [
        np.stack([cz, -sz * cx, sz * sx], -1),
        np.stack([sz, cz * cx, -cz * sx], -1),
        np.stack([zero, sx, cx], -1),
    ]
    return np.stack(rows, -2)


def matmul3(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Batched 3x3 @ 3x3 written out (no BLAS: the result of a row never depends on the batch size)."""
    return (
        A[..., :, 0, None] * B[..., None, 0, :]
        + A[..., :, 1, None] * B[..., None, 1, :]
        + A[..., :, 2, None] * B[..., None, 2, :]
    )


def matvec3(A: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Batched 3x3 @ 3-vector, written out."""
    return A[..., :, 0] * v[..., None, 0] + A[..., :, 1] * v[..., None, 1] + A[..., :, 2] * v[..., None, 2]


def upper_fk(body: Body, pelvis: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World joint positions (N, J, 3) and rotations (N, J, 3, 3) of the upper body.

    pelvis: (N, 3) world position of the root (HIP); the pelvis itself stays upright, facing +x.
    angles: (N, J, 2) local (phi_z, phi_x) per upper joint, radians.
    """
    N, J = angles.shape[0], angles.shape[1]
    local = rot_zx(angles)
    world = np.empty((N, J, 3, 3))
    pos = np.empty((N, J, 3))
    for lv in body.levels:  # 3 depth levels, each vectorised over its joints
        par = body.parent[lv]
        root = par < 0
        prot = np.where(root[None, :, None, None], np.eye(3), world[:, np.maximum(par, 0)])
        ppos = np.where(root[None, :, None], pelvis[:, None, :], pos[:, np.maximum(par, 0)])
        pos[:, lv] = ppos + matvec3(prot, np.broadcast_to(body.offset[lv], (N, len(lv), 3)))
        world[:, lv] = matmul3(prot, local[:, lv])
    return pos, world


def upper_segment_com(body: Body, pos: np.ndarray, world: np.ndarray) -> np.ndarray:
    """(N, J, 3) COM of each upper segment from the FK output."""
    local = body.direction * (body.com * body.length)[:, None]
    return pos + matvec3(world, np.broadcast_to(local, pos.shape))
