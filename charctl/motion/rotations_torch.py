"""Torch twins of the quaternion helpers in `charctl.motion.rotations` (for the on-device GPU path).

Same conventions: quaternions are scalar-last x-y-z-w, shape (..., 4), unit norm; rotations are
active and right-handed, angles in radians, world y-up. Every function broadcasts over leading
dimensions and runs on whatever device and dtype its inputs have (no host round trip).
`tests/test_gpu_path.py` holds each one equal to its numpy twin (`cross`: `tests/test_rotations.py`).
"""

from __future__ import annotations

import torch


def multiply(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product a*b of (..., 4) xyzw quaternions (apply b first, then a)."""
    ax, ay, az, aw = a.unbind(-1)
    bx, by, bz, bw = b.unbind(-1)
    return torch.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        dim=-1,
    )


def conjugate(q: torch.Tensor) -> torch.Tensor:
    """Inverse of unit quaternions (..., 4)."""
    return torch.cat([-q[..., :3], q[..., 3:]], dim=-1)


def cross(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Cross product a x b of (..., 3) vectors along the last axis (broadcasting), as `rotations.cross`.

    Written out by components (unbind, then stack of products and differences), not `torch.cross`:
    the cgail web graph (`cgail/web_graph.py`) calls it and is exported to ONNX, and these plain
    element-wise ops export to the same graph under every exporter and opset, with no dependence on
    a cross-product symbolic (the TorchScript exporter's `aten::cross` is two Rolls per operand).
    """
    ax, ay, az = a.unbind(-1)
    bx, by, bz = b.unbind(-1)
    return torch.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], dim=-1)


def rotate(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate (..., 3) vectors by (..., 4) unit quaternions."""
    u, v = torch.broadcast_tensors(q[..., :3], v)
    w = q[..., 3:4]
    t = 2.0 * torch.cross(u, v, dim=-1)
    return v + w * t + torch.cross(u, t, dim=-1)


def to_matrix(q: torch.Tensor) -> torch.Tensor:
    """(..., 4) unit quaternions -> (..., 3, 3) rotation matrices."""
    x, y, z, w = q.unbind(-1)
    # fmt: off
    rows = [
        1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
        2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
        2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
    ]
    # fmt: on
    return torch.stack(rows, dim=-1).reshape(q.shape[:-1] + (3, 3))


def heading_quat(theta: torch.Tensor) -> torch.Tensor:
    """(...) angles (radians about world +y) -> (..., 4) quaternions."""
    half = 0.5 * theta
    zero = torch.zeros_like(half)
    return torch.stack([zero, torch.sin(half), zero, torch.cos(half)], dim=-1)


def yaw_about_y(q: torch.Tensor) -> torch.Tensor:
    """Heading angle (radians) about world +y of the body's forward (+x) axis: atan2(-f_z, f_x)."""
    x, y, z, w = q.unbind(-1)
    fx = 1 - 2 * (y * y + z * z)  # first column of the rotation matrix = R @ (1, 0, 0)
    fz = 2 * (x * z - y * w)
    return torch.atan2(-fz, fx)


def wxyz_to_xyzw(q: torch.Tensor) -> torch.Tensor:
    """Reorder (..., 4) quaternions from w-x-y-z (MuJoCo) to x-y-z-w."""
    return torch.cat([q[..., 1:4], q[..., :1]], dim=-1)


def xyzw_to_wxyz(q: torch.Tensor) -> torch.Tensor:
    """Reorder (..., 4) quaternions from x-y-z-w to w-x-y-z (MuJoCo)."""
    return torch.cat([q[..., 3:4], q[..., :3]], dim=-1)
