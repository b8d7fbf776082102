"""Metrics of `charctl eval` for cgail (charctl/experiments/cgail/evaluate.py), computed from the rollouts
of rollouts.py: DTW pose error against the clips (Table 6.1), no-fall share and classifier accuracy,
the Fig 6.8 confusion matrices, and the switch study's latency, falls and whether the new skill is done.
"""

from __future__ import annotations

import warnings

import numpy as np
import torch
import torch.nn.functional as F

from charctl.eval.dtw import dtw_align
from charctl.eval.pose import pose_error_matrix
from charctl.experiments.cgail.policy import TrainedRun
from charctl.experiments.cgail.rollouts import DeviceRun, SwitchRecording, rollout_skill, survival_rollout
from charctl.experiments.cgail.skills import DemoPairs

# Table 6.1 of the paper: per-motion mean per-frame pose error after DTW (AMP, cGAIL).
PAPER_TABLE_6_1 = {
    "walk": (2.462, 1.456),
    "run": (2.162, 0.808),
    "jump": (2.984, 1.781),
    "breakdance": (2.984, 2.233),
    "spindance": (1.397, 1.051),
    "uppercut": (1.307, 0.659),
    "left_punch": (1.125, 1.412),
    "right_punch": (0.881, 1.145),
    "right_kick": (1.942, 1.367),
    "left_kick": (2.301, 1.672),
}


def skill_reference(tr: TrainedRun, skill: int, frames: int) -> np.ndarray:
    """(m, 15, 4) reference local rotations covering `frames` frames (looping clips tiled)."""
    ref = tr.agent.skills[skill]
    rot = ref.local_rot
    if ref.loop and frames > len(rot):
        reps = int(np.ceil(frames / (len(rot) - 1)))
        rot = np.concatenate([rot[:-1]] * reps + [rot[-1:]])[:frames]
    return rot


def dtw_pose_error(rollout_rot: np.ndarray, reference_rot: np.ndarray) -> float:
    """Mean per-frame e_pose along the DTW alignment (12 clip joints; root excluded)."""
    from charctl.motion.skeleton import load_skeleton

    joints = load_skeleton().clip_joint_bodies
    cost = pose_error_matrix(rollout_rot[:, joints], reference_rot[:, joints])
    i, j, total = dtw_align(cost)
    return float(cost[i, j].mean())


# ---------------------------------------------------------------------------- per mode
def dtw_table(runs: list[DeviceRun], episodes: int) -> dict[str, dict[str, float]]:
    """Table 6.1: per skill of the first run, each run's mean DTW pose error and falls, the paper's values."""
    skills = runs[0].skill_names
    table: dict[str, dict[str, float]] = {}
    for s in skills:
        table[s] = {}
        for tr in runs:
            if s not in tr.skill_names:
                continue
            k = tr.skill_index(s)
            seconds = max(2.0, min(5.0, 2 * len(tr.agent.skills[k].local_rot) / tr.cfg.env.control_hz))
            ro = rollout_skill(tr, k, episodes, seconds, seed=1234)
            errs = [dtw_pose_error(r, skill_reference(tr, k, len(r))) for r in ro.local_rot if len(r) > 2]
            table[s][tr.label] = float(np.mean(errs)) if errs else float("nan")
            table[s][f"{tr.label} falls"] = ro.falls
        if s in PAPER_TABLE_6_1:
            table[s]["paper AMP"], table[s]["paper cGAIL"] = PAPER_TABLE_6_1[s]
    return table


def survival_table(runs: list[DeviceRun], episodes: int, seconds: float, seed: int) -> dict[str, dict[str, float]]:
    """Per skill, each run's no-fall share (and classifier accuracy on its motion) over `episodes` episodes."""
    table: dict[str, dict[str, float]] = {}
    for tr in runs:
        for k, s in enumerate(tr.skill_names):
            r = survival_rollout(tr, k, episodes, seconds, seed=seed)
            row = table.setdefault(s, {})
            row[f"{tr.label} no-fall"] = r["no_fall"]
            if "class_acc_policy" in r:
                row[f"{tr.label} class acc"] = r["class_acc_policy"]
    return table


def confusion_matrices(tr: DeviceRun, episodes: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Fig 6.8: (policy, data) (K, K) mean classifier probabilities per commanded skill (the policy's
    3-s episodes from frame 0) and per clip label (the demonstration pairs)."""
    K = len(tr.skill_names)
    policy = np.zeros((K, K))
    for k in range(K):
        ro = rollout_skill(tr, k, episodes, 3.0, seed=seed)
        policy[k] = ro.probs.mean(0)
    data = np.zeros((K, K))
    with torch.no_grad():
        for k, p in enumerate(DemoPairs(tr.agent.skills).pairs):  # the demonstration pairs of each clip
            _, logits = tr.discriminate_for(p, k)
            data[k] = F.softmax(logits, -1).mean(0).cpu().numpy()
    return policy, data


PERFORM_SECONDS = 3.0  # the window after a switch in which the new skill must be seen done (issue 24)
PERFORM_SHARE = 0.8  # done = the higher foot reaches this share of the clip's highest foot, without a fall
# a skill with a heading goal (walk, run) is done when its root's mean speed over the last second watched is within
# this range of shares of its clip's mean speed, without a fall: standing (a kick's guard) and the other gait fail it
PERFORM_SPEED_RANGE = (0.5, 1.5)
# the switch matrix also asks for the clip's poses: B is done only where the frames after the ramp cover at least this
# share of B's clip frames (the fidelity evaluation's pose coverage, 15 cm at every body). The foot rule alone is met
# by a knee-up for the kick and by nothing at all for a punch, the jump or a dance (their feet stay low).
PERFORM_COVERAGE = 0.5


def clip_foot_peak(skill) -> float:
    """The higher foot's peak (m) of `skill`'s clip (a `SkillData`), as the fidelity signature measures it."""
    from charctl.eval.fidelity import signature
    from charctl.experiments.cgail.fidelity import clip_reference

    ref = clip_reference(skill)
    sig = signature(ref.body_pos, ref.body_rot, ref.dt, ref.ground)
    return float(max(sig["right_foot_peak"], sig["left_foot_peak"]))


def foot_peaks(pos: np.ndarray, rot: np.ndarray, hz: float, lengths: np.ndarray | None = None) -> np.ndarray:
    """(N,) the higher foot's peak (m) per trial over recorded frames: `pos` / `rot` (F, N, 15, ...) world bodies at
    `hz` frames per second; `lengths` (N,) frames to count per trial (None: all F)."""
    from charctl.eval.fidelity import signature

    sig = signature(pos.swapaxes(0, 1), rot.swapaxes(0, 1), 1.0 / hz, lengths=lengths)
    return np.maximum(sig["right_foot_peak"], sig["left_foot_peak"])


def performed_after_switch(
    tr: TrainedRun,
    kb: int,
    pos: np.ndarray,
    rot: np.ndarray,
    alive_hist: np.ndarray,
    t_switch: int,
    coverage_from: int | None = None,
) -> dict:
    """Whether skill `kb` is seen done in the frames after a switch to it, per trial without a fall in them: a
    skill with a heading goal (walk, run) when the root's mean horizontal speed over the last second of `pos` is
    within `PERFORM_SPEED_RANGE` x the clip's mean speed; any other skill when the higher foot's peak reaches
    `PERFORM_SHARE` x the clip's. With `coverage_from` (the switch matrix: the ramp's frames) also, for every skill,
    when the frames from that one on cover at least `PERFORM_COVERAGE` of the clip (`switch_coverage`). `pos` /
    `rot` (F, N, 15, ...) world bodies (y up, the root body first) of the F frames after the switch; `alive_hist`
    (T, N) alive before each step."""
    skill = tr.agent.skills[kb]
    clip_peak = clip_foot_peak(skill)
    hz = tr.cfg.env.control_hz
    alive_after = alive_hist[t_switch : t_switch + len(pos)].T  # (N, F)
    lengths = np.where(alive_after.all(axis=1), alive_after.shape[1], alive_after.argmin(axis=1))
    peak = foot_peaks(pos, rot, hz, lengths=np.maximum(lengths, 1))
    speed = last_second_speed(pos[:, :, 0], hz)
    if skill.heading_goal:
        lo, hi = PERFORM_SPEED_RANGE
        done = (speed >= lo * skill.mean_speed) & (speed <= hi * skill.mean_speed)
    else:
        done = peak >= PERFORM_SHARE * clip_peak
    coverage = None
    if coverage_from is not None:
        coverage = switch_coverage(skill, pos, rot, coverage_from, lengths)
        done = done & (coverage >= PERFORM_COVERAGE)
    ok = done & alive_after.all(axis=1)
    return {
        "coverage": None if coverage is None else coverage.tolist(),
        "coverage_mean": None if coverage is None else float(coverage.mean()),
        "foot_peak": peak.tolist(),
        "foot_peak_mean": float(peak.mean()),
        "clip_foot_peak": float(clip_peak),
        "speed": speed.tolist(),
        "speed_mean": float(speed.mean()),
        "clip_speed": float(skill.mean_speed),
        "rule": ("speed" if skill.heading_goal else "foot_peak") + ("+coverage" if coverage_from is not None else ""),
        "performed": int(ok.sum()),
    }


def switch_coverage(skill, pos: np.ndarray, rot: np.ndarray, start: int, lengths: np.ndarray) -> np.ndarray:
    """(N,) per trial, the pose coverage of `skill`'s clip (a `SkillData`; the fidelity evaluation's: the share of
    its frames some recorded frame matches within 15 cm at every body, root-relative in the heading frame) by the
    frames `start` to `lengths` (N,) of `pos` / `rot` (F, N, 15, ...) world bodies; 0 where none are left."""
    from charctl.eval.fidelity import COVERAGE_TOL, heading_positions
    from charctl.experiments.cgail.fidelity import clip_reference

    clip = clip_reference(skill).rel  # (m, 15, 3)
    rel = heading_positions(pos, rot[:, :, 0])  # (F, N, 15, 3)
    worst = np.linalg.norm(rel[:, :, None] - clip[None, None], axis=-1).max(axis=-1)  # (F, N, m): farthest body
    frame = np.arange(len(rel))[:, None]
    kept = (frame >= start) & (frame < np.asarray(lengths)[None, :])  # (F, N): the frames each trial is judged on
    best = np.where(kept[..., None], worst, np.inf).min(axis=0)  # (N, m): `frame_match`'s distance per trial
    return (best <= COVERAGE_TOL).mean(axis=1)


def last_second_speed(root: np.ndarray, hz: float) -> np.ndarray:
    """(N,) mean horizontal speed (m/s) of the root path `root` (F, N, 3; y up) over its last second of frames
    (all F when shorter): the xz path length over that time."""
    seg = root[-(int(hz) + 1) :, :, [0, 2]]
    return np.linalg.norm(np.diff(seg, axis=0), axis=2).sum(axis=0) * hz / max(len(seg) - 1, 1)


def switch_summary(
    tr: TrainedRun,
    kb: int,
    rec: SwitchRecording,
    t_switch: int,
    ramp: int,
    trials: int,
    coverage_from: int | None = None,
) -> dict:
    """One condition of the switch study: latency until P(B) > 0.5 per trial alive at the switch, falls,
    and whether B is seen done (`performed_after_switch`, with `coverage_from` its pose-coverage rule)."""
    live = rec.alive_hist
    pb = rec.probs[t_switch:, :, kb]
    up = live[t_switch:]  # alive before the step: frames after a fall (and its reset) do not count
    latency = []
    for i in np.flatnonzero(rec.alive_at_switch):
        hit = (pb[:, i] > 0.5) & up[:, i]
        latency.append(int(np.argmax(hit)) if hit.any() else None)
    lat_ok = [x for x in latency if x is not None]
    falls = int((~rec.alive).sum())
    return {
        **performed_after_switch(tr, kb, rec.pos_after, rec.rot_after, rec.alive_hist, t_switch, coverage_from),
        "ramp_frames": ramp,
        "alive_at_switch": int(rec.alive_at_switch.sum()),
        "latency_frames_mean": float(np.mean(lat_ok)) if lat_ok else None,
        "latency_frames": latency,
        "never_switched": int(sum(x is None for x in latency)),
        "falls": falls,
        "trials": trials,
    }


def switch_curves(rec: SwitchRecording) -> dict[str, np.ndarray]:
    """Class probabilities (T, K), r_S and r_C (T,) per frame, averaged over the trials alive before the step."""
    live = rec.alive_hist
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)

        def mean(x: np.ndarray) -> np.ndarray:
            return np.nanmean(np.where(live[..., None] if x.ndim == 3 else live, x, np.nan), axis=1)

        return {"probs": mean(rec.probs), "r_style": mean(rec.r_style), "r_class": mean(rec.r_class)}
