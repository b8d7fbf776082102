"""`charctl eval RUN... --dtw --confusion --switch A B --curves --survival S --fidelity` for cgail (docs/cgail.md;
the paper's chapter 6; --fidelity: charctl/experiments/cgail/fidelity.py).

Every mode writes JSON (+ CSV / PNG) into the output folder (default `<first run>/eval/`) and
appends its table to `report.md` there, with the command that produced it and the paper's
numbers alongside.

Policy and discriminator inference runs on the torch device of `device` (each run's config, or a
`device=cpu|cuda|auto` override on the command line); the simulator, DTW (dtw-python) and the
tables stay on the host, and only actions, probabilities and rewards come back from the device.
"""

from __future__ import annotations

import csv
import shlex
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from charctl.checkpoints import checkpoint_file_name
from charctl.errors import CharctlError
from charctl.eval.dtw import dtw_align
from charctl.eval.pose import pose_error_matrix
from charctl.eval.report import append_report, fmt_cell, markdown_table, print_table, write_json
from charctl.experiments.cgail.discriminator import blended_class_reward, style_reward
from charctl.experiments.cgail.policy import (
    TrainedRun,
    load_trained_run,
    local_joint_rotations,
    resolve_run_dirs,
)

EVAL_OVERRIDES = ("output_root", "device")  # the only key=value overrides `charctl eval cgail` takes

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


@dataclass
class SkillRollout:
    """Per-episode recordings of one commanded skill."""

    local_rot: list[np.ndarray]  # each (n_i, 15, 4) until the first fall
    probs: np.ndarray | None  # (n_total, K) classifier probabilities over all recorded pairs
    r_style: np.ndarray  # (n_total,)
    falls: int


# ---------------------------------------------------------------------------- device
@dataclass
class DeviceRun(TrainedRun):
    """A trained run whose policy and discriminator live on torch `device` (loaded on the CPU with
    `weights_only=True`, then moved). Inputs go to the device, results come back as numpy."""

    device: str = "cpu"

    @torch.no_grad()
    def mean_action(self, env) -> np.ndarray:
        """(N, 28) mean actions (PD targets, the policy's action units) as float64 on the host."""
        dev = self.device
        obs = torch.as_tensor(env.state, dtype=torch.float32, device=dev)
        cond = torch.as_tensor(env.command_blend(), dtype=torch.float32, device=dev) if self.agent.conditional else None
        return self.agent.model.mean_action(obs, cond).cpu().numpy().astype(np.float64)

    @torch.no_grad()
    def discriminate(self, pairs: np.ndarray, cond: np.ndarray) -> tuple[torch.Tensor, torch.Tensor | None]:
        """Discriminator score d (B,) and class logits (B, K) (None for AMP) of (B, 266) (o_t, o_t+1)
        pairs whose command blend was `cond` (B, K) (read by a per-skill style head), computed and left
        on the device."""
        dev = self.device
        c = torch.as_tensor(cond, dtype=torch.float32, device=dev)
        return self.agent.disc(torch.as_tensor(pairs, dtype=torch.float32, device=dev), cond=c)

    def discriminate_for(self, pairs: np.ndarray, skill: int) -> tuple[torch.Tensor, torch.Tensor | None]:
        """`discriminate` for pairs all commanded with `skill`."""
        return self.discriminate(pairs, np.eye(len(self.agent.skills))[np.full(len(pairs), skill)])


def split_eval_overrides(overrides: list[str]) -> tuple[str | None, list[str]]:
    """(the `device=` override resolved to a torch device, or None; the other overrides). Anything
    but output_root= / device=, a bad device name or an absent CUDA device is a one-line error, raised
    before any run is loaded."""
    other = [o for o in overrides if o.split("=", 1)[0] not in EVAL_OVERRIDES]
    if other:
        raise CharctlError(f"cgail eval takes only output_root=... and device=... overrides (got {' '.join(other)})")
    devices = [o.split("=", 1)[1] for o in overrides if o.split("=", 1)[0] == "device"]
    rest = [o for o in overrides if o.split("=", 1)[0] != "device"]
    return (eval_device(devices[-1]) if devices else None), rest


def eval_device(name: str) -> str:
    """The torch device `name` (auto | cpu | cuda | cuda:N) stands for: auto -> cuda when available,
    else cpu; a bad name or a missing CUDA device is a one-line CharctlError."""
    from charctl.config import resolve_device

    return resolve_device(str(name))


def load_eval_run(run_dir: str | Path, device: str | None = None, checkpoint: str | None = None) -> DeviceRun:
    """The run's agent with its policy and discriminator on torch `device` (None: the run's configured
    `device`, resolved). The checkpoint is read with `torch.load(weights_only=True,
    map_location="cpu")`: its random-number states must stay CPU ByteTensors for
    `torch.set_rng_state`; only the two inference networks move to the device."""
    tr = load_trained_run(run_dir, checkpoint)
    dev = device if device is not None else eval_device(str(tr.cfg.get("device", "auto")))
    tr.agent.model.to(dev)
    tr.agent.disc.to(dev)
    return DeviceRun(tr.run_dir, tr.cfg, tr.agent, device=dev)


# ---------------------------------------------------------------------------- rollouts
@torch.no_grad()
def rollout_skill(tr: DeviceRun, skill: int, episodes: int, seconds: float, seed: int = 0) -> SkillRollout:
    """`episodes` envs commanded with `skill` (mean actions, RSI at frame 0, no switching)."""
    env = tr.make_env(episodes, seed=seed, switch_prob=0.0, episode_seconds=seconds + 1.0)
    env.forced_command = np.full(episodes, skill)
    env.start_frame = 0
    env.random_yaw = False
    env.reset(np.arange(episodes))
    steps = int(round(seconds * env.cfg.control_hz))
    alive = np.ones(episodes, dtype=bool)
    rots = [[local_joint_rotations(env)[i]] for i in range(episodes)]
    pairs, falls = [], 0
    for _ in range(steps):
        o_t = env.obs.copy()
        res = env.step(tr.mean_action(env))
        rec = alive.copy()
        pairs.append(np.concatenate([o_t, res.pair_next], axis=1)[rec])
        fell = res.terminated & alive
        falls += int(fell.sum())
        alive &= ~res.terminated
        cur = local_joint_rotations(env)
        for i in np.flatnonzero(alive):
            rots[i].append(cur[i])
        if not alive.any():
            break
    d, logits = tr.discriminate_for(np.concatenate(pairs), skill)

    probs = F.softmax(logits, -1).cpu().numpy() if logits is not None else None
    r_style = style_reward(d, tr.agent.cfg.disc.objective).cpu().numpy()
    return SkillRollout([np.array(r) for r in rots], probs, r_style, falls)


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


# ---------------------------------------------------------------------------- modes
def eval_dtw(runs: list[DeviceRun], episodes: int, out: Path) -> dict:
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
    result = {
        "table": table,
        "episodes": episodes,
        "runs": {tr.label: str(tr.run_dir) for tr in runs},
        "metric": "mean per-frame e_pose (radians, l2 over the 12 joints) along the DTW path, RSI at frame 0",
    }
    write_json(out / "dtw.json", result)
    cols = sorted({c for row in table.values() for c in row}, key=_column_order)
    with open(out / "dtw.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["skill", *cols])
        for s, row in table.items():
            w.writerow([s, *[fmt_cell(row.get(c)) for c in cols]])
    print_table("Table 6.1: DTW pose error per skill (lower is better)", table, cols)
    append_report(out, "Table 6.1 — DTW pose error per skill", markdown_table(table, cols), result["metric"])
    return result


@torch.no_grad()
def survival_rollout(tr: DeviceRun, skill: int, episodes: int, seconds: float, seed: int = 0) -> dict:
    """`episodes` envs held on `skill` for `seconds` (mean actions, RSI at random clip frames and
    random headings, no command switches). Returns the fraction that never fell and, for cGAIL,
    the classifier's accuracy on the policy's pairs up to each env's first fall."""
    env = tr.make_env(episodes, seed=seed, switch_prob=0.0, episode_seconds=seconds + 1.0)
    env.forced_command = np.full(episodes, skill)
    env.reset(np.arange(episodes))
    alive = np.ones(episodes, dtype=bool)
    hits, total = torch.zeros((), dtype=torch.long, device=tr.device), 0  # hits stay on the device until the end
    for _ in range(int(round(seconds * env.cfg.control_hz))):
        o_t = env.obs.copy()
        res = env.step(tr.mean_action(env))
        if tr.agent.conditional:
            _, logits = tr.discriminate_for(np.concatenate([o_t, res.pair_next], axis=1)[alive], skill)
            hits += (logits.argmax(-1) == skill).sum()
            total += int(alive.sum())
        alive &= ~res.terminated
    out = {"episodes": episodes, "seconds": seconds, "no_fall": float(alive.mean())}
    if tr.agent.conditional:
        out["class_acc_policy"] = int(hits) / max(total, 1)
    return out


def eval_survival(runs: list[DeviceRun], episodes: int, seconds: float, out: Path, seed: int = 4321) -> dict:
    """Share of episodes without a fall (and classifier accuracy on policy motion) per skill and run;
    `seed` draws the RSI frames and headings (the same for every run, so runs are compared on equal starts)."""
    table: dict[str, dict[str, float]] = {}
    for tr in runs:
        for k, s in enumerate(tr.skill_names):
            r = survival_rollout(tr, k, episodes, seconds, seed=seed)
            row = table.setdefault(s, {})
            row[f"{tr.label} no-fall"] = r["no_fall"]
            if "class_acc_policy" in r:
                row[f"{tr.label} class acc"] = r["class_acc_policy"]
    result = {
        "table": table,
        "episodes": episodes,
        "seconds": seconds,
        "seed": seed,
        "runs": {tr.label: str(tr.run_dir) for tr in runs},
        "metric": "no-fall: share of episodes without a non-foot ground contact (RSI at random frames and "
        "headings, mean actions); class acc: classifier argmax == command on the policy's pairs",
    }
    write_json(out / "survival.json", result)
    cols = sorted({c for row in table.values() for c in row})
    print_table(f"Survival over {seconds:g}-s episodes ({episodes} per skill)", table, cols)
    append_report(
        out, f"Survival — {seconds:g}-s episodes, {episodes} per skill", markdown_table(table, cols), result["metric"]
    )
    return result


def eval_confusion(tr: DeviceRun, episodes: int, out: Path, seed: int = 99) -> dict:
    """Fig 6.8: mean classifier probabilities per commanded skill (policy) and per clip (data)."""
    if not tr.agent.conditional:
        raise CharctlError(f"{tr.run_dir} is an AMP (unconditional) run: it has no classifier for --confusion")
    K = len(tr.skill_names)
    policy = np.zeros((K, K))
    for k in range(K):
        ro = rollout_skill(tr, k, episodes, 3.0, seed=seed)
        policy[k] = ro.probs.mean(0)
    data = np.zeros((K, K))
    with torch.no_grad():
        for k, p in enumerate(tr.agent.demos.pairs):
            _, logits = tr.discriminate_for(p, k)
            data[k] = F.softmax(logits, -1).mean(0).cpu().numpy()
    result = {
        "skills": tr.skill_names,
        "policy": policy.tolist(),
        "data": data.tolist(),
        "policy_diagonal": np.diag(policy).tolist(),
        "data_diagonal": np.diag(data).tolist(),
        "run": str(tr.run_dir),
    }
    write_json(out / "confusion.json", result)
    from charctl.viz.plots import new_figure, save_figure

    fig, axes = new_figure(1, 2, figsize=(4 + 1.1 * K, 2.2 + 0.5 * K))
    for ax, mat, title in zip(axes, (policy, data), ("policy motion (commanded skill)", "clip data (clip label)")):
        im = ax.imshow(mat, vmin=0, vmax=1, cmap="Blues")
        ax.set_xticks(range(K), tr.skill_names, rotation=45, ha="right")
        ax.set_yticks(range(K), tr.skill_names)
        ax.set_xlabel("classifier output")
        ax.set_title(title)
        for i in range(K):
            for j in range(K):
                ax.text(
                    j,
                    i,
                    f"{mat[i, j]:.2f}",
                    ha="center",
                    va="center",
                    color="white" if mat[i, j] > 0.5 else "black",
                    fontsize=8,
                )
    fig.colorbar(im, ax=axes, shrink=0.8)
    save_figure(fig, out / "confusion.png")
    rows = {s: {"policy P(correct)": policy[k, k], "data P(correct)": data[k, k]} for k, s in enumerate(tr.skill_names)}
    print_table("Fig 6.8: classifier confusion (diagonal)", rows, ["policy P(correct)", "data P(correct)"])
    append_report(
        out,
        "Fig 6.8 — classifier confusion diagonal",
        markdown_table(rows, ["policy P(correct)", "data P(correct)"]) + "\n\n![confusion](confusion.png)",
        "rows: commanded skill (policy) or clip label (data); entries: mean softmax probability; rows sum to 1",
    )
    return result


@torch.no_grad()
def eval_switch(
    tr: DeviceRun, a: str, b: str, trials: int, out: Path, before_s: float = 1.0, after_s: float = 2.0
) -> dict:
    """Fig 6.10/6.11: command A -> B mid-episode with and without the ramp; latency and falls.

    Each trial runs `before_s` seconds of A, then the switch, then the ramp (in the ramp condition)
    and `after_s` seconds more. Both conditions are watched over the same window, which ends
    `after_s` after the ramp has finished, so a policy that follows the blended command and turns to
    B near the end of the ramp is seen doing it."""
    if not tr.agent.conditional:
        raise CharctlError(f"{tr.run_dir} is an AMP run: it takes no command, so --switch does not apply")
    ka, kb = tr.skill_index(a), tr.skill_index(b)
    hz = tr.cfg.env.control_hz
    ramp_frames = int(tr.cfg.env.ramp_frames) or 60
    t_switch = int(before_s * hz)
    t_end = t_switch + ramp_frames + int(after_s * hz)
    episode_seconds = t_end / hz + 1.0
    curves, summary = {}, {}
    for name, ramp in (("ramp", ramp_frames), ("no_ramp", 0)):
        env = tr.make_env(trials, seed=7, switch_prob=0.0, ramp_frames=ramp, episode_seconds=episode_seconds)
        env.forced_command = np.full(trials, ka)
        env.start_frame = 0
        env.random_yaw = False
        env.reset(np.arange(trials))
        probs, rs, rc, alive_hist, pos_after, rot_after = [], [], [], [], [], []
        alive = np.ones(trials, dtype=bool)
        for t in range(t_end):
            if t == t_switch:
                env.set_command(np.arange(trials), kb, ramp=ramp > 0)
                env.forced_command = np.full(trials, kb)
                alive_at_switch = alive.copy()
            o_t = env.obs.copy()
            cmd_a, cmd_b, w, blend = env.prev_cmd.copy(), env.cmd.copy(), env.w.copy(), env.command_blend()
            res = env.step(tr.mean_action(env))
            d, logits = tr.discriminate(np.concatenate([o_t, res.pair_next], axis=1), blend)
            p = F.softmax(logits, -1)
            r_c = blended_class_reward(
                p,
                torch.from_numpy(cmd_a).to(tr.device),
                torch.from_numpy(cmd_b).to(tr.device),
                torch.from_numpy(w).float().to(tr.device),
                len(tr.skill_names),
                tr.cfg.reward.class_form,
            )
            probs.append(p)  # device tensors; to the host once, after the episode
            rs.append(style_reward(d, tr.agent.cfg.disc.objective))
            rc.append(r_c)
            alive_hist.append(alive.copy())
            alive &= ~res.terminated
            if t_switch <= t < t_switch + int(PERFORM_SECONDS * hz):  # bodies after the step, for the peaks
                pos_after.append(env.sim.body_pos.copy())
                rot_after.append(env.sim.body_quat_xyzw.copy())
        probs, rs, rc = (torch.stack(x).cpu().numpy() for x in (probs, rs, rc))
        live = np.array(alive_hist)
        pb = probs[t_switch:, :, kb]
        up = live[t_switch:]  # alive before the step: frames after a fall (and its reset) do not count
        latency = []
        for i in np.flatnonzero(alive_at_switch):
            hit = (pb[:, i] > 0.5) & up[:, i]
            latency.append(int(np.argmax(hit)) if hit.any() else None)
        lat_ok = [x for x in latency if x is not None]
        falls = int((~alive).sum())
        summary[name] = {
            **performed_after_switch(tr, kb, np.array(pos_after), np.array(rot_after), np.array(alive_hist), t_switch),
            "ramp_frames": ramp,
            "alive_at_switch": int(alive_at_switch.sum()),
            "latency_frames_mean": float(np.mean(lat_ok)) if lat_ok else None,
            "latency_frames": latency,
            "never_switched": int(sum(x is None for x in latency)),
            "falls": falls,
            "trials": trials,
        }
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mean = lambda x: np.nanmean(np.where(live[..., None] if x.ndim == 3 else live, x, np.nan), axis=1)  # noqa: E731, B023 (used in this iteration)
            curves[name] = {"probs": mean(probs), "r_style": mean(rs), "r_class": mean(rc)}
    _plot_switch(curves, tr.skill_names, ka, kb, t_switch, hz, out / f"switch_{a}_to_{b}.png")
    result = {
        "from": a,
        "to": b,
        "switch_frame": t_switch,
        "summary": summary,
        "run": str(tr.run_dir),
        "curves": {n: {k: v.tolist() for k, v in c.items()} for n, c in curves.items()},
    }
    write_json(out / f"switch_{a}_to_{b}.json", result)
    peak_col = f"{b} foot peak in {PERFORM_SECONDS:g} s (m, clip)"
    rows = {
        n: {
            "latency (frames, P(B)>0.5)": s["latency_frames_mean"],
            "never switched": s["never_switched"],
            "falls": s["falls"],
            "alive at switch": s["alive_at_switch"],
            peak_col: f"{s['foot_peak_mean']:.2f} ({s['clip_foot_peak']:.2f})",
            f"performed (peak >= {PERFORM_SHARE:g} clip, no fall)": s["performed"],
            "trials": s["trials"],
        }
        for n, s in summary.items()
    }
    cols = list(next(iter(rows.values())))
    print_table(f"Fig 6.10/6.11: switch {a} -> {b}", rows, cols)
    append_report(
        out,
        f"Fig 6.10/6.11 — command switch {a} → {b}",
        markdown_table(rows, cols) + f"\n\n![switch](switch_{a}_to_{b}.png)",
        f"switch at frame {t_switch} ({before_s:.1f} s); ramp = {ramp_frames} frames linear "
        f"(eq 4.10); each trial watched until frame {t_end} ({after_s:.1f} s after the ramp ends); "
        f"latency = frames after the switch until the classifier's P({b}) > 0.5",
    )
    return result


PERFORM_SECONDS = 3.0  # the window after a switch in which the new skill must be seen done (issue 24)
PERFORM_SHARE = 0.8  # done = the higher foot reaches this share of the clip's highest foot, without a fall


def performed_after_switch(
    tr: TrainedRun, kb: int, pos: np.ndarray, rot: np.ndarray, alive_hist: np.ndarray, t_switch: int
) -> dict:
    """Whether skill `kb` is seen done in the `PERFORM_SECONDS` after a switch to it: per trial the higher
    foot's peak height (m) over the frames before any fall, against the clip's. `pos` / `rot` (F, N, 15, ...)
    world bodies of the F frames after the switch; `alive_hist` (T, N) alive before each step."""
    from charctl.eval.fidelity import signature
    from charctl.experiments.cgail.fidelity import clip_reference

    ref = clip_reference(tr.agent.skills[kb])
    clip_sig = signature(ref.body_pos, ref.body_rot, ref.dt, ref.ground)
    clip_peak = max(clip_sig["right_foot_peak"], clip_sig["left_foot_peak"])
    alive_after = alive_hist[t_switch : t_switch + len(pos)].T  # (N, F)
    lengths = np.where(alive_after.all(axis=1), alive_after.shape[1], alive_after.argmin(axis=1))
    sig = signature(pos.swapaxes(0, 1), rot.swapaxes(0, 1), 1.0 / tr.cfg.env.control_hz, lengths=np.maximum(lengths, 1))
    peak = np.maximum(sig["right_foot_peak"], sig["left_foot_peak"])
    ok = (peak >= PERFORM_SHARE * clip_peak) & alive_after.all(axis=1)
    return {
        "foot_peak": peak.tolist(),
        "foot_peak_mean": float(peak.mean()),
        "clip_foot_peak": float(clip_peak),
        "performed": int(ok.sum()),
    }


def _plot_switch(curves, names, ka, kb, t_switch, hz, path) -> None:
    from charctl.viz.plots import new_figure, save_figure

    fig, axes = new_figure(3, 2, figsize=(11, 7), sharex=True)
    for col, (name, c) in enumerate(curves.items()):
        t = (np.arange(len(c["r_style"])) - t_switch) / hz
        for k, n in enumerate(names):
            axes[0, col].plot(t, c["probs"][:, k], label=n, lw=2 if k in (ka, kb) else 1)
        axes[0, col].set_title(f"{name.replace('_', ' ')}: class probabilities C(o, o')")
        axes[1, col].plot(t, c["r_style"], color="tab:green")
        axes[1, col].set_title("style reward r_S")
        axes[2, col].plot(t, c["r_class"], color="tab:red")
        axes[2, col].set_title("control reward r_C")
        axes[2, col].set_xlabel("time from switch (s)")
        for r in range(3):
            axes[r, col].axvline(0, color="k", ls=":")
            axes[r, col].set_ylim(-0.05, 1.05)
    axes[0, 0].legend(fontsize=7)
    save_figure(fig, path)


def eval_curves(run_dirs: list[Path], out: Path) -> dict:
    """Training-curve figures from the TensorBoard logs (Fig 6.3, 6.4, 6.6/6.7, 6.9)."""
    from charctl.eval.tb import read_scalars
    from charctl.runs import read_run_config
    from charctl.viz.plots import new_figure, save_figure

    runs = []
    for d in run_dirs:
        cfg = read_run_config(d)
        n_sk = len(cfg.use_skills) if cfg.use_skills else len(cfg.skills)
        kind = "cGAIL" if cfg.cgail.conditional else "AMP"
        if cfg.cgail.conditional and cfg.cgail.class_loss == "ls":
            kind += "-LS"
        runs.append((f"{kind} ({n_sk} skills) {Path(d).name}", cfg, read_scalars(Path(d) / "tb")))
    figs = {
        "curves_reward.png": ("Fig 6.3: mean reward", ["train/reward"]),
        "curves_disc_accuracy.png": (
            "Fig 6.4: discriminator accuracy (data / policy)",
            ["train/disc_acc_data", "train/disc_acc_policy"],
        ),
        "curves_style_loss.png": ("Fig 6.5: style loss", ["losses/disc_style"]),
        "curves_class_loss.png": ("Fig 6.6/6.7: class loss (CE vs LS)", ["losses/disc_class"]),
        "curves_class_accuracy.png": (
            "Fig 6.9: classifier accuracy on data vs policy",
            ["train/class_acc_data", "train/class_acc_policy"],
        ),
        "curves_episode_length.png": ("episode length (control steps)", ["train/episode_length"]),
    }
    logged = sorted({t for _, _, scalars in runs for t in scalars})
    for measure, title in (
        ("coverage", "fidelity: pose coverage of the clip per skill"),
        ("foot_peak", "fidelity: peak height of the higher foot (m) per skill"),
    ):  # train.fidelity_every's fidelity/<skill>/<measure> scalars, where the runs logged them
        tags = [t for t in logged if t.startswith("fidelity/") and t.endswith(f"/{measure}")]
        if tags:
            figs[f"curves_fidelity_{measure}.png"] = (title, tags)
    written = []
    for fname, (title, tags) in figs.items():
        fig, ax = new_figure(figsize=(7, 4))
        any_line = False
        for label, _, scalars in runs:
            for tag in tags:
                if tag in scalars:
                    steps, vals = scalars[tag]
                    name = tag.split("/")[1] if tag.startswith("fidelity/") else tag.split("/")[-1]
                    y = vals if tag.startswith("fidelity/") else _smooth(vals)  # sparse points: drawn as logged
                    ax.plot(
                        steps,
                        y,
                        marker="." if tag.startswith("fidelity/") else None,
                        label=f"{label} {name}" if len(tags) > 1 else label,
                    )
                    any_line = True
        ax.set_title(title)
        ax.set_xlabel("samples")
        if any_line:
            ax.legend(fontsize=7)
        save_figure(fig, out / fname)
        written.append(fname)
    append_report(
        out, "Training curves", "\n".join(f"![{f}]({f})" for f in written), "runs: " + ", ".join(r[0] for r in runs)
    )
    print(f"wrote {len(written)} figures to {out}")
    return {"figures": written}


def _smooth(v: np.ndarray, k: int = 5) -> np.ndarray:
    if len(v) < k:
        return v
    return np.convolve(v, np.ones(k) / k, mode="same")


# ---------------------------------------------------------------------------- entry point
def evaluate(targets: list[str], options: dict, overrides: list[str]) -> None:
    """The modes given in `options` (--dtw, --confusion, --switch, --curves, --survival, --fidelity) over the runs."""
    device, overrides = split_eval_overrides(overrides)
    run_dirs = resolve_run_dirs(targets, overrides, "eval")
    if options.get("fidelity"):
        from charctl.experiments.cgail.fidelity import check_can_render

        check_can_render()  # the filmstrips: a machine that cannot render says so before anything is written
    checkpoint = options.get("checkpoint")
    for d in run_dirs if checkpoint else []:  # also for the modes that load no policy (--curves)
        if not (d / "checkpoints" / checkpoint_file_name(checkpoint)).is_file():
            raise CharctlError(f"checkpoint not found: {d / 'checkpoints' / checkpoint_file_name(checkpoint)}")
    default_out = (
        run_dirs[0] / "eval" / Path(checkpoint_file_name(checkpoint)).stem if checkpoint else run_dirs[0] / "eval"
    )
    out = Path(options.get("out") or default_out)
    episodes = int(options["episodes"]) if options.get("episodes") is not None else 4
    if episodes < 1:
        raise CharctlError(f"-k must be >= 1 episode, got {episodes}")
    needs_policy = any(options.get(m) for m in ("dtw", "confusion", "switch", "survival", "fidelity"))
    runs = [load_eval_run(d, device, checkpoint) for d in run_dirs] if needs_policy else []
    switch_run = check_mode_arguments(runs, options)  # every argument checked before anything is written
    out.mkdir(parents=True, exist_ok=True)
    append_report(
        out,
        None,
        None,
        None,
        command="charctl eval " + " ".join(shlex.quote(a) for a in sys.argv[2:])
        if sys.argv and sys.argv[0].endswith("charctl")
        else None,
    )
    if options.get("curves"):
        eval_curves(run_dirs, out)
    if options.get("survival"):
        eval_survival(runs, episodes, float(options["survival"]), out)
    if options.get("dtw"):
        eval_dtw(runs, episodes, out)
    if options.get("confusion"):
        eval_confusion(next(t for t in runs if t.agent.conditional), episodes, out)
    if options.get("fidelity"):
        from charctl.experiments.cgail.fidelity import eval_fidelity

        eval_fidelity(runs, episodes, out)
    if switch_run is not None:
        a, b = options["switch"]
        eval_switch(switch_run, a, b, max(episodes, 2), out)
    print(f"results in {out}/ (report.md)")


def check_mode_arguments(runs: list[DeviceRun], options: dict) -> DeviceRun | None:
    """One-line CharctlError for a mode the loaded runs cannot serve (--confusion / --switch without a
    conditional run, a --switch skill a run does not have), before any output is written. Returns the
    run --switch studies (the first conditional one), or None without --switch."""
    conditional = next((t for t in runs if t.agent.conditional), None)
    if options.get("confusion") and conditional is None:
        raise CharctlError("--confusion needs a conditional (cGAIL) run")
    if not options.get("switch"):
        return None
    if conditional is None:
        raise CharctlError("--switch needs a conditional (cGAIL) run")
    for name in options["switch"]:
        conditional.skill_index(name)
    return conditional


# ---------------------------------------------------------------------------- output helpers
def _column_order(c: str) -> tuple:
    order = ["cGAIL", "cGAIL-LS", "AMP", "paper cGAIL", "paper AMP"]
    base = c.replace(" falls", "")
    return (order.index(base) if base in order else 9, c.endswith("falls"), c)
