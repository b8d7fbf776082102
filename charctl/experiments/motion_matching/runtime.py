"""Online motion matching along a target path (paper §3).

Every `search_interval` frames the controller turns the target path into the desired future
trajectory at the feature's sample offsets, expressed in the character's current root-local
frame; the query is [pose features of the current database frame | desired trajectory]
(normalised and weighted like the database); the nearest database frame outside the exclusion
window is found and playback continues from the frame after it. Between searches the frames
are played segment-wise (vectorised): the global root is rebuilt by accumulating the database's
per-frame root deltas (ground step in the local frame, heading change), and the pose jump at
each transition is inertialized.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from charctl.experiments.motion_matching.database import Database, paper_frames
from charctl.experiments.motion_matching.inertialization import (
    apply_rotation_offset,
    decay_offsets,
    rotation_offset,
)
from charctl.experiments.motion_matching.paths import TargetPath, path_duration
from charctl.experiments.motion_matching.search import search
from charctl.experiments.motion_matching.sources import rotate_ground


@dataclass
class Rollout:
    """A generated motion: root ground path/heading per output frame, the database frames played."""

    fps: float
    ground: np.ndarray  # (T, 2) m
    heading: np.ndarray  # (T,) rad
    frames: np.ndarray  # (T,) database frame played at each output frame
    searches: int
    jumps: int
    search_seconds: float
    height: np.ndarray | None = None  # (T,) m, inertialized
    pose: np.ndarray | None = None  # (T, J, 4) inertialized local rotations (joint 0 heading-relative)
    info: dict = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return self.ground.shape[0]

    def root_rotation(self) -> np.ndarray:
        """(T, 4) world root rotation = Ry(heading) * heading-relative root rotation."""
        from charctl.motion import rotations as R

        return R.multiply(R.heading_quat(self.heading), self.pose[:, 0])


class Controller:
    """Turns the target path into desired trajectory features for the query."""

    def __init__(self, db: Database, path: TargetPath, speed: float, correction_halflife: float):
        self.db, self.path, self.speed, self.halflife = db, path, speed, correction_halflife
        self.tau = db.layout.future_offsets / db.fps  # seconds ahead of each sample
        self.past = db.layout.past_offsets

    def _arc(self, t: np.ndarray) -> np.ndarray:
        s = self.speed * np.asarray(t)
        return s if self.path.closed else np.minimum(s, self.path.length)

    def trajectory_raw(self, t: float, g: np.ndarray, h: float, history: np.ndarray, frame: int) -> np.ndarray:
        """Raw (un-normalised) trajectory features at output time t (s) for a character at ground g, heading h."""
        L = self.db.layout
        s = self._arc(t + self.tau)
        target = self.path.point_at(s)
        if self.halflife > 0:
            target = target + (g - self.path.point_at(self._arc(t)))[None] * 0.5 ** (self.tau / self.halflife)[:, None]
        parts = {"future_pos": rotate_ground(target - g, -h).ravel()}
        if "future_vel" in L.blocks:
            moving = (self.path.closed | (self.speed * (t + self.tau) < self.path.length))[:, None]
            vel = self.path.tangent_at(s) * self.speed * moving
            parts["future_vel"] = rotate_ground(vel, -h).ravel()
        if "future_dir" in L.blocks:
            parts["future_dir"] = rotate_ground(self.path.tangent_at(s), -h).ravel()
        if "past_pos" in L.blocks:
            parts["past_pos"] = rotate_ground(self._history(history, frame) - g, -h).ravel()
        return np.concatenate([parts[name] for name in L.blocks if name in parts])

    def _history(self, history: np.ndarray, frame: int) -> np.ndarray:
        """Generated ground positions `past` frames ago; before the start, walking in along the tangent."""
        idx = frame - self.past
        out = history[np.maximum(idx, 0)].copy()
        early = idx < 0
        if early.any():
            back = -idx[early] / self.db.fps * self.speed
            out[early] = history[0] - self.path.tangent_at(0.0)[None] * back[:, None]
        return out


def accumulate_root(g0: np.ndarray, h0: float, steps: np.ndarray, dh: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global ground positions (n, 2) and headings (n,) after n root deltas from (g0, h0).

    steps (n, 2): ground step (fwd, lat) in the local frame of the frame it starts from (m);
    dh (n,): heading change (rad). Step k is rotated by the heading before it.
    """
    h = h0 + np.concatenate([[0.0], np.cumsum(dh)])
    moves = rotate_ground(steps, h[:-1])
    return g0 + np.cumsum(moves, axis=0), h[1:]


def initial_frame(db: Database, traj_query: np.ndarray) -> int:
    """The searchable frame whose trajectory features best match the first desired trajectory."""
    P = db.layout.pose_dims
    d = db.features[db.search_rows, P:] - traj_query
    return int(db.search_rows[np.argmin(np.einsum("ij,ij->i", d, d))])


def shift_start(db: Database, frame: int, shift: float) -> int:
    """The searchable frame `shift` (fraction) of a cycle after `frame` within the same clip."""
    if shift == 0.0:
        return frame
    rows = db.search_rows[db.clip_id[db.search_rows] == db.clip_id[frame]]
    k = int(np.searchsorted(rows, frame))
    return int(rows[(k + int(round(shift * rows.size))) % rows.size])


def run_path(
    db: Database,
    index,
    path: TargetPath,
    cfg,
    with_pose: bool = True,
    seconds: float | None = None,
    start_shift: float = 0.0,
) -> Rollout:
    """Follow `path` with motion matching; `with_pose=False` skips the pose blend (sweep speed).

    The first frame is the searchable frame whose trajectory best matches the start of the path;
    `start_shift` in [0, 1) moves it that fraction of its clip's searchable frames further (another
    gait phase of the same clip), to average the sweep over starting conditions.
    """
    import time

    rt = cfg.runtime
    dt = 1.0 / db.fps
    duration = seconds if seconds is not None else path_duration(path, cfg.paths.speed, cfg.paths.laps)
    T = int(np.ceil(duration * db.fps)) + 1
    interval = max(1, paper_frames(rt.search_interval, cfg))
    ctrl = Controller(db, path, cfg.paths.speed, cfg.paths.correction_halflife)
    P = db.layout.pose_dims
    traj_cols = slice(P, db.layout.dims)
    ground, heading, frames, cur = _start_on_path(db, path, ctrl, T, traj_cols, start_shift)
    blend = PoseBlend(db, cur, rt.halflife, with_pose, rt.inertialize_root)

    t, searches, jumps, t_search = 0, 0, 0, 0.0
    while t < T - 1:
        traj = db.layout.normalise(ctrl.trajectory_raw(t * dt, ground[t], heading[t], ground, t), traj_cols)
        query = np.concatenate([db.features[cur, :P], traj])
        tic = time.perf_counter()
        best = _best_match(db, index, query, cur, rt.continue_if_best)
        t_search += time.perf_counter() - tic
        searches += 1
        jumps += int(best != cur)
        stop = db.clip_stop[db.clip_id[best]] - 1
        n = int(min(interval, T - 1 - t, stop - best))
        seg = np.arange(best, best + n)  # frames stepped from; frames best+1 .. best+n are shown
        steps, dh = blend.segment(cur, best, n)
        ground[t + 1 : t + n + 1], heading[t + 1 : t + n + 1] = accumulate_root(ground[t], heading[t], steps, dh)
        frames[t + 1 : t + n + 1] = seg + 1
        t += n
        cur = best + n
    out = Rollout(db.fps, ground, heading, frames, searches, jumps, t_search)
    if with_pose:
        out.height, out.pose = blend.result(T)
    return out


def _start_on_path(
    db: Database, path: TargetPath, ctrl: Controller, T: int, traj_cols: slice, start_shift: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Empty ground (T, 2; m), heading (T,; rad) and frame (T,) tracks with the first entry set: the
    path's start point, facing along its tangent, on the best-matching start frame (shifted by
    `start_shift` of its clip); also that frame."""
    ground = np.empty((T, 2))
    heading = np.empty(T)
    frames = np.empty(T, dtype=int)
    tangent = path.tangent_at(0.0)
    ground[0] = path.point_at(0.0)
    heading[0] = np.arctan2(-tangent[1], tangent[0])
    q0 = db.layout.normalise(ctrl.trajectory_raw(0.0, ground[0], heading[0], ground, 0), traj_cols)
    cur = shift_start(db, initial_frame(db, q0), start_shift)
    frames[0] = cur
    return ground, heading, frames, cur


def _best_match(db: Database, index, query: np.ndarray, cur: int, continue_if_best: bool) -> int:
    """The database frame to play from next: the search's best, or `cur` itself (its clip continues)
    when `continue_if_best` and `cur` is a valid frame before its clip's end that matches as well."""
    best, d2 = search(db, index, query, cur)
    if continue_if_best and db.valid[cur] and cur + 1 < db.clip_stop[db.clip_id[cur]]:
        dc = db.features[cur] - query
        if float(dc @ dc) <= d2:
            best = cur
    return best


def _smooth_rate(x: np.ndarray, dt: float, half: int = 2) -> np.ndarray:
    """Derivative of (N, k) samples by differences over +-half frames (clamped at the ends)."""
    i = np.arange(x.shape[0])
    hi, lo = np.minimum(i + half, x.shape[0] - 1), np.maximum(i - half, 0)
    return (x[hi] - x[lo]) / ((hi - lo)[:, None] * dt)


class PoseBlend:
    """Inertialized pose output and (optionally) inertialized root motion, segment by segment.

    Pose signal: joint rotations (joint 0 relative to the heading) and root height. Root motion
    signal: ground step (fwd, lat) per frame and heading change per frame.
    """

    def __init__(self, db: Database, start: int, halflife: float, with_pose: bool, root: bool):
        self.db, self.halflife, self.with_pose, self.root = db, halflife, with_pose, root
        J = db.pose.shape[1]
        self.rot_off = np.zeros((J, 3))  # current offsets (at the last output frame) and velocities
        self.rot_vel = np.zeros((J, 3))
        self.h_off = self.h_vel = 0.0
        self.m_off = np.zeros(3)  # root motion offsets (step fwd, step lat, dheading) per frame
        self.m_vel = np.zeros(3)
        self.motion = np.concatenate([db.step_local, db.step_heading[:, None]], axis=1) if root else None
        # rate of change of the per-frame steps, over +-2 frames (the steps of a resampled clip are piecewise
        # constant, so a one-frame difference is a train of spikes)
        self.motion_vel = _smooth_rate(self.motion, 1.0 / db.fps) if root else None
        self.poses: list[np.ndarray] = [db.pose[start : start + 1]]
        self.heights: list[np.ndarray] = [db.height[start : start + 1]]

    def segment(self, cur: int, best: int, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Play frames best+1..best+n after showing frame `cur`; returns root steps (n, 2) and dheading (n,)."""
        db, dt = self.db, 1.0 / self.db.fps
        times = np.arange(1, n + 1) * dt
        src, dst = np.arange(best, best + n), np.arange(best + 1, best + n + 1)
        steps, dh = db.step_local[src], db.step_heading[src]
        if self.root:
            # the offset applies to the next step; at a transition it keeps the step that would have come next
            motion = self.motion
            x_src = motion[cur] + self.m_off
            v_src = self.motion_vel[cur] + self.m_vel
            v_dst = self.motion_vel[best]
            o, ov = decay_offsets(x_src - motion[best], v_src - v_dst, self.halflife, np.arange(n + 1) * dt)
            blended = motion[src] + o[:n]
            steps, dh = blended[:, :2], blended[:, 2]
            self.m_off, self.m_vel = o[n], ov[n]
        if self.with_pose:
            # offsets at the transition: output (db[cur] + current offset) minus the new frame db[best]
            out_rot = apply_rotation_offset(self.rot_off, db.pose[cur])
            o_r = rotation_offset(out_rot, db.pose[best])
            v_r = self.rot_vel + db.pose_vel[cur] - db.pose_vel[best]
            o_h = db.height[cur] + self.h_off - db.height[best]
            v_h = self.h_vel + db.height_vel[cur] - db.height_vel[best]
            rr, rv = decay_offsets(o_r, v_r, self.halflife, times)
            hh, hv = decay_offsets(np.array(o_h), np.array(v_h), self.halflife, times)
            self.poses.append(apply_rotation_offset(rr, db.pose[dst]))
            self.heights.append(db.height[dst] + hh)
            self.rot_off, self.rot_vel, self.h_off, self.h_vel = rr[-1], rv[-1], float(hh[-1]), float(hv[-1])
        return steps, dh

    def result(self, T: int) -> tuple[np.ndarray, np.ndarray]:
        return np.concatenate(self.heights)[:T], np.concatenate(self.poses)[:T]
