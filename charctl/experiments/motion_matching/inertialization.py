"""Inertialization (Bollo, GDC 2018; Holden's critically damped spring form).

At a transition the output pose x_out and its velocity v_out are kept, and the offset to the
new database pose, o = x_out - x_db(b), o' = v_out - v_db(b), decays as a critically damped
spring with half-life `halflife`:

    y = 2 ln 2 / halflife,  j = o' + y o,
    o(t)  = e^{-y t} (o + j t),      o'(t) = e^{-y t} (o' - j y t)

so the output x(t) = x_db(t) + o(t) is continuous in value and velocity at t = 0 and tends to
the database motion. Rotations use rotation-vector offsets: q_out = exp(o) * q_db.
"""

from __future__ import annotations

import numpy as np

from charctl.motion import rotations as R

LN2 = float(np.log(2.0))


def decay_offsets(x0: np.ndarray, v0: np.ndarray, halflife: float, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Offsets (len(times), *x0.shape) and their velocities after `times` seconds."""
    y = 2.0 * LN2 / halflife
    t = np.asarray(times, dtype=float).reshape((-1,) + (1,) * np.ndim(x0))
    j = v0 + x0 * y
    e = np.exp(-y * t)
    return e * (x0 + j * t), e * (v0 - j * y * t)


def rotation_offset(q_src: np.ndarray, q_dst: np.ndarray) -> np.ndarray:
    """Rotation vectors o with exp(o) * q_dst = q_src (shortest arc), (..., 3)."""
    return R.log_map(R.multiply(q_src, R.conjugate(q_dst)))


def apply_rotation_offset(offset: np.ndarray, q: np.ndarray) -> np.ndarray:
    """exp(offset) * q."""
    return R.multiply(R.exp_map(offset), q)


def inertialize_segment(
    x_src: np.ndarray,
    v_src: np.ndarray,
    x_dst: np.ndarray,
    v_dst0: np.ndarray,
    halflife: float,
    dt: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Blend a jump in a vector signal: output frames after a transition.

    x_src, v_src: output value/velocity at the transition frame (shape S).
    x_dst: (n + 1, *S) the new motion from the transition frame on; v_dst0 its velocity there.
    Returns (out (n + 1, *S), offset at the last frame, offset velocity at the last frame);
    out[0] == x_src (no jump) and out[k] -> x_dst[k] as k grows.
    """
    n = x_dst.shape[0] - 1
    o, ov = decay_offsets(x_src - x_dst[0], v_src - v_dst0, halflife, np.arange(n + 1) * dt)
    return x_dst + o, o[-1], ov[-1]
