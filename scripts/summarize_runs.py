"""Markdown table of TensorBoard scalars of training runs at chosen sample counts (the docs' curve tables).

    .venv/bin/python scripts/summarize_runs.py RUN_DIR... [--tags train/episode_length,train/r_style]
        [--at 0.25e6,0.5e6,1e6,2e6] [--window 3]

One row per (run, tag); each cell is the mean of the `--window` logged iterations nearest to that
sample count (the x axis of charctl's scalars is the sample count), "—" past the end of the run.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from charctl.eval.tb import read_scalars


def value_at(steps: np.ndarray, values: np.ndarray, at: float, window: int) -> float | None:
    """Mean of the `window` points whose step is nearest to `at`; None when `at` lies past the last step."""
    if len(steps) == 0 or at > steps[-1] * 1.02:
        return None
    nearest = np.argsort(np.abs(steps - at))[:window]
    return float(np.mean(values[nearest]))


def summarize(runs: list[Path], tags: list[str], points: list[float], window: int) -> str:
    """The markdown table: | run | tag | value at each point |."""
    head = "| run | scalar | " + " | ".join(f"{p / 1e6:g}M" for p in points) + " |"
    lines = [head, "|---|---|" + "---:|" * len(points)]
    for run in runs:
        scalars = read_scalars(run / "tb")
        for tag in tags:
            if tag not in scalars:
                continue
            steps, values = (np.asarray(a, dtype=float) for a in scalars[tag])
            cells = [value_at(steps, values, p, window) for p in points]
            text = ["—" if c is None else f"{c:.3g}" for c in cells]
            lines.append(f"| {run.name} | {tag} | " + " | ".join(text) + " |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--tags", default="train/episode_length,train/r_style,train/class_acc_policy")
    ap.add_argument("--at", default="0.25e6,0.5e6,1e6,2e6,4e6,8e6")
    ap.add_argument("--window", type=int, default=3)
    a = ap.parse_args()
    missing = [str(r) for r in a.runs if not (r / "tb").is_dir()]
    if missing:
        raise SystemExit(f"error: no TensorBoard folder (RUN/tb) in {', '.join(missing)}")
    points = [float(x) for x in a.at.split(",")]
    print(summarize(a.runs, a.tags.split(","), points, a.window))


if __name__ == "__main__":
    main()
