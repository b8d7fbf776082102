"""Plot of how closely a motion matches each frame of its reference clip (docs/cgail.md, "Fidelity").

One panel per clip: x the clip's time (s), y the distance (m) of the clip frame's best match in the motion,
measured at the farthest body (`charctl.eval.fidelity.frame_match`); a thin line per episode, a thick one for
their median, a dashed line at the coverage tolerance, and the stretches that are not covered shaded and
labelled with the body farthest from the clip there.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from charctl.viz.plots import new_figure, save_figure


@dataclass
class FramePanel:
    """One clip's panel. `distance` (E, m) m per episode and clip frame; `spans` (t0 s, t1 s, label)."""

    title: str
    dt: float  # s between clip frames
    distance: np.ndarray
    spans: list[tuple[float, float, str]]


def plot_frame_match(panels: list[FramePanel], path: str | Path, tolerance: float, title: str = "") -> Path:
    """Write the panels, stacked, to a PNG at `path`; returns the path."""
    fig, axes = new_figure(len(panels), 1, figsize=(9.0, 1.9 * len(panels) + 0.6), squeeze=False)
    for ax, p in zip(axes[:, 0], panels):
        d = np.asarray(p.distance, dtype=float)
        t = np.arange(d.shape[1]) * p.dt
        for t0, t1, label in p.spans:
            ax.axvspan(t0 - p.dt / 2, t1 + p.dt / 2, color="tab:red", alpha=0.12, lw=0)
            ax.text((t0 + t1) / 2, 0.97, label, transform=ax.get_xaxis_transform(), ha="center", va="top", fontsize=7)
        for row in d:
            ax.plot(t, row, color="tab:blue", lw=0.6, alpha=0.35)
        ax.plot(t, np.median(d, axis=0), color="tab:blue", lw=1.8, label="median over episodes")
        ax.axhline(tolerance, color="k", ls="--", lw=0.8, label=f"{tolerance:g} m (covered below)")
        ax.set_xlim(-p.dt / 2, t[-1] + p.dt / 2)
        ax.set_ylim(0.0, max(2.2 * tolerance, float(d.max()) * 1.15))
        ax.set_ylabel("farthest body (m)")
        ax.set_title(p.title, fontsize=9, loc="left")
    axes[-1, 0].set_xlabel("clip time (s)")
    axes[0, 0].legend(loc="upper right", fontsize=7, bbox_to_anchor=(1.0, 1.35), ncol=2, frameon=False)
    if title:
        fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)
