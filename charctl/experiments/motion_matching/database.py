"""The motion-matching database: per-frame root-local frames, feature vectors and playback data.

Frames (paper §3): every frame t has a root-local frame on the ground: origin = the root's
ground projection (x, z), axes = heading h_t (radians about +y; "fwd" = Ry(h)·(+x), "lat" =
Ry(h)·(+z), the character's right). Pose and trajectory features are expressed in it:

  pose        root height (m), root tilt (rotation vector of Ry(-h)·q_root, x and z parts, rad),
              end-point positions (fwd, up, lat; m) and velocities (m/s) of `end_points`
  trajectory  future root positions (fwd, lat) at t + o_i, o_i = i * spacing, i = 1..n (m)
              future root velocities at t + o_i (m/s), future facing directions (unit),
              past root positions at t - j * past_spacing (m)

Each block is normalised over the searchable frames (subtract the per-dimension mean, divide by
the block's mean standard deviation, as Holden's implementation), then weighted: the stored
column is (x - mean) / scale * sqrt(w), so the squared L2 distance is sum_d w_d (dx_d)^2 with
w = position_weight * gamma^(i-1) for the i-th future position, velocity_weight * gamma^(i-1)
for its velocity, and so on.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from charctl.errors import CharctlError
from charctl.experiments.motion_matching.exclusion import in_window
from charctl.experiments.motion_matching.sources import (
    SkeletonInfo,
    SourceMotion,
    continuous_sign,
    heading_of,
    load_sources,
    rotate_ground,
    wrap_angle,
)
from charctl.motion import rotations as R

POSE_BLOCKS = ("root_height", "root_tilt", "end_pos", "end_vel")


@dataclass
class FeatureLayout:
    """Column layout, normalisation and weights of the feature matrix."""

    blocks: dict[str, slice]  # block name -> columns
    mean: np.ndarray  # (D,)
    scale: np.ndarray  # (D,)
    sqrt_w: np.ndarray  # (D,)
    future_offsets: np.ndarray  # (n,) database frames
    past_offsets: np.ndarray  # (m,) database frames (positive numbers, looking back)
    pose_dims: int  # columns [0, pose_dims) are the pose part

    @property
    def dims(self) -> int:
        return self.mean.shape[0]

    def normalise(self, raw: np.ndarray, cols: slice | None = None) -> np.ndarray:
        """Raw feature values (..., D) (or the columns `cols`) -> normalised, weighted."""
        cols = cols or slice(0, self.dims)
        return (raw - self.mean[cols]) / self.scale[cols] * self.sqrt_w[cols]


@dataclass
class Database:
    """Playback frames of all clips (concatenated) and the searchable subset."""

    fps: float
    skeleton: SkeletonInfo
    clip_names: list[str]
    clip_id: np.ndarray  # (N,) int
    clip_start: np.ndarray  # (C,) first frame index of each clip
    clip_stop: np.ndarray  # (C,) one past its last frame
    clip_period: np.ndarray  # (C,) cycle length in frames (0 = not a loop)
    phase: np.ndarray  # (N,) frames since the clip's searchable start (mod period for loops)
    ground: np.ndarray  # (N, 2) root ground position (x, z), m
    heading: np.ndarray  # (N,) rad
    height: np.ndarray  # (N,) root height, m
    step_local: np.ndarray  # (N, 2) ground step to the next frame in this frame's local frame (fwd, lat), m
    step_heading: np.ndarray  # (N,) heading change to the next frame, rad
    pose: np.ndarray  # (N, J, 4) local rotations; joint 0 = root rotation relative to the heading
    pose_vel: np.ndarray  # (N, J, 3) angular velocity of `pose` (left / parent frame), rad/s
    height_vel: np.ndarray  # (N,) m/s
    raw: np.ndarray  # (N, D) raw features
    features: np.ndarray  # (N, D) normalised, weighted features
    valid: np.ndarray  # (N,) bool: full past/future horizon available
    search_rows: np.ndarray  # (M,) frame indices that may be returned by a search
    layout: FeatureLayout
    exclude_window: int = 0  # database frames
    info: dict = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return self.clip_id.shape[0]

    @property
    def num_searchable(self) -> int:
        return self.search_rows.shape[0]

    @property
    def search_features(self) -> np.ndarray:
        return self.features[self.search_rows]

    def excluded(self, frames: np.ndarray, cur: int) -> np.ndarray:
        """True for `frames` within the exclusion window around `cur` (`in_window`)."""
        frames = np.asarray(frames)
        c = self.clip_id[frames]
        return in_window(
            c, self.phase[frames], self.clip_period[c], self.clip_id[cur], self.phase[cur], self.exclude_window
        )


def paper_frames(n: float, cfg) -> int:
    """A frame count given at frame_unit_hz (the paper's 120 Hz) in database frames."""
    return int(round(n * cfg.data.fps / cfg.frame_unit_hz))


def feature_offsets(cfg) -> tuple[np.ndarray, np.ndarray]:
    """(future, past) trajectory sample offsets in database frames; one that rounds to 0 frames at
    data.fps is a one-line error."""
    f = cfg.features
    fut = np.array([paper_frames(i * f.future_spacing, cfg) for i in range(1, f.future_samples + 1)])
    past = np.array([paper_frames(j * f.past_spacing, cfg) for j in range(1, f.past_samples + 1)], dtype=int)
    if np.any(fut < 1) or np.any(past < 1):
        raise CharctlError("a feature sample offset rounds to 0 frames at data.fps; raise data.fps or the spacing")
    return fut, past


def build_database(cfg, sources: list[SourceMotion] | None = None, info: SkeletonInfo | None = None) -> Database:
    """Build the database for `cfg` (sources are loaded unless given, to share them across a sweep)."""
    if sources is None or info is None:
        sources, info = load_sources(cfg)
    fut, past = feature_offsets(cfg)
    per_clip = [_clip_arrays(s, info, cfg, fut, past) for s in sources]
    cat = {k: np.concatenate([p[k] for p in per_clip]) for k in per_clip[0] if k not in ("blocks",)}
    lengths = np.array([s.root_pos.shape[0] for s in sources])
    stops = np.cumsum(lengths)
    starts = stops - lengths
    searchable = cat.pop("searchable")
    search_rows = np.flatnonzero(searchable & cat["valid"])
    require_searchable(search_rows.size)
    block_names, block_dims = zip(*per_clip[0]["blocks"])
    raw = cat.pop("raw")
    layout = _layout(raw[search_rows], block_names, block_dims, cfg, fut, past)
    feats = np.where(cat["valid"][:, None], layout.normalise(raw), 0.0)
    return Database(
        fps=sources[0].fps,
        skeleton=info,
        clip_names=[s.name for s in sources],
        clip_id=np.repeat(np.arange(len(sources)), lengths),
        clip_start=starts,
        clip_stop=stops,
        clip_period=np.array([s.period for s in sources]),
        phase=cat["phase"],
        ground=cat["ground"],
        heading=cat["heading"],
        height=cat["height"],
        step_local=cat["step_local"],
        step_heading=cat["step_heading"],
        pose=cat["pose"],
        pose_vel=cat["pose_vel"],
        height_vel=cat["height_vel"],
        raw=raw,
        features=np.ascontiguousarray(feats),
        valid=cat["valid"],
        search_rows=search_rows,
        layout=layout,
        exclude_window=exclude_window_frames(cfg),
    )


def exclude_window_frames(cfg) -> int:
    """runtime.exclude_window in database frames."""
    return paper_frames(cfg.runtime.exclude_window, cfg)


def require_searchable(count: int) -> None:
    """A database needs at least 2 searchable frames; fewer is a one-line error."""
    if count < 2:
        raise CharctlError(
            f"the database has {count} searchable frames: clips are shorter than the "
            "feature horizon (lower features.future_samples/spacing or add longer clips)"
        )


# ---------------------------------------------------------------------------- per clip
def _clip_arrays(s: SourceMotion, info: SkeletonInfo, cfg, fut: np.ndarray, past: np.ndarray) -> dict:
    """Frames, playback data and raw features of one clip, vectorised over its frames."""
    T = s.root_pos.shape[0]
    fps = s.fps
    ground = s.root_pos[:, [0, 2]]
    heading = smoothed_heading(s.local_rot[:, 0], info.forward, cfg.features.heading_smoothing, fps)
    rel_root = R.multiply(R.heading_quat(-heading), s.local_rot[:, 0])
    pose = s.local_rot.copy()
    pose[:, 0] = rel_root
    pose = continuous_sign(pose)
    t = np.arange(T)
    step_local, step_heading = _playback_steps(ground, heading, t)
    blocks = _feature_blocks(s, info, cfg, ground, heading, rel_root, t, fut, past)
    valid = full_horizon(t, fut, past)
    searchable, phase = searchable_and_phase(s, cfg, t)
    return {
        "ground": ground,
        "heading": heading,
        "height": s.root_pos[:, 1].copy(),
        "step_local": step_local,
        "step_heading": step_heading,
        "pose": pose,
        "pose_vel": _pose_velocity(pose, fps),
        "height_vel": np.gradient(s.root_pos[:, 1], 1.0 / fps),
        "phase": phase,
        "valid": valid,
        "searchable": searchable,
        "raw": np.concatenate([b for _, b in blocks], axis=1),
        "blocks": [(n, b.shape[1]) for n, b in blocks],
    }


def _playback_steps(ground: np.ndarray, heading: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per frame, the ground step to the next frame in the frame's heading frame (m) and the heading
    change (rad); the last frame repeats the one before it."""
    T = len(t)
    nxt = np.minimum(t + 1, T - 1)
    step_local = rotate_ground(ground[nxt] - ground, -heading)
    step_heading = wrap_angle(heading[nxt] - heading)
    step_local[-1], step_heading[-1] = step_local[-2], step_heading[-2]
    return step_local, step_heading


def _feature_blocks(
    s: SourceMotion,
    info: SkeletonInfo,
    cfg,
    ground: np.ndarray,
    heading: np.ndarray,
    rel_root: np.ndarray,
    t: np.ndarray,
    fut: np.ndarray,
    past: np.ndarray,
) -> list[tuple[str, np.ndarray]]:
    """The raw feature blocks (name, (T, width)) in layout order: root height and tilt, end effectors
    (m, m/s) in the heading frame, future (and past) trajectory positions, velocities and directions
    at the frame offsets `fut` / `past`."""
    T = len(t)
    fps = s.fps
    vel = np.gradient(ground, 1.0 / fps, axis=0)  # (T, 2) m/s world
    blocks: list[tuple[str, np.ndarray]] = []
    blocks.append(("root_height", s.root_pos[:, 1:2]))
    tilt = R.log_map(rel_root)
    blocks.append(("root_tilt", tilt[:, [0, 2]]))
    ends = s.joint_pos[:, info.end_joints]  # (T, E, 3)
    blocks.append(("end_pos", to_local3(ends - _ground3(ground)[:, None], heading).reshape(T, -1)))
    if cfg.features.end_velocities:
        end_vel = np.gradient(ends, 1.0 / fps, axis=0)
        blocks.append(("end_vel", to_local3(end_vel, heading).reshape(T, -1)))
    fidx = np.minimum(t[:, None] + fut[None], T - 1)  # (T, n)
    h_loc = -heading[:, None]
    f = cfg.features
    blocks.append(("future_pos", rotate_ground(ground[fidx] - ground[:, None], h_loc).reshape(T, -1)))
    if f.velocity_weight > 0:
        blocks.append(("future_vel", rotate_ground(vel[fidx], h_loc).reshape(T, -1)))
    if f.direction_weight > 0:
        d = np.stack([np.cos(heading[fidx] - heading[:, None]), -np.sin(heading[fidx] - heading[:, None])], -1)
        blocks.append(("future_dir", d.reshape(T, -1)))
    if past.size:
        pidx = np.maximum(t[:, None] - past[None], 0)
        blocks.append(("past_pos", rotate_ground(ground[pidx] - ground[:, None], h_loc).reshape(T, -1)))
    return blocks


def full_horizon(t: np.ndarray, fut: np.ndarray, past: np.ndarray) -> np.ndarray:
    """True for the frames `t` of a clip (of len(t) frames) whose whole future (`fut`) and past
    (`past`) sample offsets lie inside the clip."""
    return (t + fut.max() <= len(t) - 1) & (t - (past.max() if past.size else 0) >= 0)


def searchable_and_phase(s: SourceMotion, cfg, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which frames the search may jump to, and each frame's phase (frames; within the period for a
    looping clip, else the frame index, with the last `runtime.end_buffer` frames left out)."""
    T = len(t)
    searchable = (t >= s.search_start) & (t < s.search_stop)
    if s.period <= 0:
        end_buffer = paper_frames(cfg.runtime.end_buffer, cfg)
        searchable &= t < T - 1 - end_buffer
        phase = t.astype(float)
    else:
        phase = np.mod(t - s.search_start, s.period)
    return searchable, phase


def _pose_velocity(pose: np.ndarray, fps: float) -> np.ndarray:
    """Angular velocity (rad/s) of each joint's rotation in its parent frame: left differences,
    averaged to central ones inside the clip."""
    fwd = R.log_map(R.multiply(pose[1:], R.conjugate(pose[:-1]))) * fps
    return (
        np.concatenate([fwd[:1], 0.5 * (fwd[1:] + fwd[:-1]), fwd[-1:]]) if len(pose) > 2 else np.concatenate([fwd, fwd])
    )


def smoothed_heading(root_rot: np.ndarray, forward: np.ndarray, seconds: float, fps: float) -> np.ndarray:
    """Root heading (T,) rad; with seconds > 0 the facing direction is averaged over a centred window."""
    h = heading_of(root_rot, forward)
    win = int(round(seconds * fps))
    if win < 2:
        return h
    from scipy.ndimage import uniform_filter1d

    d = np.stack([np.cos(h), -np.sin(h)], axis=1)
    d = uniform_filter1d(d, size=win | 1, axis=0, mode="nearest")
    return np.arctan2(-d[:, 1], d[:, 0])


def to_local3(v: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """World vectors (T, ..., 3) -> the frame's local (fwd, up, lat) coordinates."""
    h = heading.reshape(heading.shape + (1,) * (v.ndim - 2))
    g = rotate_ground(v[..., [0, 2]], -h)
    return np.stack([g[..., 0], v[..., 1], g[..., 1]], axis=-1)


def _ground3(ground: np.ndarray) -> np.ndarray:
    return np.stack([ground[:, 0], np.zeros(ground.shape[0]), ground[:, 1]], axis=1)


# ---------------------------------------------------------------------------- normalisation
def _layout(raw_search: np.ndarray, names, dims, cfg, fut: np.ndarray, past: np.ndarray) -> FeatureLayout:
    """Per-block mean/scale over the searchable frames and per-column weights."""
    f = cfg.features
    n = fut.size
    disc = f.discount ** np.arange(n)  # gamma^(i-1), i = 1..n
    weights = {
        "root_height": np.full(1, f.pose_weight),
        "root_tilt": np.full(2, f.pose_weight),
        "future_pos": np.repeat(f.position_weight * disc, 2),
        "future_vel": np.repeat(f.velocity_weight * disc, 2),
        "future_dir": np.repeat(f.direction_weight * disc, 2),
        "past_pos": np.full(2 * past.size, f.past_weight),
    }
    blocks, mean, scale, sqrt_w = {}, [], [], []
    col = 0
    for name, d in zip(names, dims):
        x = raw_search[:, col : col + d]
        blocks[name] = slice(col, col + d)
        mean.append(x.mean(axis=0))
        s = float(x.std(axis=0).mean())
        scale.append(np.full(d, s if s > 1e-8 else 1.0))
        sqrt_w.append(np.sqrt(weights.get(name, np.full(d, f.pose_weight))))
        col += d
    pose_dims = sum(d for nme, d in zip(names, dims) if nme in POSE_BLOCKS)
    return FeatureLayout(
        blocks, np.concatenate(mean), np.concatenate(scale), np.concatenate(sqrt_w), fut, past, pose_dims
    )
