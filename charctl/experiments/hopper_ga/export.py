"""`charctl export RUN --bvh FILE --video FILE [--seconds S] [--fps F]`: the best genome's running motion."""

from __future__ import annotations

from pathlib import Path

from charctl.errors import CharctlError
from charctl.experiments.hopper_ga.results import gait_summary, load_best, open_hopper_run, run_dirs


def export(target: str, options: dict, overrides: list[str]) -> None:
    """`--bvh FILE` / `--video FILE` of the best genome's running motion (`--seconds`, `--fps`)."""
    if not options.get("bvh") and not options.get("video"):
        raise CharctlError("say what to export: --bvh FILE.bvh and/or --video FILE.mp4")
    (run_dir,) = run_dirs([target], overrides)[-1:]
    export_run(run_dir, options, overrides)


def export_run(run_dir: Path, options: dict, overrides: list[str] | None = None) -> None:
    """Write the best genome's running motion as BVH and/or mp4."""
    from charctl.experiments.hopper_ga.motion import cycles_for, resample, run_motion, write_bvh, write_video

    run, s = open_hopper_run(run_dir, overrides)
    genome, _ = load_best(run_dir)
    seconds = float(options.get("seconds") or run.cfg.export.seconds)
    if seconds <= 0:
        raise CharctlError(f"--seconds must be positive, got {seconds}")
    fps = options.get("fps")
    if fps is not None and fps <= 0:
        raise CharctlError(f"--fps must be positive, got {fps}")
    if options.get("video"):
        from charctl.viz.video import check_can_render

        check_can_render()  # a machine that cannot render says so before the BVH is written
    motion = run_motion(genome, s, cycles_for(seconds, gait_summary(genome, s)["cycle_time_s"]))
    l = float(genome[0])
    if options.get("bvh"):
        bvh_fps = float(fps or run.cfg.export.fps)
        _, root, upper, legs = resample(motion, bvh_fps)
        path = write_bvh(options["bvh"], s, l, bvh_fps, root, upper, legs)
        print(f"wrote {path} ({root.shape[0]} frames at {bvh_fps:g} fps, {motion.t[-1]:.2f} s)")
    if options.get("video"):
        vid_fps = float(fps or run.cfg.export.video_fps)
        _, root, upper, legs = resample(motion, vid_fps)
        info = write_video(options["video"], s, l, vid_fps, root, upper, legs)
        print(f"wrote {options['video']} ({info['frames']} frames, {info['render_fps']:.1f} frames/s rendered)")
