"""Pose distances between sequences of joint rotations (e_pose of docs/cgail.md, the paper's eq. 6.1)."""

from __future__ import annotations

import numpy as np


def pose_error_matrix(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    """(n, m) matrix of e_pose between frames of two sequences of local joint rotations.

    q_a (n, J, 4), q_b (m, J, 4), xyzw. Per joint the distance is the rotation angle of
    q_a^-1 q_b (radians, invariant to the sign of either quaternion); e_pose is the l2 norm of
    these angles over the J joints.
    """
    dots = np.abs(np.einsum("njc,mjc->nmj", q_a, q_b))
    angles = 2.0 * np.arccos(np.clip(dots, 0.0, 1.0))
    return np.sqrt(np.sum(angles**2, axis=-1))


def pose_error(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    """Frame-by-frame e_pose (n,) between two equally long sequences (n, J, 4)."""
    dots = np.abs(np.sum(q_a * q_b, axis=-1))
    return np.sqrt(np.sum((2.0 * np.arccos(np.clip(dots, 0.0, 1.0))) ** 2, axis=-1))
