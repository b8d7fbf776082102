"""com-cnn's body model (paper §3.2): the skeleton's joints, hinge limits and the paper's mass table mapped
onto the bodies, for the humanoid or a user BVH skeleton (metres, kilograms)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from charctl.errors import CharctlError
from charctl.motion.fk import center_of_mass, forward_kinematics
from charctl.motion.skeleton import CLIP_JOINTS, HINGE_JOINTS, Skeleton, load_skeleton


# ---------------------------------------------------------------------------- body model
@dataclass(frozen=True, eq=False)
class BodyModel:
    """The skeleton behind the pose vector: names, COM masses, joint constraints, forward axis."""

    kind: str  # "humanoid" (DeepMimic) or "bvh"
    skeleton: Skeleton  # body 0 = root; FK and COM go through charctl.motion.fk
    masses: np.ndarray  # (B,) paper mass table mapped onto the bodies (0 for unmapped ones)
    forward: np.ndarray  # (3,) root-local forward axis (humanoid +x, BVH data.bvh_forward)
    hinge: np.ndarray  # (J,) bool: joint turns about its local z only (humanoid knees/elbows)
    fixed: np.ndarray  # (J,) bool: joint never moves (humanoid wrists)
    bvh_header: str = ""  # kind == "bvh": the HIERARCHY text of the first file (for writing)
    bvh_channels: tuple = ()  # kind == "bvh": channel names per joint
    bvh_scale: float = 1.0

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(self.skeleton.names[1:])

    @property
    def num_joints(self) -> int:
        return self.skeleton.num_bodies - 1

    @property
    def pose_dim(self) -> int:
        return 6 + 3 * self.num_joints

    @property
    def error_joints(self) -> np.ndarray:
        """Joint indices (into the J joints) the joint-angle error averages over: the movable ones."""
        return np.flatnonzero(~self.fixed)

    def com(self, root_pos: np.ndarray, root_rot: np.ndarray, joint_rot: np.ndarray) -> np.ndarray:
        """Whole-body COM (..., 3), world frame, metres, from the mass table."""
        local = np.concatenate([root_rot[..., None, :], joint_rot], axis=-2)
        pos, rot = forward_kinematics(self.skeleton, root_pos, local)
        return center_of_mass(self.skeleton, pos, rot, masses=self.masses)


def humanoid_body(com_cfg) -> BodyModel:
    """The DeepMimic humanoid with the paper's Table 1 masses mapped through `com.humanoid_bodies`."""
    skel = load_skeleton()
    masses = map_masses(com_cfg.mass_table, com_cfg.humanoid_bodies, skel.names, "com.humanoid_bodies")
    joints = skel.names[1:]
    return BodyModel(
        kind="humanoid",
        skeleton=skel,
        masses=masses,
        forward=np.array([1.0, 0.0, 0.0]),
        hinge=np.array([n in HINGE_JOINTS for n in joints]),
        fixed=np.array([n not in CLIP_JOINTS for n in joints]),
    )


def map_masses(table: dict, part_to_body: dict, names, key: str) -> np.ndarray:
    """(B,) masses in `names` order: body `part_to_body[part]` (default: the part name) gets table[part]."""
    masses = np.zeros(len(names))
    hits = 0
    for part, m in table.items():
        body = part_to_body.get(part, part)
        if body in names:
            masses[list(names).index(body)] += float(m)
            hits += 1
    if hits == 0 or masses.sum() <= 0:
        raise CharctlError(
            f"no body of the skeleton matches the mass table (parts {', '.join(list(table)[:4])}, "
            f"...; bodies {', '.join(list(names)[:4])}, ...); map them with {key}"
        )
    return masses
