"""Vectorised quaternion helpers.

Convention used everywhere inside charctl: quaternions are stored **scalar-last, x-y-z-w**
(scipy's convention), shape (..., 4), unit norm. File formats that store w-x-y-z
(DeepMimic text files, MuJoCo qpos) are converted at the I/O edge with `wxyz_to_xyzw`
and `xyzw_to_wxyz`. Rotations are active, right-handed, angles in radians.

These are small elementwise formulas written with numpy broadcasting so they run over
(frames, joints) or (envs, bodies) at once; anything heavier (Euler decomposition, exp/log
maps of many rotations) goes through `scipy.spatial.transform.Rotation`.
"""

from __future__ import annotations

import numpy as np

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])
X_AXIS = np.array([1.0, 0.0, 0.0])  # DeepMimic's forward axis (read-only default)
X_AXIS.flags.writeable = False


def wxyz_to_xyzw(q: np.ndarray) -> np.ndarray:
    """Reorder (..., 4) quaternions from w-x-y-z to x-y-z-w."""
    return np.concatenate([q[..., 1:4], q[..., :1]], axis=-1)


def xyzw_to_wxyz(q: np.ndarray) -> np.ndarray:
    """Reorder (..., 4) quaternions from x-y-z-w to w-x-y-z."""
    return np.concatenate([q[..., 3:4], q[..., :3]], axis=-1)


def normalize(q: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    """Unit-normalise (..., 4) quaternions (zero quaternions become identity)."""
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    out = q / np.maximum(n, eps)
    bad = n[..., 0] < eps
    if np.any(bad):
        out[bad] = IDENTITY
    return out


def multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a*b of (..., 4) xyzw quaternions (apply b first, then a)."""
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def conjugate(q: np.ndarray) -> np.ndarray:
    """Inverse of unit quaternions."""
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of (..., 3) vectors along the last axis (broadcasting).

    Same values as `np.cross`, written by components: np.cross moves axes and checks shapes on
    every call, which dominates for the small (envs, bodies, 3) batches of the control loop.
    """
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], axis=-1)


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate (..., 3) vectors by (..., 4) unit quaternions (the leading axes broadcast)."""
    shape = np.broadcast_shapes(q.shape[:-1], v.shape[:-1]) + (3,)
    u = np.broadcast_to(q[..., :3], shape)
    t = 2.0 * cross(u, np.broadcast_to(v, shape))
    return v + q[..., 3:4] * t + cross(u, t)


def to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions -> (..., 3, 3) rotation matrices (explicit components: cheaper than
    moveaxis on small batches, so the srb hot path uses this one too)."""
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            1 - 2 * (y * y + z * z),
            2 * (x * y - z * w),
            2 * (x * z + y * w),
            2 * (x * y + z * w),
            1 - 2 * (x * x + z * z),
            2 * (y * z - x * w),
            2 * (x * z - y * w),
            2 * (y * z + x * w),
            1 - 2 * (x * x + y * y),
        ],
        axis=-1,
    ).reshape(q.shape[:-1] + (3, 3))


def from_axis_angle(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Quaternions for rotations by `angle` (radians, (...)) about unit `axis` ((3,) or (..., 3))."""
    angle = np.asarray(angle, dtype=float)
    half = 0.5 * angle[..., None]
    axis = np.broadcast_to(axis, angle.shape + (3,))
    return np.concatenate([axis * np.sin(half), np.cos(half)], axis=-1)


def log_map(q: np.ndarray) -> np.ndarray:
    """Rotation vectors (axis * angle, radians, (..., 3)) of unit quaternions, shortest arc."""
    q = np.where(q[..., 3:4] < 0, -q, q)
    v = q[..., :3]
    s = np.sqrt(np.sum(v * v, axis=-1, keepdims=True))  # not np.linalg.norm: cheaper on small batches
    angle = 2.0 * np.arctan2(s, q[..., 3:4])
    scale = np.where(s > 1e-9, angle / np.maximum(s, 1e-12), 2.0)
    return v * scale


def exp_map(r: np.ndarray) -> np.ndarray:
    """Unit quaternions of rotation vectors (..., 3)."""
    angle = np.sqrt(np.sum(r * r, axis=-1, keepdims=True))
    half = 0.5 * angle
    scale = np.where(angle > 1e-9, np.sin(half) / np.maximum(angle, 1e-12), 0.5)
    return np.concatenate([r * scale, np.cos(half)], axis=-1)


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation angle (radians, in [0, pi]) of a^-1 b; invariant to the sign of either quaternion."""
    d = np.abs(np.sum(a * b, axis=-1))
    return 2.0 * np.arccos(np.clip(d, 0.0, 1.0))


def slerp(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Spherical interpolation between (..., 4) quaternions a and b at fractions t (...)."""
    t = np.asarray(t, dtype=float)[..., None]
    dot = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(dot < 0, -b, b)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_theta = np.sin(theta)
    small = sin_theta < 1e-6
    wa = np.where(small, 1.0 - t, np.sin((1.0 - t) * theta) / np.where(small, 1.0, sin_theta))
    wb = np.where(small, t, np.sin(t * theta) / np.where(small, 1.0, sin_theta))
    return normalize(wa * a + wb * b)


def yaw_about_y(q: np.ndarray, forward: np.ndarray = X_AXIS) -> np.ndarray:
    """Heading angle (radians) about the world +y axis of the body's `forward` axis.

    A rotation Ry(theta) maps +x to (cos theta, 0, -sin theta), so theta = atan2(-f_z, f_x).
    """
    if forward is X_AXIS:  # the default, by components (the srb control loop calls this every step)
        x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
        return np.arctan2(-2.0 * (x * z - y * w), 1.0 - 2.0 * (y * y + z * z))
    f = rotate(q, np.broadcast_to(forward, q.shape[:-1] + (3,)))
    return np.arctan2(-f[..., 2], f[..., 0])


def twist_angle(q: np.ndarray, axis: int) -> np.ndarray:
    """Twist angle (radians) of (..., 4) x-y-z-w quaternions about coordinate axis `axis` (0 = x, 1 = y,
    2 = z): 2 atan2(q[axis], q_w), in [-2 pi, 2 pi] and not wrapped (callers wrap as they need).

    The angle of the twist in the swing-twist decomposition q = twist * swing (or swing * twist: same
    twist), twist a rotation about the axis and swing one about an axis perpendicular to it. For a
    hinge joint, whose rotation is about that axis only, it is the hinge angle: a quaternion
    from_axis_angle(e_axis, a) gives back a for a in (-2 pi, 2 pi]. The axis is a component index, not a
    vector, so that this is exactly the formula: a dot product with a unit vector would turn a -0.0
    component into +0.0, and atan2 gives +pi there instead of -pi when q_w < 0.
    """
    return 2.0 * np.arctan2(q[..., axis], q[..., 3])


def heading_quat(theta: np.ndarray) -> np.ndarray:
    """Quaternion of a rotation by theta (radians) about world +y."""
    return from_axis_angle(np.array([0.0, 1.0, 0.0]), theta)


def rotate_yaw(theta: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate (N, ..., 3) vectors about +y by theta (N,) radians: x' = c x + s z, z' = -s x + c z
    (= rotate(heading_quat(theta), v), by components)."""
    shape = theta.shape + (1,) * (v.ndim - 1 - theta.ndim)
    c, s = np.cos(theta).reshape(shape), np.sin(theta).reshape(shape)
    out = np.empty(np.broadcast_shapes(v.shape, shape + (3,)))
    out[..., 0] = c * v[..., 0] + s * v[..., 2]
    out[..., 1] = v[..., 1]
    out[..., 2] = -s * v[..., 0] + c * v[..., 2]
    return out


def up_y(q: np.ndarray) -> np.ndarray:
    """World y component of the body's +y axis (the cosine of its tilt from upright)."""
    x, z = q[..., 0], q[..., 2]
    return 1.0 - 2.0 * (x * x + z * z)


def mirror_z(q: np.ndarray) -> np.ndarray:
    """Reflect rotations through the x-y plane (z -> -z): R' = M R M with M = diag(1, 1, -1)."""
    return q * np.array([-1.0, -1.0, 1.0, 1.0])


def continuous_sign(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip quaternion signs along `axis` (time) so consecutive samples have a positive dot."""
    q = np.array(q, copy=True)
    q = np.moveaxis(q, axis, 0)
    for t in range(1, q.shape[0]):  # sequential by nature: each sign depends on the previous
        flip = np.sum(q[t] * q[t - 1], axis=-1) < 0
        q[t][flip] *= -1
    return np.moveaxis(q, 0, axis)
