"""DeepMimic motion files (JSON: {"Loop": "wrap"|"none", "Frames": [[44 numbers], ...]}).

Frame layout (44 numbers): dt, root position (3), root quaternion w-x-y-z (4), then for each
of chest, neck, right hip, right knee*, right ankle, right shoulder, right elbow*, left hip,
left knee*, left ankle, left shoulder, left elbow* a quaternion w-x-y-z (4) or, for the
starred hinge joints, one angle in radians about the joint's z axis. y-up, +x forward,
right side +z. Non-unit quaternions are normalised; a final frame with dt = 0 is accepted;
non-uniform frame times are resampled to the clip's median rate.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.motion import rotations as R
from charctl.motion.clip import Clip
from charctl.motion.skeleton import CLIP_JOINTS, HINGE_JOINTS, load_skeleton

FRAME_SIZE = 44
_Z = np.array([0.0, 0.0, 1.0])


def _layout() -> list[tuple[str, int, int]]:
    """(joint, start column, width) for the 12 joints of a frame."""
    out, col = [], 8
    for j in CLIP_JOINTS:
        width = 1 if j in HINGE_JOINTS else 4
        out.append((j, col, width))
        col += width
    assert col == FRAME_SIZE
    return out


LAYOUT = _layout()


def decode_frames(frames: np.ndarray, name: str, loop: bool = False, label: str = "", source: str = "") -> Clip:
    """Build a `Clip` from a (T, 44) array of DeepMimic frames."""
    skel = load_skeleton()
    frames = np.asarray(frames, dtype=float)
    T = frames.shape[0]
    local = np.tile(R.IDENTITY, (T, skel.num_bodies, 1))
    local[:, 0] = R.normalize(R.wxyz_to_xyzw(frames[:, 4:8]))
    for joint, col, width in LAYOUT:
        b = skel.index(joint)
        if width == 1:
            local[:, b] = R.from_axis_angle(_Z, frames[:, col])
        else:
            local[:, b] = R.normalize(R.wxyz_to_xyzw(frames[:, col : col + 4]))
    dts = frames[:, 0]
    steps = dts[:-1] if T > 1 else dts
    steps = steps[steps > 0]
    if steps.size == 0:
        raise CharctlError(f"{source or name}: all frame durations are zero")
    dt = float(np.median(steps))
    clip = Clip(
        name=name,
        fps=1.0 / dt,
        root_pos=frames[:, 1:4].copy(),
        local_rot=local,
        loop=loop,
        label=label,
        source=source,
        skeleton=skel,
    )
    if np.any(np.abs(steps - dt) > 0.01 * dt):  # non-uniform: resample onto a uniform grid
        clip = _resample_nonuniform(clip, np.concatenate([[0.0], np.cumsum(dts[:-1])]), dt)
    return clip


def _resample_nonuniform(clip: Clip, times: np.ndarray, dt: float) -> Clip:
    n_new = int(round(times[-1] / dt)) + 1
    t_new = np.linspace(0.0, times[-1], n_new)
    idx = np.clip(np.searchsorted(times, t_new, side="right") - 1, 0, len(times) - 2)
    w = (t_new - times[idx]) / np.maximum(times[idx + 1] - times[idx], 1e-9)
    pos = (1 - w)[:, None] * clip.root_pos[idx] + w[:, None] * clip.root_pos[idx + 1]
    B = clip.local_rot.shape[1]
    rot = R.slerp(clip.local_rot[idx], clip.local_rot[idx + 1], np.broadcast_to(w[:, None], (n_new, B)))
    return clip.replace(root_pos=pos, local_rot=rot, fps=(n_new - 1) / times[-1])


def encode_frames(clip: Clip) -> np.ndarray:
    """(T, 44) DeepMimic frames of a clip (quaternions w-x-y-z with w >= 0)."""
    T = clip.num_frames
    out = np.zeros((T, FRAME_SIZE))
    out[:, 0] = clip.dt
    out[-1, 0] = 0.0 if not clip.loop else clip.dt
    out[:, 1:4] = clip.root_pos
    skel = clip.skeleton

    def wxyz(q: np.ndarray) -> np.ndarray:
        q = np.where(q[..., 3:4] < 0, -q, q)
        return R.xyzw_to_wxyz(q)

    out[:, 4:8] = wxyz(clip.local_rot[:, 0])
    for joint, col, width in LAYOUT:
        q = clip.local_rot[:, skel.index(joint)]
        if width == 1:
            out[:, col] = R.twist_angle(q, 2)  # the hinge angle about +z
            out[:, col] = (out[:, col] + np.pi) % (2 * np.pi) - np.pi
        else:
            out[:, col : col + 4] = wxyz(q)
    return out


def read_deepmimic(path: str | Path, name: str | None = None, label: str = "") -> Clip:
    """Load a DeepMimic motion file. Any problem is a one-line `CharctlError` naming the file."""
    path = Path(path)
    if not path.is_file():
        raise CharctlError(f"motion file not found: {path}")
    try:
        data = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CharctlError(f"{path}: not a DeepMimic motion file (invalid JSON: {exc})") from exc
    if not isinstance(data, dict) or "Frames" not in data:
        raise CharctlError(f"{path}: not a DeepMimic motion file (no 'Frames' list)")
    loop = str(data.get("Loop", "none")).lower()
    if loop not in ("wrap", "none"):
        raise CharctlError(f"{path}: 'Loop' must be 'wrap' or 'none', got {loop!r}")
    try:
        frames = np.asarray(data["Frames"], dtype=float)
    except (TypeError, ValueError) as exc:
        raise CharctlError(f"{path}: 'Frames' must be a list of equal-length number lists") from exc
    if frames.ndim != 2 or frames.shape[1] != FRAME_SIZE:
        got = frames.shape[1] if frames.ndim == 2 else "ragged"
        raise CharctlError(f"{path}: each frame must have {FRAME_SIZE} numbers (humanoid3d), got {got}")
    if frames.shape[0] < 2:
        raise CharctlError(f"{path}: a clip needs at least 2 frames, got {frames.shape[0]}")
    if not np.all(np.isfinite(frames)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(frames), axis=1))[0])
        raise CharctlError(f"{path}: frame {bad} contains NaN or infinite values")
    if np.any(frames[:, 0] < 0):
        raise CharctlError(f"{path}: negative frame duration in frame {int(np.argmax(frames[:, 0] < 0))}")
    zero = _zero_quaternion(frames)
    if zero is not None:
        frame, col, joint = zero
        raise CharctlError(
            f"{path}: frame {frame}, columns {col}-{col + 3} ({joint} quaternion w-x-y-z) are all zero; "
            "a rotation quaternion must have a non-zero length"
        )
    return decode_frames(frames, name or path.stem, loop=loop == "wrap", label=label, source=str(path))


def _zero_quaternion(frames: np.ndarray) -> tuple[int, int, str] | None:
    """(frame, first column, joint) of the first quaternion of length ~0 (it has no rotation), or None."""
    for joint, col, width in [("root", 4, 4), *LAYOUT]:
        if width != 4:
            continue
        norm = np.linalg.norm(frames[:, col : col + 4], axis=1)
        bad = np.flatnonzero(norm < 1e-8)
        if bad.size:
            return int(bad[0]), col, joint
    return None


def write_deepmimic(clip: Clip, path: str | Path) -> None:
    """Write a clip as a DeepMimic motion file."""
    frames = encode_frames(clip)
    body = {"Loop": "wrap" if clip.loop else "none", "Frames": frames.round(9).tolist()}
    Path(path).write_text(json.dumps(body, indent=1))
