"""What `charctl eval` writes for cgail (charctl/experiments/cgail/evaluate.py): per mode its JSON (+ CSV /
PNG) in the output folder and its table, appended to report.md there with the command that produced it
and the paper's numbers alongside. The table and file helpers are charctl.eval.report's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from charctl.eval import report as shared
from charctl.eval.report import markdown_table, print_table, write_csv, write_json
from charctl.experiments.cgail.config import method_label

REPORT_HEADER = "# cgail evaluation report\n\nPaper values: Table 6.1 (docs/cgail.md). Produced by charctl.\n"
DTW_METRIC = "mean per-frame e_pose (radians, l2 over the 12 joints) along the DTW path, RSI at frame 0"
SURVIVAL_METRIC = (
    "no-fall: share of episodes without a non-foot ground contact (RSI at random frames and "
    "headings, mean actions); class acc: classifier argmax == command on the policy's pairs"
)


def append_report(out: Path, title: str | None, body: str | None, note: str | None, command: str | None = None) -> None:
    """charctl.eval.report.append_report into out/report.md, started with the cgail report's header."""
    shared.append_report(out, title, body, note, command=command, header=REPORT_HEADER)


def write_dtw(out: Path, table: dict, episodes: int, runs: list) -> dict:
    """dtw.json, dtw.csv and the Table 6.1 section of report.md."""
    result = {
        "table": table,
        "episodes": episodes,
        "runs": {tr.label: str(tr.run_dir) for tr in runs},
        "metric": DTW_METRIC,
    }
    write_json(out / "dtw.json", result)
    cols = sorted({c for row in table.values() for c in row}, key=_column_order)
    write_csv(out / "dtw.csv", table, cols, index="skill")
    print_table("Table 6.1: DTW pose error per skill (lower is better)", table, cols)
    append_report(out, "Table 6.1 — DTW pose error per skill", markdown_table(table, cols), result["metric"])
    return result


def write_survival(out: Path, table: dict, episodes: int, seconds: float, seed: int, runs: list) -> dict:
    """survival.json and its section of report.md."""
    result = {
        "table": table,
        "episodes": episodes,
        "seconds": seconds,
        "seed": seed,
        "runs": {tr.label: str(tr.run_dir) for tr in runs},
        "metric": SURVIVAL_METRIC,
    }
    write_json(out / "survival.json", result)
    cols = sorted({c for row in table.values() for c in row})
    print_table(f"Survival over {seconds:g}-s episodes ({episodes} per skill)", table, cols)
    append_report(
        out, f"Survival — {seconds:g}-s episodes, {episodes} per skill", markdown_table(table, cols), result["metric"]
    )
    return result


def write_confusion(out: Path, tr, policy: np.ndarray, data: np.ndarray) -> dict:
    """confusion.json, confusion.png (both matrices) and the Fig 6.8 section of report.md."""
    K = len(tr.skill_names)
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


def write_switch(out: Path, tr, a: str, b: str, ka: int, kb: int, summary: dict, curves: dict, frames: dict) -> dict:
    """switch_<a>_to_<b>.png / .json and the Fig 6.10/6.11 section of report.md. `frames`: the study's
    switch_frame, end_frame, ramp_frames, before_s, after_s, and perform_seconds / perform_share (the
    window and foot-peak share of metrics.performed_after_switch)."""
    t_switch, t_end, ramp_frames = frames["switch_frame"], frames["end_frame"], frames["ramp_frames"]
    before_s, after_s = frames["before_s"], frames["after_s"]
    perform_seconds, perform_share = frames["perform_seconds"], frames["perform_share"]
    _plot_switch(curves, tr.skill_names, ka, kb, t_switch, tr.cfg.env.control_hz, out / f"switch_{a}_to_{b}.png")
    result = {
        "from": a,
        "to": b,
        "switch_frame": t_switch,
        "summary": summary,
        "run": str(tr.run_dir),
        "curves": {n: {k: v.tolist() for k, v in c.items()} for n, c in curves.items()},
    }
    write_json(out / f"switch_{a}_to_{b}.json", result)
    peak_col = f"{b} foot peak in {perform_seconds:g} s (m, clip)"
    rows = {
        n: {
            "latency (frames, P(B)>0.5)": s["latency_frames_mean"],
            "never switched": s["never_switched"],
            "falls": s["falls"],
            "alive at switch": s["alive_at_switch"],
            peak_col: f"{s['foot_peak_mean']:.2f} ({s['clip_foot_peak']:.2f})",
            f"performed (kick: peak >= {perform_share:g} clip; walk/run: speed; no fall)": s["performed"],
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


def write_switch_matrix(out: Path, tr, cells: dict, frames: dict) -> dict:
    """switch_matrix.json / .png and its report section: per ordered pair (A, B) of `cells` (`switch_summary` dicts,
    ramp condition) the trials where B is performed, the falls and how many never switched (P(B) > 0.5)."""
    names = tr.skill_names
    K = len(names)
    share = np.full((K, K), np.nan)
    for (a, b), c in cells.items():
        share[names.index(a), names.index(b)] = c["performed"] / c["trials"]
    worst = min(cells.items(), key=lambda kv: kv[1]["performed"] / kv[1]["trials"])
    result = {
        "skills": names,
        "performed_share": [[None if np.isnan(v) else float(v) for v in row] for row in share],
        "pairs": [{"from": a, "to": b, **c} for (a, b), c in cells.items()],
        "worst_pair": list(worst[0]),
        "frames": frames,
        "run": str(tr.run_dir),
    }
    write_json(out / "switch_matrix.json", result)
    import matplotlib

    from charctl.viz.plots import new_figure, save_figure

    fig, ax = new_figure(1, 1, figsize=(3 + 0.8 * K, 2.4 + 0.6 * K))
    cmap = matplotlib.colormaps["RdYlGn"].with_extremes(bad="lightgray")  # the diagonal: no switch
    ax.imshow(np.ma.masked_invalid(share), vmin=0, vmax=1, cmap=cmap)
    ax.set_xticks(range(K), names, rotation=45, ha="right")
    ax.set_yticks(range(K), names)
    ax.set_xlabel("to (B)")
    ax.set_ylabel("from (A)")
    ax.set_title("switch A -> B with the ramp: share performed")
    for (a, b), c in cells.items():
        ax.text(names.index(b), names.index(a), f"{c['performed']}/{c['trials']}", ha="center", va="center", fontsize=8)
    save_figure(fig, out / "switch_matrix.png")
    rows = {
        f"{a} → {b}": {
            "performed": f"{c['performed']} / {c['trials']}",
            "never switched": c["never_switched"],
            "falls": c["falls"],
            "B's measure (clip)": f"speed {c['speed_mean']:.2f} m/s ({c['clip_speed']:.2f})"
            if c["rule"].startswith("speed")
            else f"foot {c['foot_peak_mean']:.2f} m ({c['clip_foot_peak']:.2f})",
            "coverage after the ramp": c["coverage_mean"],
            "latency (frames)": c["latency_frames_mean"],
        }
        for (a, b), c in cells.items()
    }
    cols = list(next(iter(rows.values())))
    print_table("switch matrix (ramp)", rows, cols)
    append_report(
        out,
        "Switch matrix — every ordered pair, with the ramp",
        markdown_table(rows, cols) + "\n\n![switch matrix](switch_matrix.png)",
        f"`--switch A B`'s ramp condition watched {frames['perform_seconds']:g} s after the switch (frame "
        f"{frames['switch_frame']}, ramp {frames['ramp_frames']} frames); performed, without a fall: walk / run (a "
        f"heading goal) at {frames['perform_speed_range'][0]:g}-{frames['perform_speed_range'][1]:g} x the clip's "
        f"speed over the last second, any other skill with the higher foot at {frames['perform_share']:g} x the "
        f"clip's peak, and for every skill the frames after the ramp covering at least "
        f"{frames['perform_coverage']:g} of B's clip (pose coverage, 15 cm at every body); never switched = the "
        "classifier's P(B) never > 0.5 while alive",
    )
    return result


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


def write_curves(run_dirs: list[Path], out: Path) -> dict:
    """Training-curve figures from the TensorBoard logs (Fig 6.3, 6.4, 6.6/6.7, 6.9)."""
    runs = _curve_runs(run_dirs)
    written = []
    for fname, (title, tags) in _curve_figures(runs).items():
        _plot_curves(runs, title, tags, out / fname)
        written.append(fname)
    append_report(
        out, "Training curves", "\n".join(f"![{f}]({f})" for f in written), "runs: " + ", ".join(r[0] for r in runs)
    )
    print(f"wrote {len(written)} figures to {out}")
    return {"figures": written}


def _curve_runs(run_dirs: list[Path]) -> list[tuple[str, object, dict]]:
    """(label, config, TensorBoard scalars) per run; the label names the method (`config.method_label`), its
    skill count and the run folder."""
    from charctl.eval.tb import read_scalars
    from charctl.runs import read_run_config

    runs = []
    for d in run_dirs:
        cfg = read_run_config(d)
        n_sk = len(cfg.use_skills) if cfg.use_skills else len(cfg.skills)
        runs.append((f"{method_label(cfg)} ({n_sk} skills) {Path(d).name}", cfg, read_scalars(Path(d) / "tb")))
    return runs


def _curve_figures(runs: list[tuple[str, object, dict]]) -> dict[str, tuple[str, list[str]]]:
    """File name -> (title, scalar tags) of every curve figure; the fidelity figures only where some
    run logged fidelity/<skill>/<measure> scalars (train.fidelity_every)."""
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
    return figs


def _plot_curves(runs: list[tuple[str, object, dict]], title: str, tags: list[str], path: Path) -> None:
    """One figure: each run's `tags` against samples (smoothed; sparse fidelity points as logged)."""
    from charctl.viz.plots import new_figure, save_figure

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
    save_figure(fig, path)


def _smooth(v: np.ndarray, k: int = 5) -> np.ndarray:
    if len(v) < k:
        return v
    return np.convolve(v, np.ones(k) / k, mode="same")


def _column_order(c: str) -> tuple:
    order = ["cGAIL", "cGAIL-LS", "AMP", "paper cGAIL", "paper AMP"]
    base = c.replace(" falls", "")
    return (order.index(base) if base in order else 9, c.endswith("falls"), c)
