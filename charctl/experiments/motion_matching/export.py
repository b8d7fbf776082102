"""`charctl export motion-matching|RUN path=star [case=best] --bvh F --video F [--seconds S] [--fps F]`:
one rollout along a target path, its errors and path plot in a new run directory, BVH / mp4."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.eval.report import write_json
from charctl.experiments.motion_matching.cases import describe, resolve_case
from charctl.experiments.motion_matching.config import NAME, load_config

FPS_USER_SKELETON = "--fps is not supported for a data.bvh_dir skeleton; the BVH is written at data.fps"


def export(target: str, options: dict, overrides: list[str]) -> None:
    """Run the config's path (`path=`, `case=`) and write metrics.json, root_path.csv, path.png and
    `--bvh` / `--video` of the generated motion."""
    from charctl.experiments.motion_matching.database import build_database
    from charctl.experiments.motion_matching.paths import make_path, path_errors
    from charctl.experiments.motion_matching.prechecks import check_exclusion
    from charctl.experiments.motion_matching.runtime import run_path
    from charctl.experiments.motion_matching.search import make_index
    from charctl.experiments.motion_matching.sources import load_sources
    from charctl.runs import new_run

    cfg = load_config([target], overrides)
    cfg, case = resolve_case(cfg)
    path = make_path(str(cfg.path), cfg.paths)
    seconds = options.get("seconds")
    _check_options(cfg, options, seconds)
    sources, info = load_sources(cfg)
    check_exclusion(cfg, sources)  # before the rollout (which could stop on it after running for a while)
    db = build_database(cfg, sources, info)
    index = make_index(cfg.runtime.index, db)
    tic = time.perf_counter()
    rollout = run_path(db, index, path, cfg, with_pose=True, seconds=seconds)
    gen_s = time.perf_counter() - tic
    err = path_errors(path, rollout.ground, cfg.paths.speed, 1.0 / db.fps)
    out = new_run(cfg, NAME).dir
    label = f"case {case}: {describe(case)}" if case else "features from the config"
    metrics = {
        "path": path.name,
        "case": case,
        "setting": label,
        **err,
        "frames": rollout.num_frames,
        "searches": rollout.searches,
        "jumps": rollout.jumps,
        "generate_seconds": gen_s,
        "realtime_factor": rollout.num_frames / db.fps / max(gen_s, 1e-9),
    }
    write_json(out / "metrics.json", metrics)
    _write_root_path(out / "root_path.csv", rollout, db.fps)
    _plot_path(out / "path.png", path, rollout, label, err)
    print(
        f"{path.name} ({label}): {rollout.num_frames} frames, "
        f"e_time {err['e_time_mean']:.3f} ± {err['e_time_std']:.3f} m, "
        f"e_near {err['e_near_mean']:.3f} ± {err['e_near_std']:.3f} m -> {out}"
    )
    _write_media(db, rollout, options)


def _check_options(cfg, options: dict, seconds: float | None) -> None:
    """Reject `--seconds` <= 0, `--video` with a user skeleton (data.bvh_dir) or on a machine that cannot
    render, and `--fps` for a user skeleton's BVH."""
    if seconds is not None and seconds <= 0:
        raise CharctlError(f"--seconds must be positive, got {seconds}")
    if options.get("video") and cfg.data.bvh_dir:
        raise CharctlError("--video needs the humanoid database; with data.bvh_dir export --bvh only")
    if options.get("bvh") and options.get("fps") is not None and cfg.data.bvh_dir:
        raise CharctlError(FPS_USER_SKELETON)
    if options.get("video"):
        from charctl.viz.video import check_can_render

        check_can_render()  # before the run directory and the BVH are written


def _write_root_path(file: Path, rollout, fps: float) -> None:
    """root_path.csv: time (s) and the ground-plane root position x, z (m) of every generated frame."""
    np.savetxt(
        file,
        np.column_stack([np.arange(rollout.num_frames) / fps, rollout.ground]),
        delimiter=",",
        header="t,x,z",
        comments="",
        fmt="%.5f",
    )


def _plot_path(file: Path, path, rollout, label: str, err: dict) -> None:
    """path.png: the target path and the generated root path, titled with their errors (m)."""
    from charctl.experiments.motion_matching.paths import draw_paths
    from charctl.viz.plots import new_figure, save_figure

    fig, ax = new_figure(figsize=(5, 5))
    draw_paths(ax, path, rollout.ground)
    ax.set_title(
        f"{path.name}, {label}\ne_time {err['e_time_mean']:.3f}±{err['e_time_std']:.3f} m, "
        f"e_near {err['e_near_mean']:.3f}±{err['e_near_std']:.3f} m",
        fontsize=8,
    )
    save_figure(fig, file)


def _write_media(db, rollout, options: dict) -> None:
    """`--bvh` and `--video` of the generated motion (the video at `--fps`, default 30)."""
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
        raise CharctlError(FPS_USER_SKELETON)
    local = rollout.pose.copy()
    local[:, 0] = rollout.root_rotation()
    root = np.column_stack([rollout.ground[:, 0], rollout.height, rollout.ground[:, 1]])
    return write_user_bvh(db.skeleton.bvh_template, root / db.skeleton.bvh_scale, local, path, db.fps)
