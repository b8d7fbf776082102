"""Retargeting steps 1-2 (docs/motion_import.md): the source motion resampled, scaled and moved, its planted
foot frames, and its height rebased so the humanoid's planted feet touch the ground (metres, y-up)."""

from __future__ import annotations

import numpy as np

from charctl.errors import CharctlError
from charctl.motion import rotations as R
from charctl.motion.bvh_any import SourceMotion
from charctl.motion.retarget.common import CONTACT_HEIGHT, CONTACT_MIN_S, CONTACT_SPEED, SIDES, RetargetHumanoid


# ---------------------------------------------------------------------------- source preparation
def resample_source(src: SourceMotion, fps: float) -> SourceMotion:
    """Resample positions (linear) and world rotations (slerp) to `fps`; duration and ends kept."""
    T = src.num_frames
    duration = (T - 1) / src.fps
    n = max(2, int(round(duration * fps)) + 1)
    x = np.linspace(0.0, T - 1, n)
    i0 = np.clip(np.floor(x).astype(int), 0, T - 2)
    w = (x - i0)[:, None, None]
    pos = (1 - w) * src.pos[i0] + w * src.pos[i0 + 1]
    J = src.rot.shape[1]
    rot = R.slerp(src.rot[i0], src.rot[i0 + 1], np.broadcast_to(w[:, :, 0], (n, J)))
    ends = {j: (1 - w[:, :, 0]) * p[i0] + w[:, :, 0] * p[i0 + 1] for j, p in src.end_pos.items()}
    new_fps = (n - 1) / duration if duration > 0 else fps
    return _replace(src, pos=pos, rot=rot, end_pos=ends, fps=new_fps)


def _replace(src: SourceMotion, **changes) -> SourceMotion:
    import dataclasses

    return dataclasses.replace(src, **changes)


def scale_source(src: SourceMotion, scale: float) -> SourceMotion:
    """Positions scaled by the leg-length ratio (about the world origin)."""
    return _replace(src, pos=src.pos * scale, end_pos={k: p * scale for k, p in src.end_pos.items()})


def turn_and_move(src: SourceMotion, turn: np.ndarray, shift: np.ndarray) -> SourceMotion:
    def move(p: np.ndarray) -> np.ndarray:
        return R.rotate(np.broadcast_to(turn, p.shape[:-1] + (4,)), p - shift)

    rot = R.multiply(np.broadcast_to(turn, src.rot.shape), src.rot)
    return _replace(src, pos=move(src.pos), rot=rot, end_pos={k: move(p) for k, p in src.end_pos.items()})


def toe_points(src: SourceMotion, side: str) -> np.ndarray:
    """(T, 3) toe point of a foot: the toe joint, else the foot joint's End Site or child."""
    p = src.point(f"{side}toe_points")
    if p is None:
        p = src.end_or_child(src.jmap.joints[f"{side}_ankle"])
    if p is None:
        raise CharctlError(f"{src.path}: the {side} foot has no toe joint nor End Site (map {side}toe_points)")
    return p


def clean_mask(mask: np.ndarray, n: int) -> np.ndarray:
    """Fill gaps shorter than n frames, then drop runs shorter than n frames."""
    out = mask.copy()
    for value in (False, True):  # gaps first (runs of False), then short contacts (runs of True)
        runs = true_runs(out == value)
        for a, b in runs:
            if b - a < n and a > 0 and b < len(out):
                out[a:b] = not value
    return out


def true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of every run of True."""
    d = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def foot_contacts(src: SourceMotion) -> np.ndarray:
    """(T, 2) right/left foot contact: ankle within CONTACT_HEIGHT of the clip's ankle level and slow."""
    j = src.jmap.joints
    ankles = np.stack([src.pos[:, j[f"{s}_ankle"]] for s in SIDES], axis=1)  # (T, 2, 3)
    level = np.percentile(ankles[:, :, 1], 5)
    speed = np.linalg.norm(np.gradient(ankles, 1.0 / src.fps, axis=0), axis=-1)
    raw = (ankles[:, :, 1] - level < CONTACT_HEIGHT) & (speed < CONTACT_SPEED)
    n = max(1, int(round(CONTACT_MIN_S * src.fps)))
    return np.stack([clean_mask(raw[:, k], n) for k in range(2)], axis=1)


def _clearance(foot_rot: np.ndarray, hum: RetargetHumanoid) -> np.ndarray:
    """(T,) ankle height at which the lowest corner of the foot box, turned by `foot_rot`, touches the ground."""
    T = foot_rot.shape[0]
    corners = R.rotate(foot_rot[:, None, :], np.broadcast_to(hum.foot_corners, (T, 8, 3)))
    return -corners[..., 1].min(axis=1)


def rebase_height(src: SourceMotion, contacts: np.ndarray, H: dict, hum: RetargetHumanoid) -> SourceMotion:
    """Shift vertically so the humanoid's feet, placed at the source ankles with the transferred foot
    orientations, touch the ground during contact (median over the contact frames): root height from the
    feet. A clip without contact frames is put on the ground at its lowest foot frame."""
    j = src.jmap.joints
    gaps = []
    for k, s in enumerate(SIDES):
        gap = src.pos[:, j[f"{s}_ankle"], 1] - _clearance(H[f"{s}_ankle"], hum)
        gaps.append(gap[contacts[:, k]] if contacts[:, k].any() else gap)
    g = np.concatenate(gaps)
    h = np.median(g) if contacts.any() else np.min(g)
    dy = np.array([0.0, -h, 0.0])
    return _replace(src, pos=src.pos + dy, end_pos={k: p + dy for k, p in src.end_pos.items()})
