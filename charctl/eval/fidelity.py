"""Motion fidelity of a character against a reference clip, on plain arrays (docs/cgail.md, "Fidelity").

Every function takes world-frame body positions (..., 15, 3) and rotations (..., 15, 4, xyzw) of the
DeepMimic humanoid (charctl body order, world y up, the ground plane at y = 0) and works on whole
arrays: no loop over bodies or frames in Python.

- `heading_positions`: body positions relative to the root, in the root's heading frame (the root's yaw
  about +y removed, as `charctl.experiments.cgail.features` does): +x forward, y up, +z right. The
  root itself is always at 0 there.
- `body_error_and_coverage`: (a) the mean body-position error along the DTW alignment: the frame cost
  is the mean over the 15 bodies of the Euclidean distance between the two heading-frame positions
  (the root's term is 0 by construction, so this is 14/15 of the mean over the other 14 bodies), and
  the error is the mean cost over the aligned frame pairs; (b) pose coverage: the share of the clip's
  frames that some frame of the sequence matches within `COVERAGE_TOL` = 0.15 m at every body (the
  maximum over bodies of the distance <= 0.15 m).
- `frame_match` / `uncovered_spans`: the same match per clip frame (distance and farthest body), and the
  stretches of the clip that are not covered: where a policy departs from its clip and by which body.
- `signature`: peak height of each foot and hand, airborne share, mean horizontal root speed and mean
  absolute yaw rate (see its docstring for the definitions and the airborne threshold).
"""

from __future__ import annotations

import functools

import numpy as np

from charctl.eval.dtw import dtw_align
from charctl.motion import rotations as R
from charctl.motion.skeleton import load_skeleton

COVERAGE_TOL = 0.15  # m: a clip frame is covered when some frame is this close at every body
AIRBORNE_MARGIN = 0.05  # m above the standing sole height: a foot higher than this is off the ground
FEET = ("right_ankle", "left_ankle")
HANDS = ("right_wrist", "left_wrist")
PEAK_KEYS = ("right_foot_peak", "left_foot_peak", "right_hand_peak", "left_hand_peak")


@functools.lru_cache(maxsize=1)
def _bodies() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(foot body indices, hand body indices, foot-box half extents (3,), foot-box centre in the foot frame (3,))."""
    skel = load_skeleton()
    feet = np.array([skel.index(n) for n in FEET])
    hands = np.array([skel.index(n) for n in HANDS])
    geom = skel.geoms[feet[0]]
    if geom.kind != "box" or skel.geoms[feet[1]] != geom:
        raise ValueError(f"expected the same box geometry on both feet, got {geom} / {skel.geoms[feet[1]]}")
    return feet, hands, np.asarray(geom.size, dtype=float), np.asarray(geom.pos, dtype=float)


def heading_positions(body_pos: np.ndarray, root_rot: np.ndarray) -> np.ndarray:
    """(..., B, 3) positions relative to the root in the root's heading frame.

    `body_pos` (..., B, 3) world positions, `root_rot` (..., 4) the root's world rotation (xyzw)."""
    inv = R.heading_quat(-R.yaw_about_y(root_rot))  # removes the yaw (features.heading_inverse)
    rel = body_pos - body_pos[..., :1, :]
    return R.rotate(np.broadcast_to(inv[..., None, :], rel.shape[:-1] + (4,)), rel)


def body_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, m, B) Euclidean distance of every body between frame i of `a` (n, B, 3) and frame j of `b` (m, B, 3)."""
    return np.linalg.norm(a[:, None] - b[None], axis=-1)


def tile_index(frames: int, clip_frames: int, loop: bool) -> np.ndarray:
    """Clip frame index of each frame of the DTW reference: a looping clip is tiled (its last frame,
    which closes the loop, dropped between repeats) to `frames` frames when it is shorter, as
    `charctl.experiments.cgail.metrics.skill_reference` tiles rotations; any other clip is used once."""
    if not loop or frames <= clip_frames or clip_frames < 2:
        return np.arange(clip_frames)
    reps = int(np.ceil(frames / (clip_frames - 1)))
    return np.concatenate([np.tile(np.arange(clip_frames - 1), reps), [clip_frames - 1]])[:frames]


def _best_match(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """From (n, m, B) distances: per clip frame j, the smallest over the n sequence frames of the farthest
    body's distance (m,) in m, and the index (m,) of that farthest body in the best-matching frame."""
    worst = d.max(axis=-1)  # (n, m): the farthest body
    best = worst.argmin(axis=0)
    cols = np.arange(d.shape[1])
    return worst[best, cols], d[best, cols].argmax(axis=-1)


def frame_match(seq: np.ndarray, clip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which parts of the clip a sequence does: per clip frame, (distance (m,) in m, body (m,) index).

    `seq` (n, B, 3) and `clip` (m, B, 3) are heading-frame positions (`heading_positions`). The distance
    of clip frame j is that of its best-matching sequence frame, measured at the body farthest from the
    clip there; `body` names that body. Frame j counts as covered when the distance is <= `COVERAGE_TOL`,
    so the mean of (distance <= COVERAGE_TOL) is `body_error_and_coverage`'s coverage."""
    return _best_match(body_distances(seq, clip))


def uncovered_spans(covered: np.ndarray) -> list[tuple[int, int]]:
    """Runs of consecutive False in a (m,) bool array, as (first, last) frame indices, last inclusive."""
    edges = np.diff(np.concatenate([[1], np.asarray(covered, dtype=np.int8), [1]]))
    return list(zip(np.flatnonzero(edges == -1).tolist(), (np.flatnonzero(edges == 1) - 1).tolist()))


def error_and_frame_match(
    seq: np.ndarray, clip: np.ndarray, loop: bool = False
) -> tuple[float, np.ndarray, np.ndarray]:
    """(mean body-position error along the DTW alignment (m), then `frame_match`'s distance (m,) and body (m,)) of
    one sequence, from one computation of the body distances. `seq`, `clip` and `loop` as `body_error_and_coverage`."""
    d = body_distances(seq, clip)  # (n, m, B)
    cost = d.mean(axis=-1)[:, tile_index(len(seq), len(clip), loop)]
    i, j, _ = dtw_align(cost)
    return (float(cost[i, j].mean()), *_best_match(d))


def body_error_and_coverage(
    seq: np.ndarray, clip: np.ndarray, loop: bool = False, tol: float = COVERAGE_TOL
) -> tuple[float, float]:
    """(mean body-position error along the DTW alignment (m), pose coverage in [0, 1]) of one sequence.

    `seq` (n, B, 3) and `clip` (m, B, 3) are heading-frame positions (`heading_positions`). The DTW
    reference is the clip, tiled to n frames when it loops (`tile_index`); coverage counts the clip's
    own m frames."""
    error, dist, _ = error_and_frame_match(seq, clip, loop)
    return error, float(np.mean(dist <= tol))


def foot_sole_heights(body_pos: np.ndarray, body_rot: np.ndarray) -> np.ndarray:
    """(..., 2) height above the ground (y = 0) of the lowest point of each foot's box (right, left)."""
    feet, _, half, centre = _bodies()
    m = R.to_matrix(body_rot[..., feet, :])  # (..., 2, 3, 3)
    mid_y = body_pos[..., feet, 1] + m[..., 1, :] @ centre
    return mid_y - np.abs(m[..., 1, :]) @ half


def standing_sole_height(body_pos: np.ndarray, body_rot: np.ndarray) -> float:
    """The sole height of a foot standing on the ground in this sequence: the 10th percentile over
    frames of the lower foot's sole height. Clips need it: their feet sink into the ground by up to
    7 cm (run -4.3 cm, kick -2.6 cm, walk 0.0 cm here), a simulated foot cannot."""
    return float(np.percentile(foot_sole_heights(body_pos, body_rot).min(axis=-1), 10))


def signature(
    body_pos: np.ndarray,
    body_rot: np.ndarray,
    dt: float,
    ground: float = 0.0,
    lengths: np.ndarray | None = None,
) -> dict[str, np.ndarray | float]:
    """What the motion does, in numbers a viewer would check.

    `body_pos` (T, 15, 3) / `body_rot` (T, 15, 4) world frame, one sequence; or (E, T, 15, ...) for E
    sequences padded to T frames, with `lengths` (E,) the number of valid frames of each. `dt` the
    time between frames (s). Returns floats for one sequence, (E,) arrays for several:

    - `right_foot_peak`, `left_foot_peak`, `right_hand_peak`, `left_hand_peak`: the highest world y (m
      above the ground plane, y is up) of the ankle / wrist body origin over the frames;
    - `airborne`: share of frames with both feet off the ground, a foot being off when the lowest point
      of its box is more than `AIRBORNE_MARGIN` = 5 cm above `ground`, the sequence's standing sole
      height (0 for the simulator, whose feet rest on the plane; `standing_sole_height` of the clip
      for a clip, whose feet sink into the ground);
    - `speed`: mean horizontal root speed, m/s: the root's path length in the xz plane over the time;
    - `yaw_rate`: mean absolute rate of the root's heading (yaw about +y, unwrapped), rad/s.
    """
    single = body_pos.ndim == 3
    pos = body_pos[None] if single else body_pos
    rot = body_rot[None] if single else body_rot
    E, T = pos.shape[:2]
    n = np.full(E, T) if lengths is None else np.asarray(lengths, dtype=int)
    valid = np.arange(T)[None, :] < n[:, None]  # (E, T)
    step_valid = valid[:, 1:] & valid[:, :-1]  # (E, T-1): both ends of the step recorded
    feet, hands, _, _ = _bodies()
    heights = np.where(valid[..., None], pos[:, :, np.concatenate([feet, hands]), 1], -np.inf).max(axis=1)  # (E, 4)
    sole = foot_sole_heights(pos, rot).min(axis=-1)  # (E, T): the lower foot
    airborne = np.sum((sole > ground + AIRBORNE_MARGIN) & valid, axis=1) / np.maximum(n, 1)
    root = pos[:, :, 0]
    planar = np.linalg.norm(np.diff(root[..., [0, 2]], axis=1), axis=-1)  # (E, T-1) m per frame
    yaw = np.unwrap(R.yaw_about_y(rot[:, :, 0]), axis=1)
    turn = np.abs(np.diff(yaw, axis=1))
    steps = np.maximum(step_valid.sum(axis=1), 1) * dt
    out = {key: heights[:, c] for c, key in enumerate(PEAK_KEYS)}
    out["airborne"] = airborne
    out["speed"] = np.where(step_valid, planar, 0.0).sum(axis=1) / steps
    out["yaw_rate"] = np.where(step_valid, turn, 0.0).sum(axis=1) / steps
    return {k: float(v[0]) for k, v in out.items()} if single else out
