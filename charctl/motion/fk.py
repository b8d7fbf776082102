"""Forward kinematics and centre of mass of the humanoid, vectorised over any leading shape.

All outputs are in the world frame (y-up), metres. The loop runs over the tree's depth levels
(5 for the humanoid), never over frames or environments.
"""

from __future__ import annotations

import numpy as np

from charctl.motion import rotations as R
from charctl.motion.skeleton import Skeleton


def forward_kinematics(skel: Skeleton, root_pos: np.ndarray, local_rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body frame positions and rotations.

    Args:
        root_pos: (..., 3) world position of the root body frame.
        local_rot: (..., B, 4) xyzw rotation of each body relative to its parent
            (index 0: the root's world rotation).
    Returns:
        pos (..., B, 3) and rot (..., B, 4), world frame.
    """
    shape = local_rot.shape[:-2]
    pos = np.empty(shape + (skel.num_bodies, 3))
    rot = np.empty(shape + (skel.num_bodies, 4))
    pos[..., 0, :] = root_pos
    rot[..., 0, :] = local_rot[..., 0, :]
    for level in skel.depth_levels[1:]:
        par = skel.parents[level]
        prot = rot[..., par, :]
        pos[..., level, :] = pos[..., par, :] + R.rotate(
            prot, np.broadcast_to(skel.offsets[level], prot.shape[:-1] + (3,))
        )
        rot[..., level, :] = R.multiply(prot, local_rot[..., level, :])
    return pos, rot


def center_of_mass(
    skel: Skeleton,
    pos: np.ndarray,
    rot: np.ndarray,
    masses: np.ndarray | None = None,
    com_local: np.ndarray | None = None,
) -> np.ndarray:
    """Whole-body centre of mass (..., 3), world frame.

    `masses` (B,) replaces the model masses (a user mass table, e.g. com-cnn's);
    `com_local` (B, 3) replaces the bodies' local COM offsets.
    """
    m = skel.masses if masses is None else np.asarray(masses, dtype=float)
    local = skel.com_local if com_local is None else com_local
    body_com = pos + R.rotate(rot, np.broadcast_to(local, rot.shape[:-1] + (3,)))
    return np.einsum("...bi,b->...i", body_com, m) / m.sum()
