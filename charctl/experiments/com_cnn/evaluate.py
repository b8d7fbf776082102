"""`charctl eval RUN... --pose-error [--dtw]` for com-cnn (paper §4, Table 5).

--pose-error, on the held-out clips of the first run's split:
  (a) teacher forcing: history from the ground truth, C_t from the ground truth; mean joint-angle
      error (degrees, averaged over the movable joints and all frames) per paper motion type, for
      every run given (e.g. the COM model and the history-only model) and the nearest-neighbour
      baseline, with the paper's Table 5 numbers alongside;
  (b) autoregressive: seeded with ground-truth history, then fed its own output, C_t from the
      ground truth; error against time horizon (PNG). With data.frame=root_t the root frame at t is
      the ground truth's (the paper's input needs it); with root_prev nothing but C_t is given.
  plus generation speed (batch 1, CPU, frames/s) of every run.
--dtw: each held-out clip generated autoregressively from its first frame and its COM path, then
  DTW-aligned to the ground truth; mean per-frame e_pose (docs/cgail.md, eq. 6.1; radians, l2 over joints).
Writes report.md, pose_error.json and figures to -o DIR (default: <first run>/eval/).
The metrics and the command are here; report.py writes report.md and the figures.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.eval.report import write_json, write_report
from charctl.experiments.com_cnn.body import BodyModel
from charctl.experiments.com_cnn.checkpoint import LoadedRun, load_run, resolve_targets
from charctl.experiments.com_cnn.data import WindowSet, heading_frame
from charctl.experiments.com_cnn.generate import generation_demo
from charctl.experiments.com_cnn.report import plot_ar_curves, render_report
from charctl.experiments.com_cnn.rollout import (
    Buffer,
    LastFrame,
    Predictor,
    fit_nearest_neighbour,
    given_reference,
    previous_root_reference,
    rollout,
)
from charctl.experiments.com_cnn.sequences import Sequence, motion_type, split_sequences
from charctl.motion import rotations as R

# data keys that must agree for runs to share one evaluation table
SPLIT_KEYS = ("bvh_dir", "clips", "mirror", "test_clips", "fps", "loop_min_seconds", "loop_blend_frames", "bvh_scale")


# ---------------------------------------------------------------------------- metrics
def joint_angles_deg(joint_exp_a: np.ndarray, joint_rot_b: np.ndarray, body: BodyModel) -> np.ndarray:
    """(...,) mean angle (degrees) over the movable joints between exp maps (..., 3J) and quats (..., J, 4)."""
    qa = R.exp_map(joint_exp_a.reshape(joint_exp_a.shape[:-1] + (body.num_joints, 3)))
    return np.degrees(R.angle_between(qa, joint_rot_b)[..., body.error_joints].mean(axis=-1))


def teacher_forced_errors(
    pred: Predictor, seqs: list[Sequence], body: BodyModel, motion_types: dict, chunk: int = 512
) -> dict:
    """Mean joint-angle error (deg) per motion type, per clip and overall, history from the ground truth."""
    from charctl.experiments.com_cnn.train import joint_angle_error_deg

    w = WindowSet(seqs, body, pred.history, pred.frame)
    errs = []
    for s in range(0, len(w), chunk):
        idx = np.arange(s, min(s + chunk, len(w)))
        hist, com, target = w.features(idx)
        errs.append(joint_angle_error_deg(pred.predict(hist, com), target, body))
    err = np.concatenate(errs)
    seq_of = w.table.seq_index[w.targets]
    return summarise(err, [seqs[k] for k in seq_of], motion_types)


def summarise(err: np.ndarray, seq_per_sample: list[Sequence], motion_types: dict) -> dict:
    types = np.array([motion_type(s.label, motion_types) for s in seq_per_sample])
    names = np.array([s.name for s in seq_per_sample])
    out = {"all": float(err.mean()), "frames": int(err.size), "per_type": {}, "per_clip": {}}
    for t in sorted(set(types)):
        out["per_type"][t] = float(err[types == t].mean())
    for n in sorted(set(names)):
        out["per_clip"][n] = float(err[names == n].mean())
    return out


def reference_for(pred: Predictor, body: BodyModel, gt_pos: np.ndarray, gt_rot: np.ndarray):
    """The rollout's reference frames: the model's own last frame (root_prev) or the ground truth's root at t."""
    if pred.frame == "root_prev":
        return previous_root_reference(body)
    return given_reference(*heading_frame(gt_pos, gt_rot, body.forward))


def seed_buffer(seq: Sequence, starts: np.ndarray, history: int) -> Buffer:
    """Ground-truth history windows (B, i) ending just before each start (edge-padded at frame 0)."""
    idx = np.maximum(starts[:, None] - history + np.arange(history)[None, :], 0)
    return Buffer(seq.root_pos[idx], seq.root_rot[idx], R.log_map(seq.joint_rot[idx]).reshape(len(starts), history, -1))


def autoregressive_errors(
    pred: Predictor, seqs: list[Sequence], body: BodyModel, horizon: int, stride: int, motion_types: dict
) -> dict:
    """Joint-angle error (deg) and root position error (m) against the number of generated frames."""
    sums = {"all": np.zeros(horizon)}
    counts = {"all": np.zeros(horizon)}
    root_sum, root_cnt = np.zeros(horizon), np.zeros(horizon)
    for seq in seqs:
        T = seq.num_frames
        H = min(horizon, T - 1)
        starts = np.arange(1, T - H + 1, stride)
        tgt = starts[:, None] + np.arange(H)[None, :]  # (B, H) ground-truth frames
        gen = rollout(
            pred,
            body,
            seed_buffer(seq, starts, pred.history),
            seq.com[tgt],
            reference_for(pred, body, seq.root_pos[tgt], seq.root_rot[tgt]),
        )
        err = joint_angles_deg(gen.joint_exp, seq.joint_rot[tgt], body)  # (B, H)
        kind = motion_type(seq.label, motion_types)
        for key in ("all", kind):
            sums.setdefault(key, np.zeros(horizon))[:H] += err.sum(0)
            counts.setdefault(key, np.zeros(horizon))[:H] += err.shape[0]
        root_sum[:H] += np.linalg.norm((gen.root_pos - seq.root_pos[tgt])[..., [0, 2]], axis=-1).sum(0)
        root_cnt[:H] += err.shape[0]
    curve = {k: (sums[k] / np.maximum(counts[k], 1)).tolist() for k in sums}
    return {
        "curve_deg": curve,
        "root_xz_error_m": (root_sum / np.maximum(root_cnt, 1)).tolist(),
        "rollouts": int(counts["all"][0]),
    }


def dtw_errors(pred: Predictor, seqs: list[Sequence], body: BodyModel, motion_types: dict) -> dict:
    """Each clip generated from its first frame (batched, padded to the longest), DTW e_pose against the truth."""
    from charctl.eval.dtw import mean_aligned_cost
    from charctl.eval.pose import pose_error, pose_error_matrix

    Tmax = max(s.num_frames for s in seqs)
    tgt = np.stack([np.minimum(np.arange(1, Tmax), s.num_frames - 1) for s in seqs])  # (B, H), padded by the last frame

    def stack(attr: str) -> np.ndarray:
        return np.stack([getattr(s, attr)[t] for s, t in zip(seqs, tgt)])

    seed = Buffer(
        np.stack([s.root_pos[:1] for s in seqs]),
        np.stack([s.root_rot[:1] for s in seqs]),
        np.stack([R.log_map(s.joint_rot[:1]).reshape(1, -1) for s in seqs]),
    )
    gen = rollout(pred, body, seed, stack("com"), reference_for(pred, body, stack("root_pos"), stack("root_rot")))
    J = body.num_joints
    ej = body.error_joints
    aligned, framewise = [], []
    for b, s in enumerate(seqs):
        n = s.num_frames - 1
        qa = R.exp_map(gen.joint_exp[b, :n].reshape(n, J, 3))[:, ej]
        qb = s.joint_rot[1:][:, ej]
        aligned.append(mean_aligned_cost(pose_error_matrix(qa, qb)))
        framewise.append(float(pose_error(qa, qb).mean()))
    types = [motion_type(s.label, motion_types) for s in seqs]
    out = {"per_clip": {s.name: a for s, a in zip(seqs, aligned)}, "per_type": {}, "framewise_per_type": {}}
    for t in sorted(set(types)):
        out["per_type"][t] = float(np.mean([a for a, k in zip(aligned, types) if k == t]))
        out["framewise_per_type"][t] = float(np.mean([a for a, k in zip(framewise, types) if k == t]))
    out["all"] = float(np.mean(aligned))
    out["framewise_all"] = float(np.mean(framewise))
    return out


# ---------------------------------------------------------------------------- command
def evaluate(targets: list[str], options: dict, overrides: list[str]) -> dict:
    """`--pose-error` and/or `--dtw` over one or more runs -> pose_error.json, report.md, figures."""
    if not options.get("pose_error") and not options.get("dtw"):
        raise CharctlError("com-cnn evaluates with --pose-error and/or --dtw")
    runs = _load_runs_of_one_split(targets, overrides)
    base = runs[0]
    cfg = base.cfg
    train_seqs, test_seqs = split_sequences(base.seqs, cfg.data.test_clips)
    if not test_seqs:
        raise CharctlError("no held-out clips (data.test_clips is empty): nothing to evaluate")
    body, types = base.body, dict(cfg.eval.motion_types)
    print(f"held-out clips: {', '.join(s.name for s in test_seqs)}")
    preds = _predictors(runs, train_seqs, body)
    out_dir = Path(options.get("out") or base.dir / "eval")
    out_dir.mkdir(parents=True, exist_ok=True)
    result: dict = {
        "runs": [str(r.dir) for r in runs],
        "test_clips": [s.name for s in test_seqs],
        "train_clips": sorted({s.base for s in train_seqs}),
        "motion_types": {k: list(v) for k, v in types.items()},
        "paper_table5": dict(cfg.eval.paper_table5),
        "fps": float(cfg.data.fps),
    }
    if options.get("pose_error"):
        result.update(_pose_error_results(runs, preds, test_seqs, body, types, out_dir))
        plot_ar_curves(result["autoregressive"], float(cfg.data.fps), out_dir / "ar_curve.png")
    if options.get("dtw"):
        result["dtw"] = {p.name: dtw_errors(p, test_seqs, body, types) for p in preds}
    write_json(out_dir / "pose_error.json", result)
    report = render_report(result)
    write_report(out_dir, report)
    print(report)
    print(f"wrote {out_dir / 'report.md'}")
    return result


def _load_runs_of_one_split(targets: list[str], overrides: list[str]) -> list[LoadedRun]:
    """The target runs, labels made unique by their folder name; all must share the first run's split."""
    runs = [load_run(d, overrides) for d in resolve_targets(targets, overrides)]
    labels = [r.label for r in runs]
    for r in runs:
        if labels.count(r.label) > 1:
            r.suffix = f" [{r.dir.name}]"
    base = runs[0]
    for r in runs[1:]:
        diff = [k for k in SPLIT_KEYS if r.cfg.data[k] != base.cfg.data[k]]
        if diff:
            raise CharctlError(
                f"{r.dir} uses different data.{diff[0]} than {base.dir}: evaluate runs of one split together"
            )
    return runs


def _predictors(runs: list[LoadedRun], train_seqs: list[Sequence], body: BodyModel) -> list[Predictor]:
    """Each run's network, then the baselines fitted on the training clips: nearest neighbour, last frame."""
    cfg = runs[0].cfg
    nn = fit_nearest_neighbour(
        WindowSet(train_seqs, body, int(cfg.data.history), str(cfg.data.frame)),
        int(cfg.eval.nn_pca_dims),
        float(cfg.eval.nn_com_weight),
        int(cfg.seed),
    )
    return [r.predictor() for r in runs] + [nn, LastFrame(int(cfg.data.history), str(cfg.data.frame))]


def _pose_error_results(
    runs: list[LoadedRun],
    preds: list[Predictor],
    test_seqs: list[Sequence],
    body: BodyModel,
    types: dict,
    out_dir: Path,
) -> dict:
    """`--pose-error`: teacher-forced and autoregressive errors per predictor (horizon `eval.horizon_s`
    seconds), each run's generation figure in `out_dir`, and its training numbers."""
    cfg = runs[0].cfg
    horizon = max(1, int(round(float(cfg.eval.horizon_s) * cfg.data.fps)))
    return {
        "teacher_forced": {p.name: teacher_forced_errors(p, test_seqs, body, types) for p in preds},
        "autoregressive": {
            p.name: autoregressive_errors(p, test_seqs, body, horizon, int(cfg.eval.ar_stride), types) for p in preds
        },
        "generation": {r.label: generation_demo(r, out_dir / f"generation_{n}.png") for n, r in enumerate(runs)},
        "training": {r.label: {k: r.metrics.get(k) for k in _TRAINING_KEYS} for r in runs},
    }


# the training numbers of each run that pose_error.json and report.md carry
_TRAINING_KEYS = (
    "step",
    "samples",
    "wall_s",
    "samples_per_s",
    "train_loss_ema",
    "test_loss",
    "train_windows",
    "test_windows",
    "parameters",
    "device",
)
