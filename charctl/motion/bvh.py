"""BVH motion capture files: a writer for the humanoid and a reader for any skeleton.

Writer: joints carry the DeepMimic names (root, chest, neck, right_hip, ..., left_wrist), offsets
in metres, root channels `Xposition Yposition Zposition Zrotation Yrotation Xrotation`, joint
channels `Zrotation Yrotation Xrotation` (degrees; R = Rz Ry Rx applied in that order, as
Blender's importer expects), y-up. End sites mark the head, the toes and the hands.

Reader: any hierarchy and channel order; `BvhMotion.forward_kinematics()` gives world joint
positions and rotations, so the data-driven experiments can take a user's own mocap folder.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from charctl.errors import CharctlError
from charctl.motion import rotations as R
from charctl.motion.clip import Clip
from charctl.motion.skeleton import load_skeleton

# End-site offsets (metres, in the joint's frame) for the humanoid's leaf joints.
_END_SITES = {
    "neck": (0.0, 0.2, 0.0),
    "right_ankle": (0.18, -0.05, 0.0),
    "left_ankle": (0.18, -0.05, 0.0),
    "right_wrist": (0.0, -0.06, 0.0),
    "left_wrist": (0.0, -0.06, 0.0),
}


@dataclass
class BvhMotion:
    """A parsed BVH file. Angles in the file are degrees; `frames` keeps the raw channel values."""

    names: list[str]
    parents: np.ndarray  # (J,) -1 for the root
    offsets: np.ndarray  # (J, 3) in file units
    channels: list[list[str]]  # per joint, e.g. ["Xposition", ..., "Zrotation"]
    frames: np.ndarray  # (T, total channels)
    frame_time: float
    end_sites: dict[int, np.ndarray] = field(default_factory=dict)
    source: str = ""

    @property
    def num_frames(self) -> int:
        return self.frames.shape[0]

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    def _columns(self) -> list[np.ndarray]:
        cols, start = [], 0
        for ch in self.channels:
            cols.append(np.arange(start, start + len(ch)))
            start += len(ch)
        return cols

    def local_transforms(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-joint local translation (T, J, 3) and rotation (T, J, 4 xyzw)."""
        T, J = self.num_frames, len(self.names)
        trans = np.broadcast_to(self.offsets, (T, J, 3)).copy()
        rot = np.tile(R.IDENTITY, (T, J, 1))
        for j, (ch, cols) in enumerate(zip(self.channels, self._columns())):  # load time, not a hot path
            pos_axes = [("XYZ".index(c[0]), k) for k, c in zip(cols, ch) if c.endswith("position")]
            for axis, k in pos_axes:
                trans[:, j, axis] = self.frames[:, k]
            rot_ch = [(c[0].upper(), k) for k, c in zip(cols, ch) if c.endswith("rotation")]
            if rot_ch:
                order = "".join(a for a, _ in rot_ch)
                angles = self.frames[:, [k for _, k in rot_ch]]
                rot[:, j] = Rotation.from_euler(order, angles, degrees=True).as_quat()
        return trans, rot

    def forward_kinematics(self) -> tuple[np.ndarray, np.ndarray]:
        """World joint positions (T, J, 3) in file units and rotations (T, J, 4 xyzw)."""
        trans, rot = self.local_transforms()
        T, J = trans.shape[:2]
        pos = np.empty((T, J, 3))
        wrot = np.empty((T, J, 4))
        for j in range(J):  # parents precede children in a BVH file
            p = self.parents[j]
            if p < 0:
                pos[:, j], wrot[:, j] = trans[:, j], rot[:, j]
            else:
                pos[:, j] = pos[:, p] + R.rotate(wrot[:, p], trans[:, j])
                wrot[:, j] = R.multiply(wrot[:, p], rot[:, j])
        return pos, wrot


# ---------------------------------------------------------------------------- reading
def read_bvh(path: str | Path) -> BvhMotion:
    """Parse a BVH file; any problem is a one-line `CharctlError` naming the file."""
    path = Path(path)
    if not path.is_file():
        raise CharctlError(f"BVH file not found: {path}")
    try:
        return _parse(path.read_text().split(), str(path))
    except CharctlError:
        raise
    except (ValueError, IndexError, UnicodeDecodeError) as exc:
        raise CharctlError(f"{path}: malformed BVH ({exc})") from exc


def _parse(tok: list[str], src: str) -> BvhMotion:
    if not tok or tok[0] != "HIERARCHY":
        raise CharctlError(f"{src}: malformed BVH (does not start with HIERARCHY)")
    names, parents, offsets, channels, end_sites, i = _parse_hierarchy(tok, src)
    if not names:
        raise CharctlError(f"{src}: malformed BVH (no joints)")
    values, frame_time = _parse_motion(tok, i, src, sum(len(c) for c in channels))
    # re-map end-site parent markers (-2 placeholders never reach `parents`)
    return BvhMotion(
        names,
        np.array(parents),
        np.array(offsets),
        channels,
        values,
        frame_time,
        end_sites,
        src,
    )


def _parse_hierarchy(tok: list[str], src: str) -> tuple[list, list, list, list, dict, int]:
    """The HIERARCHY section from token 1 up to MOTION: joint names, parent indices (-1: root),
    offsets (file units), channel names, end-site offsets by joint index, and MOTION's token index."""
    names, parents, offsets, channels, end_sites = [], [], [], [], {}
    stack: list[int] = []
    i = 1
    pending_end = False
    while tok[i] != "MOTION":
        t = tok[i]
        if t in ("ROOT", "JOINT"):
            names.append(tok[i + 1])
            parents.append(stack[-1] if stack else -1)
            channels.append([])
            offsets.append(np.zeros(3))
            i += 2
        elif t == "End":
            pending_end = True
            i += 2
        elif t == "{":
            stack.append(-2 if pending_end else len(names) - 1)
            i += 1
        elif t == "}":
            stack.pop()
            pending_end = False
            i += 1
        elif t == "OFFSET":
            off = np.array([float(x) for x in tok[i + 1 : i + 4]])
            if pending_end:
                end_sites[[s for s in stack if s >= 0][-1]] = off
            else:
                offsets[-1] = off
            i += 4
        elif t == "CHANNELS":
            n = int(tok[i + 1])
            channels[-1] = tok[i + 2 : i + 2 + n]
            i += 2 + n
        else:
            raise CharctlError(f"{src}: malformed BVH (unexpected token {t!r} in HIERARCHY)")
    return names, parents, offsets, channels, end_sites, i


def _parse_motion(tok: list[str], i: int, src: str, width: int) -> tuple[np.ndarray, float]:
    """The MOTION section at token `i`: the (frames, width) channel values and the frame time (s)."""
    if tok[i + 1] != "Frames:" or tok[i + 3] != "Frame" or tok[i + 4] != "Time:":
        raise CharctlError(f"{src}: malformed BVH (MOTION header must give 'Frames:' and 'Frame Time:')")
    n_frames = int(tok[i + 2])
    frame_time = float(tok[i + 5])
    values = np.array([float(x) for x in tok[i + 6 :]])
    if values.size != n_frames * width:
        raise CharctlError(
            f"{src}: malformed BVH ({values.size} motion values, expected {n_frames} frames x {width} channels)"
        )
    if frame_time <= 0 or not np.all(np.isfinite(values)):
        raise CharctlError(f"{src}: malformed BVH (non-positive frame time or non-finite values)")
    return values.reshape(n_frames, width), frame_time


def read_bvh_as_clip(path: str | Path) -> Clip:
    """Read a BVH written with the humanoid's joint names (e.g. by charctl) back into a `Clip`."""
    motion = read_bvh(path)
    skel = load_skeleton()
    missing = [n for n in skel.names if n not in motion.names]
    if missing:
        raise CharctlError(
            f"{path}: BVH skeleton is not the DeepMimic humanoid (missing joints {', '.join(missing[:4])}); "
            "data-driven experiments take other skeletons through data.bvh_dir"
        )
    trans, rot = motion.local_transforms()
    idx = [motion.names.index(n) for n in skel.names]
    return Clip(
        name=Path(path).stem,
        fps=motion.fps,
        root_pos=trans[:, idx[0]].copy(),
        local_rot=rot[:, idx],
        source=str(path),
        skeleton=skel,
    )


# ---------------------------------------------------------------------------- writing
def write_bvh(clip: Clip, path: str | Path, fps: float | None = None) -> Path:
    """Write `clip` (resampled to `fps` if given) as a BVH file in metres; returns the path."""
    if fps is not None:
        if fps <= 0:
            raise CharctlError(f"--fps must be positive, got {fps}")
        clip = clip.resample(fps)
    skel = clip.skeleton
    children: dict[int, list[int]] = {b: [] for b in range(skel.num_bodies)}
    for b in range(1, skel.num_bodies):
        children[int(skel.parents[b])].append(b)
    lines = ["HIERARCHY"]

    def emit(b: int, depth: int) -> None:
        pad = "\t" * depth
        kind = "ROOT" if b == 0 else "JOINT"
        lines.append(f"{pad}{kind} {skel.names[b]}")
        lines.append(pad + "{")
        off = skel.offsets[b] if b > 0 else np.zeros(3)
        lines.append(f"{pad}\tOFFSET {off[0]:.6f} {off[1]:.6f} {off[2]:.6f}")
        if b == 0:
            lines.append(f"{pad}\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation")
        else:
            lines.append(f"{pad}\tCHANNELS 3 Zrotation Yrotation Xrotation")
        for c in children[b]:
            emit(c, depth + 1)
        if not children[b]:
            e = _END_SITES.get(skel.names[b], (0.0, 0.05, 0.0))
            lines.extend(
                [f"{pad}\tEnd Site", pad + "\t{", f"{pad}\t\tOFFSET {e[0]:.6f} {e[1]:.6f} {e[2]:.6f}", pad + "\t}"]
            )
        lines.append(pad + "}")

    emit(0, 0)
    order = list(skel.dfs_order)
    T, B = clip.num_frames, skel.num_bodies
    euler = Rotation.from_quat(clip.local_rot[:, order].reshape(-1, 4)).as_euler("ZYX", degrees=True).reshape(T, B, 3)
    data = np.concatenate([clip.root_pos, euler.reshape(T, -1)], axis=1)
    return write_bvh_file(path, lines, data, clip.dt)


def write_bvh_file(path: str | Path, hierarchy: list[str], data: np.ndarray, frame_time: float) -> Path:
    """Write a BVH file atomically: `hierarchy` lines (from "HIERARCHY" on), then the MOTION section
    with one row of `data` (T, channels) per frame. Shared by every BVH writer in charctl."""
    T = data.shape[0]
    lines = [*hierarchy, "MOTION", f"Frames: {T}", f"Frame Time: {frame_time:.8f}"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in data]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text("\n".join(lines) + "\n")
    tmp.replace(path)
    return path
