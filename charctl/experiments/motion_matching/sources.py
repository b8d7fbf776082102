"""Source motions for the database: the shipped humanoid locomotion loops or a user's BVH folder.

Every source becomes a `SourceMotion`: root position (T, 3) metres in a y-up world, local joint
rotations (T, J, 4 xyzw; joint 0 = the root's world rotation), world joint positions (T, J, 3)
metres, and which frames may be searched. Looping clips are closed at the seam and unrolled
(DeepMimic "wrap" playback: each cycle continues from the previous one's end, turned by the
cycle's heading change), so every searchable frame has a full past and future trajectory.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.motion import rotations as R


@dataclass
class SourceMotion:
    """One clip of the database source, already at the database rate."""

    name: str
    fps: float
    root_pos: np.ndarray  # (T, 3) world, metres, y-up
    local_rot: np.ndarray  # (T, J, 4) xyzw; joint 0 = root world rotation
    joint_pos: np.ndarray  # (T, J, 3) world, metres
    search_start: int  # first searchable frame
    search_stop: int  # one past the last searchable frame
    period: float = 0.0  # cycle length in frames for unrolled loops (0 = not a loop)


@dataclass
class SkeletonInfo:
    """What the runtime needs to know about the skeleton the database was built from."""

    kind: str  # "humanoid" | "bvh"
    joint_names: list[str]
    forward: np.ndarray  # (3,) root-local forward axis
    end_joints: list[int]  # joints whose positions/velocities are pose features
    bvh_template: object = None  # BvhMotion of the first file (kind == "bvh"), for export
    bvh_scale: float = 1.0  # file units per metre^-1 (metres = file units * scale)
    extra: dict = field(default_factory=dict)


# ---------------------------------------------------------------------------- humanoid clips
def humanoid_sources(cfg) -> tuple[list[SourceMotion], SkeletonInfo]:
    """The configured charctl clips (and their mirrors), loops closed, unrolled and resampled."""
    from charctl.motion.library import load_clip
    from charctl.motion.skeleton import BODY_NAMES

    names = list(cfg.data.clips)
    if not names:
        raise CharctlError("data.clips is empty: name at least one locomotion clip (see `charctl data list`)")
    if cfg.data.mirror:
        names += [n + ":mirror" for n in names if not n.endswith(":mirror")]
    unknown = [e for e in cfg.features.end_points if e not in BODY_NAMES]
    if unknown:
        raise CharctlError(f"features.end_points: unknown body {unknown[0]!r}; bodies: {', '.join(BODY_NAMES)}")
    sources = []
    for name in names:
        clip = load_clip(name)
        if clip.num_frames < 3:
            raise CharctlError(f"clip {name!r} has only {clip.num_frames} frames")
        sources.append(_humanoid_source(clip, cfg.data))
    info = SkeletonInfo(
        kind="humanoid",
        joint_names=list(BODY_NAMES),
        forward=np.array([1.0, 0.0, 0.0]),
        end_joints=[BODY_NAMES.index(e) for e in cfg.features.end_points],
    )
    return sources, info


def _humanoid_source(clip, data_cfg) -> SourceMotion:
    """Close/unroll a looping clip, resample it to data.fps and run FK."""
    from charctl.motion.clip import Clip

    src_fps = clip.fps
    root_pos, local_rot = clip.root_pos, clip.local_rot
    before = after = 0
    period = 0.0
    if clip.loop:
        if data_cfg.close_loops:
            root_pos, local_rot = close_loop(root_pos, local_rot, np.array([1.0, 0.0, 0.0]))
        before, after = data_cfg.loop_cycles_before, data_cfg.loop_cycles_after
        root_pos, local_rot = unroll_loop(root_pos, local_rot, before, after, np.array([1.0, 0.0, 0.0]))
    unrolled = clip.replace(root_pos=root_pos, local_rot=local_rot)
    res = unrolled.resample(data_cfg.fps)
    res = Clip(name=clip.name, fps=res.fps, root_pos=res.root_pos, local_rot=res.local_rot, skeleton=clip.skeleton)
    T = res.num_frames
    if clip.loop:
        cycle_s = (clip.num_frames - 1) / src_fps
        period = cycle_s * res.fps
        start = int(round(before * period))
        stop = int(round((before + 1) * period))
    else:
        start, stop = 0, T
    return SourceMotion(clip.name, res.fps, res.root_pos, res.local_rot, res.body_pos, start, stop, period)


def close_loop(root_pos: np.ndarray, local_rot: np.ndarray, forward: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Make the last frame's pose equal the first one's by spreading the seam residual linearly.

    Joint rotations get q'_t = exp(w_t r) q_t with r = log(q_0 q_{T-1}^-1), w_t = t/(T-1); the root
    rotation is treated the same way relative to its heading; the root height is corrected
    linearly. The root's ground position and heading are left alone (they define the cycle).
    """
    T = root_pos.shape[0]
    w = np.linspace(0.0, 1.0, T)
    h = heading_of(local_rot[:, 0], forward)
    rel = R.multiply(R.heading_quat(-h), local_rot[:, 0])
    rot = local_rot.copy()
    rot[:, 0] = rel
    resid = R.log_map(R.multiply(rot[0], R.conjugate(rot[-1])))  # (J, 3)
    rot = R.multiply(R.exp_map(w[:, None, None] * resid[None]), rot)
    rot[:, 0] = R.multiply(R.heading_quat(h), rot[:, 0])
    pos = root_pos.copy()
    pos[:, 1] += w * (root_pos[0, 1] - root_pos[-1, 1])
    return pos, R.normalize(rot)


def unroll_loop(
    root_pos: np.ndarray, local_rot: np.ndarray, before: int, after: int, forward: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Repeat a loop (last frame = next cycle's first) `before` cycles back and `after` forward.

    Cycle c is the base cycle moved by A^c, where A maps the first frame's ground frame onto the
    last frame's (heading change dh, ground translation). Returns (before+1+after)*(T-1)+1 frames.
    """
    T = root_pos.shape[0]
    h = heading_of(local_rot[:, 0], forward)
    dh = float(wrap_angle(h[-1] - h[0]))
    p0, p_end = root_pos[0, [0, 2]], root_pos[-1, [0, 2]]
    cyc_pos, cyc_rot = root_pos[:-1], local_rot[:-1]
    anchors = {0: p0}  # T_c = A^c(p0)
    for c in range(1, after + 2):
        anchors[c] = p_end + rotate_ground(anchors[c - 1] - p0, dh)
    for c in range(-1, -before - 1, -1):
        anchors[c] = p0 + rotate_ground(anchors[c + 1] - p_end, -dh)
    pos_parts, rot_parts = [], []
    for c in range(-before, after + 1):
        ground = anchors[c] + rotate_ground(cyc_pos[:, [0, 2]] - p0, c * dh)
        pos_parts.append(np.stack([ground[:, 0], cyc_pos[:, 1], ground[:, 1]], axis=1))
        r = cyc_rot.copy()
        r[:, 0] = R.multiply(R.heading_quat(np.full(T - 1, c * dh)), r[:, 0])
        rot_parts.append(r)
    last_ground = anchors[after + 1]
    pos_parts.append(np.array([[last_ground[0], root_pos[0, 1], last_ground[1]]]))
    r = local_rot[:1].copy()
    r[:, 0] = R.multiply(R.heading_quat(np.array([(after + 1) * dh])), r[:, 0])
    rot_parts.append(r)
    return np.concatenate(pos_parts), continuous_sign(np.concatenate(rot_parts))


# ---------------------------------------------------------------------------- user BVH folder
def bvh_sources(cfg) -> tuple[list[SourceMotion], SkeletonInfo]:
    """Every .bvh file in data.bvh_dir (one skeleton, y-up), resampled to data.fps."""
    from charctl.motion.bvh import read_bvh

    folder = Path(cfg.data.bvh_dir)
    if not folder.is_dir():
        raise CharctlError(f"data.bvh_dir: not a folder: {folder}")
    files = sorted(folder.glob("*.bvh"))
    if not files:
        raise CharctlError(f"data.bvh_dir: no .bvh files in {folder}")
    motions = [read_bvh(f) for f in files]
    first = motions[0]
    for f, m in zip(files[1:], motions[1:]):
        if m.names != first.names:
            raise CharctlError(f"{f}: skeleton differs from {files[0].name} (one skeleton per data.bvh_dir)")
    scale = cfg.data.bvh_scale or _auto_bvh_scale(first)
    sources = []
    for f, m in zip(files, motions):
        trans, rot = m.local_transforms()
        trans, rot = resample_motion(trans * scale, rot, m.fps, cfg.data.fps)
        fps = m.fps if abs(m.fps - cfg.data.fps) <= 1e-3 * cfg.data.fps else cfg.data.fps
        pos = generic_fk(m.parents, trans, rot)
        if pos.shape[0] < 3:
            raise CharctlError(f"{f}: too few frames ({pos.shape[0]})")
        sources.append(SourceMotion(f.stem, fps, pos[:, 0].copy(), rot, pos, 0, pos.shape[0]))
    forward = _bvh_forward(cfg.data.bvh_forward, sources)
    ends = _bvh_end_joints(cfg.data.bvh_end_joints, first, sources[0].joint_pos)
    info = SkeletonInfo(
        kind="bvh", joint_names=list(first.names), forward=forward, end_joints=ends, bvh_template=first, bvh_scale=scale
    )
    return sources, info


def resample_motion(trans: np.ndarray, rot: np.ndarray, fps: float, new_fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Resample (T, J, 3) translations (linear) and (T, J, 4) rotations (slerp) to `new_fps`."""
    T = trans.shape[0]
    if T < 2 or abs(fps - new_fps) <= 1e-3 * new_fps:  # same rate up to rounding of the frame time
        return trans, rot
    duration = (T - 1) / fps
    n_new = max(2, int(round(duration * new_fps)) + 1)
    src = np.arange(n_new) * (fps / new_fps)
    src = np.minimum(src, T - 1)
    i0 = np.clip(np.floor(src).astype(int), 0, T - 2)
    w = src - i0
    out_t = (1 - w)[:, None, None] * trans[i0] + w[:, None, None] * trans[i0 + 1]
    out_r = R.slerp(rot[i0], rot[i0 + 1], np.broadcast_to(w[:, None], (n_new, rot.shape[1])))
    return out_t, out_r


def generic_fk(parents: np.ndarray, trans: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """World joint positions (T, J, 3) from local translations/rotations; parents precede children."""
    T, J = trans.shape[:2]
    pos = np.empty((T, J, 3))
    wrot = np.empty((T, J, 4))
    for j in range(J):  # load time, once per joint
        p = parents[j]
        if p < 0:
            pos[:, j], wrot[:, j] = trans[:, j], rot[:, j]
        else:
            pos[:, j] = pos[:, p] + R.rotate(wrot[:, p], trans[:, j])
            wrot[:, j] = R.multiply(wrot[:, p], rot[:, j])
    return pos


def _auto_bvh_scale(motion) -> float:
    """0.01 for centimetre files (root higher than 5 units), else 1."""
    trans, _ = motion.local_transforms()
    return 0.01 if float(np.median(trans[:, 0, 1])) > 5.0 else 1.0


_AXES = {"+x": (1.0, 0.0, 0.0), "-x": (-1.0, 0.0, 0.0), "+z": (0.0, 0.0, 1.0), "-z": (0.0, 0.0, -1.0)}


def _bvh_forward(choice: str, sources: list[SourceMotion]) -> np.ndarray:
    """The root-local forward axis: given, or the one best aligned with the direction of travel."""
    if choice != "auto":
        return np.array(_AXES[choice])
    score = dict.fromkeys(_AXES, 0.0)
    for s in sources:
        vel = np.gradient(s.root_pos[:, [0, 2]], axis=0)
        speed = np.linalg.norm(vel, axis=1)
        moving = speed > 0.2 * max(speed.max(), 1e-9)
        for k, a in _AXES.items():
            f = R.rotate(s.local_rot[:, 0], np.broadcast_to(np.array(a), (s.root_pos.shape[0], 3)))[:, [0, 2]]
            f /= np.maximum(np.linalg.norm(f, axis=1, keepdims=True), 1e-9)
            score[k] += float(np.sum(np.sum(f * vel, axis=1)[moving] / speed[moving]))
    return np.array(_AXES[max(score, key=score.get)])


def _bvh_end_joints(names: list[str], motion, joint_pos: np.ndarray) -> list[int]:
    if names:
        missing = [n for n in names if n not in motion.names]
        if missing:
            raise CharctlError(
                f"data.bvh_end_joints: no joint {missing[0]!r} in the BVH; joints: {', '.join(motion.names)}"
            )
        return [motion.names.index(n) for n in names]
    leaves = [j for j in range(len(motion.names)) if j not in set(motion.parents.tolist())]
    heights = joint_pos[:, leaves, 1].mean(axis=0)
    return [leaves[i] for i in np.argsort(heights)[:2]]


# ---------------------------------------------------------------------------- ground-plane helpers
def heading_of(root_rot: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """Heading (radians about +y) of the root's `forward` axis; Ry(h) maps +x onto it."""
    return R.yaw_about_y(root_rot, forward)


def continuous_sign(q: np.ndarray) -> np.ndarray:
    """Flip quaternion signs along axis 0 so consecutive samples have a non-negative dot (vectorised)."""
    s = np.where(np.sum(q[1:] * q[:-1], axis=-1) < 0, -1.0, 1.0)
    flips = np.concatenate([np.ones((1,) + s.shape[1:]), np.cumprod(s, axis=0)])
    return q * flips[..., None]


def wrap_angle(a):
    """Angles wrapped to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def rotate_ground(v: np.ndarray, angle) -> np.ndarray:
    """Rotate ground vectors (..., 2) = (x, z) by Ry(angle): +x -> (cos a, -sin a)."""
    c, s = np.cos(angle), np.sin(angle)
    x, z = v[..., 0], v[..., 1]
    return np.stack([c * x + s * z, -s * x + c * z], axis=-1)


def load_sources(cfg) -> tuple[list[SourceMotion], SkeletonInfo]:
    """Humanoid clips, or the user's BVH folder when data.bvh_dir is set."""
    return bvh_sources(cfg) if cfg.data.bvh_dir else humanoid_sources(cfg)
