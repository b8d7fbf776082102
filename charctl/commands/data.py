"""`charctl data list|show`."""

from __future__ import annotations

import numpy as np
from rich.console import Console
from rich.table import Table

from charctl.motion.library import catalogue, load_clip


def list_clips() -> None:
    table = Table(title="Motion clips (pybullet_data/data/motions)")
    for col, just in [
        ("clip", "left"),
        ("frames", "right"),
        ("fps", "right"),
        ("duration s", "right"),
        ("loop", "left"),
        ("class", "left"),
    ]:
        table.add_column(col, justify=just)
    for e in catalogue():
        c = load_clip(e.name)
        table.add_row(
            e.name, str(c.num_frames), f"{c.fps:.1f}", f"{c.duration:.2f}", "wrap" if c.loop else "none", e.label
        )
    Console().print(table)
    Console().print(
        "Append ':mirror' to any name for the left/right mirrored clip; "
        "a path loads your own DeepMimic .txt or charctl .bvh file."
    )


def clip_summary(name: str) -> dict:
    """Facts about one clip (metres, seconds, m/s)."""
    c = load_clip(name)
    root = c.root_pos
    travel = np.linalg.norm((root[-1] - root[0])[[0, 2]])
    path = np.sum(np.linalg.norm(np.diff(root[:, [0, 2]], axis=0), axis=1))
    com_y = c.com()[:, 1]
    return {
        "clip": c.name,
        "source": c.source,
        "class": c.label,
        "frames": c.num_frames,
        "fps": round(c.fps, 3),
        "duration_s": round(c.duration, 3),
        "loop": "wrap" if c.loop else "none",
        "root_travel_m": round(float(travel), 3),
        "root_path_length_m": round(float(path), 3),
        "mean_speed_m_s": round(float(path / max(c.duration, 1e-9)), 3),
        "root_height_range_m": [round(float(root[:, 1].min()), 3), round(float(root[:, 1].max()), 3)],
        "com_height_range_m": [round(float(com_y.min()), 3), round(float(com_y.max()), 3)],
        "heading_change_deg": round(float(np.degrees(np.unwrap(c.heading())[-1] - c.heading()[0])), 1),
    }


def show_clip(name: str) -> None:
    table = Table(title=f"clip {name}", show_header=False)
    table.add_column("key", style="bold")
    table.add_column("value")
    for k, v in clip_summary(name).items():
        table.add_row(k, str(v))
    Console().print(table)
