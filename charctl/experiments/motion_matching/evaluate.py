"""`charctl eval motion-matching --sweep [-o DIR]`: the paper's Table 1 feature study (the cases
of cases.py x the target paths, errors pooled over start phases, tables and plots). The reproduction
report of a sweep folder is report.py."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from charctl.errors import CharctlError
from charctl.eval.report import markdown_grid, write_json
from charctl.experiments.motion_matching.cases import TABLE1, describe, with_case
from charctl.experiments.motion_matching.config import NAME, load_config

if TYPE_CHECKING:
    from charctl.experiments.motion_matching.sources import SkeletonInfo, SourceMotion


# ---------------------------------------------------------------------------- eval --sweep
def evaluate(targets: list[str], options: dict, overrides: list[str]) -> None:
    """`--sweep [-o DIR]`: the Table 1 feature study -> sweep.json, sweep.md, plots, metrics.json."""
    from charctl.experiments.motion_matching.sources import load_sources
    from charctl.progress import TrainingProgress

    if not options.get("sweep"):
        raise CharctlError("motion-matching evaluates with --sweep (the Table 1 feature study)")
    cfg = load_config(targets, overrides)
    # every case, path and source (data.bvh_dir or data.clips), and each case's database size and exclusion
    # window, checked before the output folder is made
    cases, paths = sweep_plan(cfg)
    sources = load_sources(cfg)
    check_databases(cfg, cases, sources[0])
    out = output_dir(cfg, options.get("out"))
    with TrainingProgress(len(cases), "Table 1 sweep", unit="cases") as bar:
        payload = run_sweep(
            cfg, out, progress=lambda case: bar.update(1, case=case), plan=(cases, paths), sources=sources
        )
    write_json(out / "metrics.json", {k: v for k, v in payload.items() if k != "cases"})
    print((out / "sweep.md").read_text())
    print(
        f"sweep: {out / 'sweep.md'}, {out / 'sweep.json'}" + (f", plots in {out / 'plots'}" if cfg.sweep.plots else "")
    )


def output_dir(cfg, out: str | Path | None) -> Path:
    """--out if given, else a new run directory outputs/motion-matching/<timestamp>/."""
    if out is not None:
        path = Path(out)
        path.mkdir(parents=True, exist_ok=True)
        from charctl.config import to_yaml
        from charctl.files import atomic_write_text

        atomic_write_text(path / "config.yaml", to_yaml(cfg))
        return path
    from charctl.runs import new_run

    return new_run(cfg, NAME).dir


# ---------------------------------------------------------------------------- running the sweep
def sweep_plan(cfg) -> tuple[list[int], dict]:
    """(the Table 1 cases of cfg.sweep, its target paths by name); an unknown case or path, or a case whose
    feature offsets round to 0 frames at data.fps, is a one-line error."""
    from charctl.experiments.motion_matching.database import feature_offsets
    from charctl.experiments.motion_matching.paths import make_path

    cases = list(cfg.sweep.cases) or sorted(TABLE1)
    bad = [c for c in cases if c not in TABLE1]
    if bad:
        raise CharctlError(f"sweep.cases: {bad[0]} is not a Table 1 case (1..19)")
    for case in cases:
        feature_offsets(with_case(cfg, case))
    return cases, {p: make_path(p, cfg.paths) for p in cfg.sweep.paths}


def check_databases(cfg, cases: list[int], sources: list[SourceMotion]) -> None:
    """Each case's database (built from `sources`) would have at least 2 searchable frames and leave a frame
    outside runtime.exclude_window for every search; the first case that would not is build_database's or
    search's one-line error, given here before anything is built or written."""
    from charctl.experiments.motion_matching.prechecks import check_exclusion, check_searchable

    for case in cases:
        ccfg = with_case(cfg, case)
        check_searchable(ccfg, sources)
        check_exclusion(ccfg, sources)


def run_sweep(
    cfg,
    out_dir: Path,
    progress=None,
    plan: tuple[list[int], dict] | None = None,
    sources: tuple[list[SourceMotion], SkeletonInfo] | None = None,
) -> dict:
    """Run the cases of cfg.sweep on its paths (`plan`: `sweep_plan(cfg)`, `sources`: `load_sources(cfg)`
    when already made); write sweep.json, sweep.md and PNG plots to out_dir."""
    from charctl.experiments.motion_matching.database import build_database
    from charctl.experiments.motion_matching.runtime import run_path
    from charctl.experiments.motion_matching.search import make_index
    from charctl.experiments.motion_matching.sources import load_sources

    cases, paths = plan or sweep_plan(cfg)
    starts = int(cfg.sweep.starts)
    tic = time.perf_counter()
    sources, info = sources or load_sources(cfg)
    results: dict[int, dict] = {}
    rollouts: dict[int, dict] = {}
    for case in cases:
        ccfg = with_case(cfg, case)
        db = build_database(ccfg, sources, info)
        index = make_index(ccfg.runtime.index, db)
        results[case] = {"description": describe(case), "paths": {}}
        rollouts[case] = {}
        for name, path in paths.items():
            runs = [run_path(db, index, path, ccfg, with_pose=False, start_shift=k / starts) for k in range(starts)]
            err = pooled_errors(path, [r.ground for r in runs], ccfg.paths.speed, 1.0 / db.fps)
            results[case]["paths"][name] = {
                **err,
                "frames": sum(r.num_frames for r in runs),
                "searches": sum(r.searches for r in runs),
                "jumps": sum(r.jumps for r in runs),
            }
            rollouts[case][name] = runs[0].ground
        if progress is not None:
            progress(case)
    elapsed = time.perf_counter() - tic
    summary = summarise(results)
    out_dir.mkdir(parents=True, exist_ok=True)
    payload = {
        "cases": results,
        **summary,
        "seconds": elapsed,
        "database_frames": int(db.num_searchable),
        "database_fps": float(db.fps),
        "paths": list(paths),
        "speed": float(cfg.paths.speed),
        "starts": starts,
    }
    payload = json.loads(json.dumps(payload))  # one form (string keys) for the file and the table
    write_json(out_dir / "sweep.json", payload)
    (out_dir / "sweep.md").write_text(sweep_markdown(payload))
    if cfg.sweep.plots:
        plot_sweep(paths, rollouts, results, summary["best_case"], out_dir, starts)
    return payload


def pooled_errors(path, grounds: list[np.ndarray], speed: float, dt: float) -> dict[str, float]:
    """Mean/std of e_time and e_near over the frames of all rollouts together."""
    from charctl.experiments.motion_matching.paths import frame_errors

    per = [frame_errors(path, g, speed, dt) for g in grounds]
    out = {}
    for k in ("e_time", "e_near"):
        v = np.concatenate([p[k] for p in per])
        out[f"{k}_mean"], out[f"{k}_std"] = float(v.mean()), float(v.std())
    return out


def summarise(results: dict[int, dict]) -> dict:
    """Best case overall (lowest mean over paths of e_time_mean) and per path, for both metrics."""
    cases = sorted(results)
    paths = list(results[cases[0]]["paths"])
    out = {}
    for metric in ("e_time", "e_near"):
        avg = {c: float(np.mean([results[c]["paths"][p][f"{metric}_mean"] for p in paths])) for c in cases}
        out[f"best_case_{metric}"] = min(avg, key=avg.get)
        out[f"avg_{metric}"] = avg
        out[f"best_per_path_{metric}"] = {
            p: min(cases, key=lambda c: results[c]["paths"][p][f"{metric}_mean"]) for p in paths
        }
    out["best_case"] = out["best_case_e_time"]
    return out


def sweep_markdown(payload: dict) -> str:
    """Two tables (e_time, e_near): mean ± std per path, best per column in bold, best row starred."""
    results = payload["cases"]
    cases = sorted(results, key=int)
    paths = payload["paths"]
    lines = [
        f"Database: {payload['database_frames']} searchable frames at {payload['database_fps']:.0f} Hz; "
        f"target speed {payload['speed']:g} m/s; each path run from {payload['starts']} starting gait phase(s), "
        f"mean ± std over all their frames; {payload['seconds']:.1f} s for the whole sweep.",
        "",
    ]
    titles = {
        "e_time": "e_time — distance to the target point at the same time (m)",
        "e_near": "e_near — distance to the nearest point of the path (m)",
    }
    for metric in ("e_time", "e_near"):
        best_row = str(payload[f"best_case_{metric}"])
        best_col = {p: str(c) for p, c in payload[f"best_per_path_{metric}"].items()}
        rows = [_sweep_row(payload, metric, c, best_row, best_col) for c in cases]
        table = markdown_grid(["case", "features", *paths, "mean"], rows, align="r-" + "r" * (len(paths) + 1))
        lines += [f"**{titles[metric]}**", "", *table.split("\n")]
        lines += ["", f"★ best row (lowest mean over the paths): case {best_row}; bold: best per path.", ""]
    return "\n".join(lines)


def _sweep_row(payload: dict, metric: str, c: str, best_row: str, best_col: dict[str, str]) -> list[str]:
    """Case `c`'s row of `sweep_markdown`'s `metric` table: the case (★ on the best row), its features,
    mean ± std per path (bold: the path's best case), and the mean over the paths."""
    results = payload["cases"]
    cells = []
    for p in payload["paths"]:
        r = results[c]["paths"][p]
        cell = f"{r[f'{metric}_mean']:.3f} ± {r[f'{metric}_std']:.3f}"
        cells.append(f"**{cell}**" if best_col[p] == str(c) else cell)
    mark = " ★" if str(c) == best_row else ""
    return [f"{c}{mark}", results[c]["description"], *cells, f"{payload[f'avg_{metric}'][c]:.3f}"]


def plot_sweep(paths: dict, rollouts: dict, results: dict, best: int, out_dir: Path, starts: int = 1) -> None:
    """One PNG per case (generated vs target, one panel per path) and best.png."""
    from charctl.experiments.motion_matching.paths import draw_paths
    from charctl.viz.plots import new_figure, save_figure

    for case, by_path in rollouts.items():
        fig, axes = new_figure(1, len(paths), figsize=(4.2 * len(paths), 4.2))
        axes = np.atleast_1d(axes)
        for ax, (name, path) in zip(axes, paths.items()):
            draw_paths(ax, path, by_path[name])
            r = results[case]["paths"][name]
            ax.set_title(f"{name}: e_time {r['e_time_mean']:.2f}±{r['e_time_std']:.2f} m", fontsize=9)
        note = f" — first of {starts} starts shown, errors pooled over all" if starts > 1 else ""
        fig.suptitle(
            f"case {case}: {results[case]['description']}" + (" (best)" if case == best else "") + note, fontsize=10
        )
        save_figure(fig, out_dir / "plots" / f"case_{case:02d}.png", dpi=90)
        if case == best:
            import shutil

            shutil.copyfile(out_dir / "plots" / f"case_{case:02d}.png", out_dir / "best.png")
