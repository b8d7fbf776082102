"""`charctl export RUN --com-path FILE.csv|circle:r=2,speed=1.2 [--crouch-at T] --bvh OUT.bvh --video OUT.mp4`:
full-body motion generated from a user's COM path (generation itself: generate.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.experiments.com_cnn.checkpoint import load_run, resolve_targets
from charctl.experiments.com_cnn.generate import (
    frames_to_clip,
    generate_motion,
    plot_generation,
    render_with_com,
    write_generic_bvh,
)

VIDEO_NEEDS_HUMANOID = "--video renders the DeepMimic humanoid; this run was trained on data.bvh_dir (use --bvh)"


def export(target: str, options: dict, overrides: list[str]) -> None:
    """Generate from `--com-path` (default generate.com_path) and write `--bvh` / `--video`, the clamped
    input COM as CSV and a plot next to it."""
    run = load_run(resolve_targets([target], overrides)[0], overrides)
    if options.get("video") is not None:
        _check_video(run)  # before the CSV, plot and BVH beside it are written
    g, fps = run.cfg.generate, float(run.cfg.data.fps)
    spec = options.get("com_path") or str(g.com_path)
    out = generate_motion(run, spec, float(options.get("seconds") or g.seconds), options.get("crouch_at"))
    st = out["stats"]
    L, H = st["seed_frames"], st["frames"]
    print(
        f"generated {H} frames ({H / fps:.1f} s) after a {L}-frame seed ({st['seed_clip']}) in {st['wall_s']:.2f} s: "
        f"{st['frames_per_s']:.0f} frames/s = {st['real_time_factor']:.1f}x real time "
        f"(batch 1, {run.model.fc[0].weight.device}); "
        f"mean |body COM - input COM| = {st['com_tracking_error_m'] * 100:.1f} cm"
    )
    bvh, video = options.get("bvh"), options.get("video")
    if bvh is None and video is None:
        bvh = run.dir / "generated.bvh"
    side = str(Path(bvh or video).with_suffix(""))
    np.savetxt(side + "_com_path.csv", out["com_path"], delimiter=",", header="x,y,z", comments="", fmt="%.5f")
    plot_generation(out, fps, Path(side + "_plot.png"))
    frames = (out["root_pos"], out["root_rot"], out["joint_rot"])
    if bvh is not None:
        if run.body.kind == "humanoid":
            from charctl.motion.bvh import write_bvh

            write_bvh(frames_to_clip(run, "generated", *frames), bvh)
        else:
            write_generic_bvh(run.body, *frames, fps, Path(bvh))
        print(f"wrote {bvh} (frames 0-{L - 1}: seed from the data, {L}-{L + H - 1}: generated)")
    if video is not None:
        info = render_with_com(
            frames_to_clip(run, "generated", *frames), np.concatenate([out["seed"].com, out["com_path"]]), Path(video)
        )
        print(f"wrote {video} ({info['frames']} frames; purple ball = input COM, as in the paper's Fig. 1)")
    print(f"wrote {side}_com_path.csv (the clamped input COM) and {side}_plot.png")


def _check_video(run) -> None:
    """--video: a humanoid run (a data.bvh_dir skeleton is not rendered) on a machine that can render."""
    from charctl.viz.video import check_can_render

    if run.body.kind != "humanoid":
        raise CharctlError(VIDEO_NEEDS_HUMANOID)
    check_can_render()
