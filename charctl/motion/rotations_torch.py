"""Torch twins of the quaternion helpers in `charctl.motion.rotations` (for the on-device GPU path).

Same conventions: quaternions are scalar-last x-y-z-w, shape (..., 4), unit norm; rotations are
active and right-handed, angles in radians, world y-up. Every function broadcasts over leading
dimensions and runs on whatever device and dtype its inputs have (no host round trip).
`tests/test_gpu_path.py` holds each one equal to its numpy twin (`cross`: `tests/test_rotations.py`).
"""

from __future__ import annotations

import functools

import torch

# elements of an input up to which `multiply` and `to_matrix` gather their terms (fewer ops: per-op overhead dominates
# there); larger inputs take one element-wise op per term, faster at that size (256 x 15 quaternions on one CPU
# thread: to_matrix 0.26 against 0.49 ms, multiply 0.13 against 0.36 ms)
_GATHER_MAX = 4096

# `multiply` of few quaternions: component c of a*b is ((t0 + S1 t1) + S2 t2) + S3 t3, the terms t_k gathered from
# the 16 products a_i b_j (flattened, index 4 i + j; x, y, z, w = 0, 1, 2, 3), row k of _MULTIPLY_TERMS over c
_MULTIPLY_TERMS = (12, 13, 14, 15, 3, 2, 1, 0, 6, 7, 4, 5, 9, 8, 11, 10)  # aw b. | a. bw | ay bz ... | az by ...
_MULTIPLY_SIGNS = ((1.0, -1.0, 1.0, -1.0), (1.0, 1.0, -1.0, -1.0), (-1.0, 1.0, 1.0, -1.0))


@functools.lru_cache(maxsize=16)
def _multiply_tables(device: torch.device, dtype: torch.dtype) -> tuple[torch.Tensor, torch.Tensor]:
    return torch.tensor(_MULTIPLY_TERMS, device=device), torch.tensor(_MULTIPLY_SIGNS, dtype=dtype, device=device)


def multiply(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product a*b of (..., 4) xyzw quaternions (apply b first, then a).

    As `to_matrix`, few quaternions (at most `_GATHER_MAX` elements each, e.g. a reset's rows) take a gathered
    form (~5 ops instead of ~30) with the same operations on each component, so bit-identical results."""
    if a.shape == b.shape and a.numel() <= _GATHER_MAX:
        idx, sign = _multiply_tables(a.device, a.dtype)
        terms = (a[..., :, None] * b[..., None, :]).flatten(-2).index_select(-1, idx).unflatten(-1, (4, 4))
        out = terms[..., 0, :]
        for k in range(3):  # s t with s = +-1 is exact: a difference rounds as in the written-out sum
            out = torch.addcmul(out, terms[..., k + 1, :], sign[k])
        return out
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


# `to_matrix` of few quaternions: entry e (row-major) of the matrix is 2 (P[A[e]] + S[e] P[B[e]]), subtracted from 1
# on the diagonal, with P the 16 products q_i q_j of the components (x, y, z, w) = (0, 1, 2, 3), flattened.
_MATRIX_A = (5, 1, 2, 1, 0, 6, 2, 6, 0)  # yy xy xz / xy xx yz / xz yz xx
_MATRIX_B = (10, 11, 7, 11, 10, 3, 7, 3, 5)  # zz zw yw / zw zz xw / yw xw yy
_MATRIX_S = (1.0, -1.0, 1.0, 1.0, 1.0, -1.0, -1.0, 1.0, 1.0)
_MATRIX_DIAG = (True, False, False, False, True, False, False, False, True)


@functools.lru_cache(maxsize=16)
def _matrix_tables(device: torch.device, dtype: torch.dtype) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    return (
        torch.tensor(_MATRIX_A + _MATRIX_B, device=device),
        torch.tensor(_MATRIX_S, dtype=dtype, device=device),
        torch.tensor(_MATRIX_DIAG, device=device),
    )


def to_matrix(q: torch.Tensor) -> torch.Tensor:
    """(..., 4) unit quaternions -> (..., 3, 3) rotation matrices.

    Two forms with the same operations on each entry, so bit-identical results: for few quaternions (at
    most `_GATHER_MAX` elements, a control step's heading frames and resets) the 16 products q_i q_j
    in one op and the nine entries from one gather (~9 ops, per-op overhead dominates there); for many, one
    element-wise op per term (~40 ops, faster than the gather at that size)."""
    if q.numel() <= _GATHER_MAX:
        idx, sign, diag = _matrix_tables(q.device, q.dtype)
        products = (q[..., :, None] * q[..., None, :]).flatten(-2)
        pairs = products.index_select(-1, idx).unflatten(-1, (2, 9))
        t = 2 * torch.addcmul(pairs[..., 0, :], pairs[..., 1, :], sign)  # 2 (a + s b), s = +-1: exact as a +- b
        return torch.where(diag, 1 - t, t).unflatten(-1, (3, 3))
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
