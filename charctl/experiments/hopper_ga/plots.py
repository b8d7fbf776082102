"""Figures of the hopper-ga experiment (matplotlib, Agg): the normalised best-fitness curve
(paper Fig 5.7), target vs actual COM path (Fig 3.14), the limp test (Fig 3.13) and a
side-view strip of one cycle (Fig 5.1-5.5 style)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from charctl.viz.plots import new_figure, save_figure


def normalised_curve(values: list[float]) -> np.ndarray:
    """(eval - min) / (max - min) over the run (paper Fig 5.7); all zeros if the curve is flat."""
    v = np.asarray(values, dtype=float)
    lo, hi = np.nanmin(v), np.nanmax(v)
    return np.zeros_like(v) if hi - lo <= 0 else (v - lo) / (hi - lo)


def fitness_curve(history: dict, path: Path, title: str) -> Path:
    fig, (ax0, ax1) = new_figure(1, 2, figsize=(10, 3.6))
    gens = np.arange(len(history["best"]))
    ax0.plot(gens, normalised_curve(history["best"]), color="k")
    ax0.set_xlabel("generation")
    ax0.set_ylabel("(eval - min) / (max - min)")
    ax0.set_title("best eval, normalised (Fig 5.7)")
    ax1.plot(gens, history["best"], label="best eval")
    ax1.plot(gens, history["mean"], label="mean eval (valid)", alpha=0.7)
    ax1.set_xlabel("generation")
    ax1.set_ylabel("eval (eq 14)")
    ax1.legend(loc="upper right")
    fig.suptitle(title)
    return save_figure(fig, path)


def com_path(motion, path: Path, title: str) -> Path:
    """Top view (x, z) of the eq 7 target COM (dashed) and the actual COM (solid), plus z(t)."""
    fig, (ax0, ax1) = new_figure(2, 1, figsize=(10, 5.2))
    ax0.plot(motion.target[:, 0], motion.target[:, 1], "--", color="tab:red", label="target COM (eq 7)")
    ax0.plot(motion.com[:, 0], motion.com[:, 2], "-", color="k", label="actual COM (eq 8)")
    ax0.set_xlabel("x (m, forward)")
    ax0.set_ylabel("z (m, right +)")
    ax0.legend(loc="upper right")
    ax0.set_title("COM path, top view (Fig 3.14)")
    ax1.plot(motion.t, motion.target[:, 1], "--", color="tab:red", label="target z")
    ax1.plot(motion.t, motion.com[:, 2], "-", color="k", label="actual z")
    ax1.set_xlabel("t (s)")
    ax1.set_ylabel("z (m)")
    fig.suptitle(title)
    return save_figure(fig, path)


def limp(normal, limping, path: Path, title: str) -> Path:
    """Lateral COM of the normal run vs the limp run (left leg's stance shortened, Fig 3.13)."""
    fig, (ax0, ax1) = new_figure(2, 1, figsize=(10, 5.2))
    for ax, m, name in ((ax0, normal, "normal"), (ax1, limping, "limp (left leg)")):
        ax.plot(m.t, m.target[:, 1], "--", color="tab:red", label="target z")
        ax.plot(m.t, m.com[:, 2], "-", color="k", label="COM z")
        ax.axhline(
            float(np.mean(m.com[:, 2])),
            color="tab:blue",
            lw=1,
            label=f"mean COM z = {np.mean(m.com[:, 2]) * 100:+.1f} cm",
        )
        stance = m.support >= 0
        ax.fill_between(
            m.t, -0.1, 0.1, where=stance & (m.support == 0), color="tab:blue", alpha=0.1, label="right stance"
        )
        ax.fill_between(
            m.t, -0.1, 0.1, where=stance & (m.support == 1), color="tab:orange", alpha=0.15, label="left stance"
        )
        ax.set_ylabel("z (m, right +)")
        ax.set_title(name)
        ax.legend(loc="upper right", fontsize=7, ncol=3)
    ax1.set_xlabel("t (s)")
    fig.suptitle(title)
    return save_figure(fig, path)


def strip(motion, s, l: float, path: Path, title: str, frames: int = 12) -> Path:
    """Side view (x, y) stick figures over the first two cycles."""
    from charctl.experiments.hopper_ga.character import matvec3, upper_fk

    r = motion.rollout
    K = len(motion.t)
    idx = np.linspace(0, K - 1, frames).round().astype(int)
    up, rot = upper_fk(s.body, motion.root, motion.upper)
    tip = up + matvec3(rot, np.broadcast_to(s.body.direction * s.body.length[:, None], up.shape))
    fig, ax = new_figure(1, 1, figsize=(12, 3.2))
    for n, k in enumerate(idx):
        shade = 0.2 + 0.6 * n / max(frames - 1, 1)
        legs = r.legs
        for side, col in ((0, (0.2, 0.4, shade)), (1, (shade, 0.45, 0.2))):
            pts = np.stack([legs.hip[0, k, side], legs.knee[0, k, side], legs.foot[0, k, side]])
            ax.plot(pts[:, 0], pts[:, 1], "-", color=col, lw=1.5)
        for j in range(len(s.body.names)):
            ax.plot([up[k, j, 0], tip[k, j, 0]], [up[k, j, 1], tip[k, j, 1]], "-", color=(0.3, 0.3, 0.3), lw=1.2)
        ax.plot([motion.root[k, 0], up[k, 0, 0]], [motion.root[k, 1], up[k, 0, 1]], "-", color=(0.3, 0.3, 0.3), lw=1.2)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_title(title)
    return save_figure(fig, path)
