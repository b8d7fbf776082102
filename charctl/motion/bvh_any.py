"""A BVH file of any skeleton as world joint trajectories in charctl's frame (y-up, metres).

`read_source` parses the file (charctl.motion.bvh's reader: one-line errors for a malformed file),
checks its channels, resolves the joint map onto the humanoid (charctl.motion.skeleton_maps), runs
forward kinematics in any channel order (positions on any joint, rotation channels in the order the
file lists them, intrinsic, degrees), and turns the result into a y-up world in metres: the up axis is
the one pointing from the feet to the head (or `up=`), the unit the one that gives a human leg length
(or `units=`). Nothing here depends on the file's rest pose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from charctl.errors import CharctlError
from charctl.motion import rotations as R
from charctl.motion.bvh import BvhMotion, read_bvh
from charctl.motion.skeleton_maps import JointMap, resolve_map

# metres per file unit; "cmu": the CMU database's length unit (1/0.45 inch, mocap.cs.cmu.edu FAQ)
UNITS: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "cmu": 0.0254 / 0.45}
TYPICAL_LEG_M = 0.85  # hip -> knee -> ankle of an adult, for unit detection
_CHANNELS = {f"{a}{k}" for a in "xyz" for k in ("position", "rotation")}
_UP_AXES = {"y": (1, 1.0), "-y": (1, -1.0), "z": (2, 1.0), "-z": (2, -1.0), "x": (0, 1.0), "-x": (0, -1.0)}


@dataclass
class SourceMotion:
    """World joint trajectories of a mocap file in charctl's frame: y-up, metres."""

    path: str
    names: list[str]
    parents: np.ndarray  # (J,)
    pos: np.ndarray  # (T, J, 3) metres, y-up
    rot: np.ndarray  # (T, J, 4) xyzw world rotation of each joint frame
    fps: float
    jmap: JointMap
    up: str  # the file's up axis ("y", "z", "-z", ...)
    units: str  # unit name, or "x<metres per unit>" when given as a number
    unit_m: float  # metres per file unit
    up_detected: bool
    units_detected: bool
    end_pos: dict[int, np.ndarray]  # joint -> (T, 3) world position of its End Site (metres)
    frames_in_file: int
    dropped_frames: int = 0  # leading reference frames (a T-pose before the motion) left out
    file_fps: float = 0.0  # the file's own frame rate (`fps` changes when the motion is resampled)

    @property
    def num_frames(self) -> int:
        return self.pos.shape[0]

    def leg_length(self) -> float:
        """Median hip -> knee -> ankle length (metres) over both legs and all frames."""
        return _leg_length(self.pos, self.jmap)

    def arm_length(self) -> float:
        """Median shoulder -> elbow -> wrist length (metres) over both arms and all frames."""
        out = []
        for s in ("right", "left"):
            a, b, c = (self.jmap.joints[f"{s}_{k}"] for k in ("shoulder", "elbow", "wrist"))
            out.append(_segment(self.pos, a, b) + _segment(self.pos, b, c))
        return float(np.median(np.concatenate(out)))

    def point(self, key: str) -> np.ndarray | None:
        """(T, 3) of an optional map key: its joint, or None."""
        j = self.jmap.get(key)
        return None if j is None else self.pos[:, j]

    def end_or_child(self, joint: int) -> np.ndarray | None:
        """(T, 3) of the joint's End Site, else its first child joint, else None."""
        if joint in self.end_pos:
            return self.end_pos[joint]
        kids = np.flatnonzero(self.parents == joint)
        return self.pos[:, kids[0]] if kids.size else None


def read_source(
    path: str | Path,
    skeleton: str | None = None,
    up: str | None = None,
    units: str | None = None,
    start: float | None = None,
    stop: float | None = None,
) -> SourceMotion:
    """Parse, map and convert a BVH file; every problem is a one-line `CharctlError` naming the file."""
    path = Path(path).expanduser()
    motion = read_bvh(path)
    src = str(path)
    _check_channels(motion, src)
    if motion.num_frames < 2:
        raise CharctlError(f"{src}: a motion needs at least 2 frames, got {motion.num_frames}")
    jmap = resolve_map(motion.names, skeleton, src)
    up = up or jmap.settings.get("up")
    units = units or jmap.settings.get("units")
    frames = _trim(motion, start, stop, src)
    pos, rot = _forward_kinematics(motion, frames)
    ends = {
        j: pos[:, j] + R.rotate(rot[:, j], np.broadcast_to(np.asarray(off, float), pos[:, j].shape))
        for j, off in motion.end_sites.items()
    }

    up_detected = up is None
    up = _detect_up(pos, jmap, src) if up is None else _check_up(up)
    turn = _up_rotation(up)
    pos = np.einsum("ij,tkj->tki", turn.as_matrix(), pos)
    rot = R.multiply(np.broadcast_to(turn.as_quat(), rot.shape), rot)
    ends = {j: p @ turn.as_matrix().T for j, p in ends.items()}

    pos, rot, ends, dropped = _drop_reference_frames(pos, rot, ends, _leg_length(pos, jmap))

    leg = _leg_length(pos, jmap)
    if not leg > 0:
        raise CharctlError(f"{src}: the legs have zero length (hip, knee and ankle joints coincide)")
    units_detected = units is None
    name, unit_m = _detect_units(leg) if units is None else _parse_units(units)
    return SourceMotion(
        path=src,
        names=list(motion.names),
        parents=np.asarray(motion.parents),
        pos=pos * unit_m,
        rot=R.normalize(rot),
        fps=motion.fps,
        jmap=jmap,
        up=up,
        units=name,
        unit_m=unit_m,
        up_detected=up_detected,
        units_detected=units_detected,
        end_pos={j: p * unit_m for j, p in ends.items()},
        frames_in_file=motion.num_frames,
        dropped_frames=dropped,
        file_fps=motion.fps,
    )


# ---------------------------------------------------------------------------- checks and parsing
def _check_channels(motion: BvhMotion, src: str) -> None:
    for name, chans in zip(motion.names, motion.channels):
        for c in chans:
            if c.lower() not in _CHANNELS:
                raise CharctlError(
                    f"{src}: joint {name!r} has unknown channel {c!r} (known: Xposition Yposition Zposition "
                    "Xrotation Yrotation Zrotation)"
                )
        rot_axes = [c[0].upper() for c in chans if c.lower().endswith("rotation")]
        if len(rot_axes) != len(set(rot_axes)):
            raise CharctlError(f"{src}: joint {name!r} repeats a rotation channel ({' '.join(chans)})")


def _trim(motion: BvhMotion, start: float | None, stop: float | None, src: str) -> np.ndarray:
    t0 = 0 if start is None else int(round(start * motion.fps))
    t1 = motion.num_frames if stop is None else int(round(stop * motion.fps)) + 1
    for name, v in (("--start", start), ("--stop", stop)):
        if v is not None and not (math.isfinite(v) and v >= 0):
            raise CharctlError(f"{name} must be a finite number of seconds >= 0, got {v}")
    t1 = min(t1, motion.num_frames)
    if t1 - t0 < 2:
        raise CharctlError(
            f"{src}: --start/--stop leave {max(t1 - t0, 0)} frame(s) of {motion.num_frames} "
            f"({motion.num_frames / motion.fps:.2f} s at {motion.fps:g} fps); a motion needs at least 2 frames"
        )
    return motion.frames[t0:t1]


def _forward_kinematics(motion: BvhMotion, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World joint positions (file units) and rotations of `frames`, any channel order and case."""
    T, J = frames.shape[0], len(motion.names)
    trans = np.broadcast_to(np.asarray(motion.offsets, dtype=float), (T, J, 3)).copy()
    local = np.tile(R.IDENTITY, (T, J, 1))
    col = 0
    for j, chans in enumerate(motion.channels):
        order, cols = "", []
        for k, c in enumerate(chans):
            axis, kind = "XYZ".index(c[0].upper()), c[1:].lower()
            if kind == "position":
                trans[:, j, axis] = frames[:, col + k]
            else:
                order += c[0].upper()
                cols.append(col + k)
        if order:
            local[:, j] = Rotation.from_euler(order, frames[:, cols], degrees=True).as_quat()
        col += len(chans)
    pos = np.empty((T, J, 3))
    rot = np.empty((T, J, 4))
    for j in range(J):  # parents precede children in a BVH file
        p = motion.parents[j]
        if p < 0:
            pos[:, j], rot[:, j] = trans[:, j], local[:, j]
        else:
            pos[:, j] = pos[:, p] + R.rotate(rot[:, p], trans[:, j])
            rot[:, j] = R.multiply(rot[:, p], local[:, j])
    return pos, rot


def _drop_reference_frames(pos: np.ndarray, rot: np.ndarray, ends: dict, leg: float) -> tuple:
    """Leave out leading frames that jump to the rest of the motion (the T-pose frame 0 that many
    conversions, e.g. CMU's, put before the capture): a joint moving more than 5x the clip's typical
    largest per-frame step and more than 0.2 of the leg length between frames 0 and 1."""
    dropped = 0
    while pos.shape[0] - dropped > 3:
        step = np.linalg.norm(np.diff(pos[dropped : dropped + 12], axis=0), axis=-1).max(axis=1)  # (n-1,)
        rest = np.median(step[1:])
        if step[0] > 5 * rest and step[0] > 0.2 * leg:
            dropped += 1
        else:
            break
    if dropped:
        pos, rot = pos[dropped:], rot[dropped:]
        ends = {j: p[dropped:] for j, p in ends.items()}
    return pos, rot, ends, dropped


def _check_up(up: str) -> str:
    u = up.lower().lstrip("+")
    if u not in _UP_AXES:
        raise CharctlError(f"--up must be one of y, z, x, -y, -z, -x, got {up!r}")
    return u


def _detect_up(pos: np.ndarray, jmap: JointMap, src: str) -> str:
    feet = 0.5 * (pos[:, jmap.joints["right_ankle"]] + pos[:, jmap.joints["left_ankle"]])
    v = np.median(pos[:, jmap.joints["neck"]] - feet, axis=0)
    axis = int(np.argmax(np.abs(v)))
    if not np.abs(v[axis]) > 0:
        raise CharctlError(f"{src}: cannot tell the up axis (head and feet coincide); give --up y|z")
    return ("" if v[axis] > 0 else "-") + "xyz"[axis]


def _up_rotation(up: str) -> Rotation:
    """The rotation that takes the file's up axis onto +y (right-handed, no mirroring)."""
    quarter = np.pi / 2
    return {
        "y": Rotation.identity(),
        "-y": Rotation.from_rotvec([np.pi, 0.0, 0.0]),
        "z": Rotation.from_rotvec([-quarter, 0.0, 0.0]),  # (x, y, z) -> (x, z, -y)
        "-z": Rotation.from_rotvec([quarter, 0.0, 0.0]),
        "x": Rotation.from_rotvec([0.0, 0.0, quarter]),  # +x -> +y
        "-x": Rotation.from_rotvec([0.0, 0.0, -quarter]),
    }[up]


def _segment(pos: np.ndarray, a: int, b: int) -> np.ndarray:
    return np.linalg.norm(pos[:, b] - pos[:, a], axis=-1)


def _leg_length(pos: np.ndarray, jmap: JointMap) -> float:
    out = []
    for s in ("right", "left"):
        a, b, c = (jmap.joints[f"{s}_{k}"] for k in ("hip", "knee", "ankle"))
        out.append(_segment(pos, a, b) + _segment(pos, b, c))
    return float(np.median(np.concatenate(out)))


def _detect_units(leg_file_units: float) -> tuple[str, float]:
    """The unit that makes the leg closest to an adult's (log scale)."""
    name = min(UNITS, key=lambda u: abs(math.log(leg_file_units * UNITS[u] / TYPICAL_LEG_M)))
    return name, UNITS[name]


def _parse_units(units: str) -> tuple[str, float]:
    u = str(units).lower()
    if u in UNITS:
        return u, UNITS[u]
    try:
        value = float(u)
    except ValueError:
        value = float("nan")
    if not (math.isfinite(value) and value > 0):
        raise CharctlError(f"--units must be one of {', '.join(UNITS)} or metres per file unit (> 0), got {units!r}")
    return f"x{value:g}", value
