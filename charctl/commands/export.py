"""`charctl export bvh|video CLIP -o FILE` and `charctl export RUN_DIR|EXPERIMENT ...`; `charctl play`."""

from __future__ import annotations

from pathlib import Path

from charctl.errors import CharctlError


def export_command(target: str, args: list[str], options: dict) -> None:
    if target in ("bvh", "video"):
        return export_clip(target, args, options)
    from charctl.experiments import EXPERIMENTS, entry
    from charctl.runs import run_experiment

    if target in EXPERIMENTS:
        experiment = target
    elif Path(target).is_dir():
        experiment = run_experiment(target)
    else:
        raise CharctlError(f"{target!r} is not 'bvh', 'video', a run directory or an experiment ({', '.join(sorted(EXPERIMENTS))})")
    overrides = [a for a in args if "=" in a]
    stray = [a for a in args if "=" not in a]
    if stray:
        raise CharctlError(f"unexpected argument(s) {' '.join(stray)}; overrides look like key=value")
    entry(experiment, "export")(target, options, overrides)


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
        print(f"wrote {path} ({clip.num_frames} frames)")
    else:
        from charctl.viz.video import render_clip

        info = render_clip(clip, out, fps=options.get("fps"))
        print(f"wrote {out} ({info['frames']} frames, {info['render_fps']:.0f} frames/s rendered)")


def play_command(run_dir: Path | None) -> None:
    from charctl.experiments import entry
    from charctl.runs import latest_run, run_experiment

    run_dir = run_dir or latest_run("outputs", "cgail")
    entry(run_experiment(run_dir), "play")(run_dir)
