"""`charctl export bvh|video CLIP -o FILE` and `charctl export RUN_DIR|EXPERIMENT ...`; `charctl play`."""

from __future__ import annotations

from pathlib import Path

from charctl.errors import CharctlError


def export_command(target: str, args: list[str], options: dict) -> None:
    from charctl.options import check_options

    check_options(options)  # numbers in range, every output writable: before any work or file
    if options.get("web"):  # a web demo's site folder: writable, not a file
        from charctl.paths import check_writable_dir

        check_writable_dir(Path(options["web"]), "--web folder")
    if target in ("bvh", "video"):
        return export_clip(target, args, options)
    from charctl.experiments import experiment_of, select_options

    exp = experiment_of(target)
    overrides = [a for a in args if "=" in a]
    stray = [a for a in args if "=" not in a]
    if stray:
        raise CharctlError(f"unexpected argument(s) {' '.join(stray)}; overrides look like key=value")
    exp.entry("export")(target, select_options(exp, "export", options), overrides)


def export_clip(kind: str, args: list[str], options: dict) -> None:
    from charctl.motion.library import load_clip

    if len(args) != 1:
        raise CharctlError(f"usage: charctl export {kind} CLIP -o FILE.{'bvh' if kind == 'bvh' else 'mp4'}")
    out = options.get("output")
    if out is None:
        raise CharctlError(f"give the output file with -o FILE.{'bvh' if kind == 'bvh' else 'mp4'}")
    clip = load_clip(args[0])
    if kind == "bvh":
        from charctl.motion.bvh import write_bvh

        path = write_bvh(clip, out, fps=options.get("fps"))
        frames, fps = _bvh_frames(path)
        print(f"wrote {path} ({frames} frames at {fps:.2f} fps, {(frames - 1) / fps:.2f} s)")
    else:
        from charctl.viz.video import render_clip

        info = render_clip(clip, out, fps=options.get("fps"))
        print(f"wrote {out} ({info['frames']} frames, {info['render_fps']:.0f} frames/s rendered)")


def _bvh_frames(path: Path) -> tuple[int, float]:
    """(frame count, frames per second) from a BVH file's MOTION header: what was really written."""
    frames, frame_time = 0, 0.0
    with open(path) as fh:
        for line in fh:
            if line.startswith("Frames:"):
                frames = int(line.split()[1])
            elif line.startswith("Frame Time:"):
                frame_time = float(line.split()[2])
                break
    return frames, 1.0 / frame_time if frame_time > 0 else 0.0


def play_command(target: str) -> None:
    """`charctl play EXPERIMENT|RUN_DIR`: the experiment's interactive viewer on a run (the name = its latest run)."""
    from charctl.experiments import experiment_of, latest_run_dir

    exp = experiment_of(target)
    play = exp.entry("play")
    play(latest_run_dir(exp.name) if target == exp.name else Path(target))
