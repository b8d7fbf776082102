"""`charctl train|eval|export motion-matching`: config handling, artefacts, printing."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError

NAME = "motion-matching"


def load_config(targets: list[str], overrides: list[str]):
    """The config of a run directory (if one is given) or the composed experiment config."""
    from charctl.config import compose_config
    from charctl.experiments.motion_matching.config import Config
    from charctl.runs import open_run

    runs = [t for t in targets if t != NAME]
    if len(runs) > 1:
        raise CharctlError("motion-matching evaluates one run directory (or the experiment name) at a time")
    if runs:
        return open_run(runs[0], Config, overrides).cfg
    return compose_config(NAME, overrides, Config)


def output_dir(cfg, out: str | Path | None) -> Path:
    """--out if given, else a new run directory outputs/motion-matching/<timestamp>/."""
    if out is not None:
        path = Path(out)
        path.mkdir(parents=True, exist_ok=True)
        from charctl.config import to_yaml
        from charctl.runs import atomic_write_text

        atomic_write_text(path / "config.yaml", to_yaml(cfg))
        return path
    from charctl.runs import new_run

    return new_run(cfg, NAME).dir


# ---------------------------------------------------------------------------- train (optional)
def train(cfg, run) -> dict:
    """No learning: build the database, report its size and save it (database.npz) in the run."""
    from charctl.experiments.motion_matching.database import build_database
    from charctl.experiments.motion_matching.study import resolve_case

    cfg, case = resolve_case(cfg)
    tic = time.perf_counter()
    db = build_database(cfg)
    seconds = time.perf_counter() - tic
    np.savez_compressed(
        run.path("database.npz"), features=db.features[db.search_rows], frames=db.search_rows,
        clip_id=db.clip_id[db.search_rows], mean=db.layout.mean, scale=db.layout.scale, sqrt_w=db.layout.sqrt_w,
    )
    metrics = {
        "searchable_frames": int(db.num_searchable), "playback_frames": int(db.num_frames),
        "feature_dims": int(db.layout.dims), "fps": float(db.fps), "build_seconds": seconds,
        "blocks": {k: [v.start, v.stop] for k, v in db.layout.blocks.items()}, "clips": db.clip_names,
        "case": case,
    }
    run.write_metrics(metrics)
    print(f"database: {db.num_searchable} searchable frames ({db.num_frames} with the unrolled loops), "
          f"{db.layout.dims} features, {db.fps:.0f} Hz, built in {seconds:.2f} s -> {run.dir / 'database.npz'}")
    return {k: v for k, v in metrics.items() if not isinstance(v, (dict, list))}


# ---------------------------------------------------------------------------- eval --sweep
def evaluate(targets: list[str], options: dict, overrides: list[str]) -> None:
    from charctl.experiments import unsupported_options
    from charctl.experiments.motion_matching.study import TABLE1, run_sweep
    from charctl.progress import TrainingProgress

    unsupported_options(NAME, options, {"sweep", "out"})
    if not options.get("sweep"):
        raise CharctlError("motion-matching evaluates with --sweep (the Table 1 feature study)")
    cfg = load_config(targets, overrides)
    out = output_dir(cfg, options.get("out"))
    n = len(cfg.sweep.cases) or len(TABLE1)
    with TrainingProgress(n, "Table 1 sweep", unit="cases") as bar:
        payload = run_sweep(cfg, out, progress=lambda case: bar.update(1, case=case))
    (out / "metrics.json").write_text(json.dumps({k: v for k, v in payload.items() if k != "cases"}, indent=2))
    print((out / "sweep.md").read_text())
    print(f"sweep: {out / 'sweep.md'}, {out / 'sweep.json'}" + (f", plots in {out / 'plots'}" if cfg.sweep.plots else ""))


# ---------------------------------------------------------------------------- export
def export(target: str, options: dict, overrides: list[str]) -> None:
    from charctl.experiments import unsupported_options
    from charctl.experiments.motion_matching.database import build_database
    from charctl.experiments.motion_matching.paths import make_path, path_errors
    from charctl.experiments.motion_matching.runtime import run_path
    from charctl.experiments.motion_matching.search import make_index
    from charctl.experiments.motion_matching.study import describe, draw_paths, resolve_case

    unsupported_options(NAME, options, {"bvh", "video", "seconds", "fps"})
    cfg = load_config([target], overrides)
    cfg, case = resolve_case(cfg)
    path = make_path(str(cfg.path), cfg.paths)
    seconds = options.get("seconds")
    if seconds is not None and seconds <= 0:
        raise CharctlError(f"--seconds must be positive, got {seconds}")
    if options.get("video") and cfg.data.bvh_dir:
        raise CharctlError("--video needs the humanoid database; with data.bvh_dir export --bvh only")
    db = build_database(cfg)
    index = make_index(cfg.runtime.index, db)
    tic = time.perf_counter()
    rollout = run_path(db, index, path, cfg, with_pose=True, seconds=seconds)
    gen_s = time.perf_counter() - tic
    err = path_errors(path, rollout.ground, cfg.paths.speed, 1.0 / db.fps)
    out = output_dir(cfg, None)
    label = f"case {case}: {describe(case)}" if case else "features from the config"
    metrics = {"path": path.name, "case": case, "setting": label, **err, "frames": rollout.num_frames,
               "searches": rollout.searches, "jumps": rollout.jumps, "generate_seconds": gen_s,
               "realtime_factor": rollout.num_frames / db.fps / max(gen_s, 1e-9)}
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2))
    np.savetxt(out / "root_path.csv", np.column_stack([np.arange(rollout.num_frames) / db.fps, rollout.ground]),
               delimiter=",", header="t,x,z", comments="", fmt="%.5f")
    from charctl.viz.plots import new_figure, save_figure

    fig, ax = new_figure(figsize=(5, 5))
    draw_paths(ax, path, rollout.ground)
    ax.set_title(f"{path.name}, {label}\ne_time {err['e_time_mean']:.3f}±{err['e_time_std']:.3f} m, "
                 f"e_near {err['e_near_mean']:.3f}±{err['e_near_std']:.3f} m", fontsize=8)
    save_figure(fig, out / "path.png")
    print(f"{path.name} ({label}): {rollout.num_frames} frames, e_time {err['e_time_mean']:.3f} ± {err['e_time_std']:.3f} m, "
          f"e_near {err['e_near_mean']:.3f} ± {err['e_near_std']:.3f} m -> {out}")
    if options.get("bvh"):
        written = write_rollout_bvh(db, rollout, options["bvh"], options.get("fps"))
        print(f"wrote {written}")
    if options.get("video"):
        from charctl.viz.video import render_clip

        info = render_clip(rollout_clip(db, rollout), options["video"], fps=options.get("fps") or 30.0)
        print(f"wrote {options['video']} ({info['frames']} frames, {info['render_fps']:.0f} frames/s rendered)")


def rollout_clip(db, rollout):
    """The generated humanoid motion as a charctl Clip (root position/rotation in the world)."""
    from charctl.motion.clip import Clip

    if db.skeleton.kind != "humanoid":
        raise CharctlError("a charctl Clip needs the humanoid database (data.bvh_dir gives the user's skeleton)")
    local = rollout.pose.copy()
    local[:, 0] = rollout.root_rotation()
    root = np.column_stack([rollout.ground[:, 0], rollout.height, rollout.ground[:, 1]])
    return Clip(name="motion-matching", fps=db.fps, root_pos=root, local_rot=local)


def write_rollout_bvh(db, rollout, path, fps: float | None = None) -> Path:
    """BVH of the generated motion: charctl's humanoid writer, or the user's own skeleton."""
    if db.skeleton.kind == "humanoid":
        from charctl.motion.bvh import write_bvh

        return write_bvh(rollout_clip(db, rollout), path, fps=fps)
    from charctl.experiments.motion_matching.bvh_out import write_user_bvh

    if fps is not None:
        raise CharctlError("--fps is not supported for a data.bvh_dir skeleton; the BVH is written at data.fps")
    local = rollout.pose.copy()
    local[:, 0] = rollout.root_rotation()
    root = np.column_stack([rollout.ground[:, 0], rollout.height, rollout.ground[:, 1]])
    return write_user_bvh(db.skeleton.bvh_template, root / db.skeleton.bvh_scale, local, path, db.fps)
