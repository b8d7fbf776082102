"""report.md and the figures of `charctl eval RUN... --pose-error [--dtw]` for com-cnn (paper §4, Table 5):
teacher-forced and autoregressive errors per motion type against the paper's numbers, and generation speed."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from charctl.eval.report import markdown_grid


# ---------------------------------------------------------------------------- report
def plot_ar_curves(ar: dict, fps: float, path: Path) -> None:
    """One panel for all held-out clips, one per paper motion type."""
    from charctl.viz.plots import new_figure, save_figure

    keys = ["all"] + sorted(k for k in next(iter(ar.values()))["curve_deg"] if k != "all")
    fig, axes = new_figure(1, len(keys), figsize=(4.2 * len(keys), 4), squeeze=False)
    for ax, key in zip(axes[0], keys):
        for name, res in ar.items():
            y = np.asarray(res["curve_deg"].get(key, []))
            ax.plot(np.arange(1, len(y) + 1) / fps, y, label=name)
        ax.set_xlabel("horizon (s) of self-fed generation")
        ax.set_title("all held-out clips" if key == "all" else key)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("mean joint-angle error (deg)")
    axes[0][0].legend(fontsize=6)
    save_figure(fig, path)


def render_report(res: dict) -> str:
    """Markdown: Table 5 style comparison, autoregressive curve, training/generation numbers, DTW."""
    types = list(dict.fromkeys([*res["motion_types"], "other"]))
    lines = [
        "# com-cnn evaluation",
        "",
        f"Held-out clips: {', '.join(res['test_clips'])}.  ",
        f"Training clips: {', '.join(res['train_clips'])} (and mirrors where data.mirror).  ",
        "Paper motion types: "
        + "; ".join(f"{k} = DeepMimic labels {', '.join(v)}" for k, v in res["motion_types"].items())
        + "; other = every other label.",
        "",
    ]
    if "teacher_forced" in res:
        lines += _teacher_forced_section(res, types) + _autoregressive_section(res, types) + _speed_section(res)
    if "dtw" in res:
        dtw = markdown_grid(["model", *types, "all"], [_dtw_cells(n, r, types) for n, r in res["dtw"].items()])
        lines += [
            "",
            "## DTW: whole held-out clips generated from their first frame and COM path",
            "",
            "Mean per-frame e_pose (radians, l2 over the movable joints, as "
            "in cgail's eq. 6.1) after DTW alignment to the ground truth; "
            "frame by frame without alignment in brackets.",
            "",
            *dtw.split("\n"),
        ]
    return "\n".join(lines) + "\n"


def _dtw_cells(name: str, r: dict, types: list[str]) -> list[str]:
    """One model's DTW row: aligned (framewise) e_pose per motion type (– where it has none) and overall."""
    per_type = [
        f"{r['per_type'][t]:.3f} ({r['framewise_per_type'][t]:.3f})" if t in r["per_type"] else "–" for t in types
    ]
    return [name, *per_type, f"{r['all']:.3f} ({r['framewise_all']:.3f})"]


def _teacher_forced_section(res: dict, types: list[str]) -> list[str]:
    lines = [
        "## Teacher forcing (Table 5 style): mean joint-angle error, degrees",
        "",
        "History and C_t from the ground truth. Error = angle "
        "between the predicted and the true local rotation, "
        "averaged over the movable joints and every frame of the held-out clips.",
        "",
    ]
    rows = [_teacher_forced_cells(name, r, types) for name, r in res["teacher_forced"].items()]
    paper = res["paper_table5"]
    rows.append(["paper Table 5 (its own mocap; units not stated)", *[paper.get(t, "–") for t in types], "–", "–"])
    lines += markdown_grid(["model", *types, "all", "frames"], rows).split("\n")
    clips = res["test_clips"]
    per_clip = [
        [name, *[f"{r['per_clip'].get(c, float('nan')):.2f}" for c in clips]]
        for name, r in res["teacher_forced"].items()
    ]
    lines += ["", "Per clip (teacher forcing, degrees):", "", *markdown_grid(["model", *clips], per_clip).split("\n")]
    return lines


def _teacher_forced_cells(name: str, r: dict, types: list[str]) -> list:
    """One model's teacher-forcing row: error (degrees) per motion type (– where it has none), overall, frames."""
    return [
        name,
        *[f"{r['per_type'][t]:.2f}" if t in r["per_type"] else "–" for t in types],
        f"{r['all']:.2f}",
        r["frames"],
    ]


def _autoregressive_section(res: dict, types: list[str]) -> list[str]:
    fps = res["fps"]
    ar = res["autoregressive"]
    n = len(next(iter(ar.values()))["curve_deg"]["all"])
    marks = [h for h in (1, 5, 15, 30, 60, 90, 150, 300) if h <= n]
    lines = [
        "",
        "## Autoregressive: error against horizon (history = the model's own output)",
        "",
        "Seeded with ground-truth history at every "
        + "k-th frame of each held-out clip, then self-fed; C_t from the ground truth. "
        "With data.frame=root_t the root's heading frame at t is also the ground truth's "
        "(the paper's input needs it); "
        "with root_prev the model places the root itself.",
        "",
        "![autoregressive error](ar_curve.png)",
        "",
    ]
    rows = []
    for name, r in ar.items():
        for key in ["all", *[t for t in types if t in r["curve_deg"]]]:
            c = r["curve_deg"][key]
            end = f"{r['root_xz_error_m'][-1]:.2f}" if key == "all" else ""
            rows.append([name, key, *[f"{c[h - 1]:.1f}" for h in marks], end])
    header = ["model", "type", *[f"{h / fps:.2f} s" for h in marks], "root xz error at the end (m)"]
    return lines + markdown_grid(header, rows).split("\n")


def _speed_section(res: dict) -> list[str]:
    rows = [_speed_cells(t, res["generation"][name], name) for name, t in res["training"].items()]
    lines = ["", "## Training and generation", "", *markdown_grid(SPEED_HEADER, rows).split("\n")]
    lines += [
        "",
        "Generation demo (eval): seed = the first frames of "
        "the seed clip, then a circle of radius 2 m at 1.2 m/s "
        "with the COM lowered by generate.crouch_drop from 60 % of "
        "the path on. COM tracking = mean distance between the "
        "generated body's COM (paper mass table) and the input COM.",
        "",
    ]
    for n, name in enumerate(res["generation"]):
        g = res["generation"][name]
        lines += [
            f"{name}: root height {g['root_height_m'][0]:.2f}–{g['root_height_m'][1]:.2f} "
            "m for an input COM height of "
            f"{g['input_com_height_m'][0]:.2f}–{g['input_com_height_m'][1]:.2f} m.",
            "",
            f"![generation {n}](generation_{n}.png)",
            "",
        ]
    return lines


SPEED_HEADER = [
    "model",
    "steps",
    "samples",
    "train wall (s)",
    "samples/s",
    "final loss (EMA)",
    "gen frames/s (batch 1, CPU)",
    "x real time",
    "COM tracking (cm)",
]


def _speed_cells(t: dict, g: dict, name: str) -> list:
    """One model's row of the training and generation table (SPEED_HEADER's columns): its training
    numbers `t` and its generation demo's `g`."""
    return [
        name,
        t.get("step"),
        t.get("samples"),
        _fmt(t.get("wall_s"), 1),
        _fmt(t.get("samples_per_s"), 0),
        _fmt(t.get("train_loss_ema"), 4),
        f"{g['frames_per_s']:.0f}",
        f"{g['real_time_factor']:.1f}",
        f"{100 * g['com_tracking_error_m']:.1f}",
    ]


def _fmt(x, digits: int) -> str:
    return "–" if x is None else f"{x:.{digits}f}"
