"""`charctl` command line. Thin: parse, then hand over to charctl.commands / the experiments.

Heavy imports (torch, mujoco, hydra) happen inside the commands so `charctl --help` is fast.
Overrides (`key=value`, Hydra syntax) follow the positional arguments of train/eval/export.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import List, Optional, Tuple

import typer

from charctl.errors import CharctlError

app = typer.Typer(
    name="charctl",
    help="Train and evaluate character-animation research systems: cgail, srb, com-cnn, motion-matching, hopper-ga.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)
data_app = typer.Typer(help="Inspect the motion clips (DeepMimic clips shipped in pybullet).", no_args_is_help=True)
app.add_typer(data_app, name="data")

OverridesArg = typer.Argument(None, help="Hydra overrides, e.g. scale=smoke ppo.lr=1e-4", show_default=False)


# ---------------------------------------------------------------------------- data
@data_app.command("list")
def data_list() -> None:
    """List every clip: frames, fps, duration, loop, class label."""
    from charctl.commands.data import list_clips

    list_clips()


@data_app.command("show")
def data_show(clip: str = typer.Argument(..., help="clip name (see `charctl data list`), file path, optional ':mirror'")) -> None:
    """Facts about one clip, with root travel, mean speed and COM height range."""
    from charctl.commands.data import show_clip

    show_clip(clip)


# ---------------------------------------------------------------------------- train
@app.command()
def train(
    experiment: str = typer.Argument(..., help="cgail | srb | com-cnn | motion-matching | hopper-ga"),
    overrides: Optional[List[str]] = OverridesArg,
    resume: Optional[Path] = typer.Option(None, "--resume", help="continue this run directory from its last checkpoint"),
    multirun: bool = typer.Option(False, "-m", "--multirun", help="sweep: a=1,2 b=x,y runs every combination in turn"),
) -> None:
    """Train an experiment: `charctl train cgail scale=smoke ppo.lr=1e-4`."""
    from charctl.commands.train import train_command

    train_command(experiment, list(overrides or []), resume=resume, multirun=multirun)


# ---------------------------------------------------------------------------- eval
@app.command("eval")
def evaluate(
    targets: Optional[List[str]] = typer.Argument(None, help="run directories, an experiment name, and/or key=value overrides", show_default=False),
    dtw: bool = typer.Option(False, "--dtw", help="DTW pose error against the reference clips (Table 6.1)"),
    confusion: bool = typer.Option(False, "--confusion", help="classifier confusion matrix (Fig 6.8)"),
    switch: Optional[Tuple[str, str]] = typer.Option(None, "--switch", help="command switch study A -> B (Fig 6.10/6.11)", show_default=False),
    curves: bool = typer.Option(False, "--curves", help="training-curve figures from TensorBoard logs"),
    pose_error: bool = typer.Option(False, "--pose-error", help="com-cnn: teacher-forced and autoregressive joint-angle error"),
    push: bool = typer.Option(False, "--push", help="srb: push-robustness study"),
    sweep: bool = typer.Option(False, "--sweep", help="motion-matching: the Table 1 feature sweep"),
    episodes: Optional[int] = typer.Option(None, "--episodes", "-k", help="episodes/trials per case"),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="folder for tables and figures (default: inside the run)"),
) -> None:
    """Evaluate runs. No run directory = the latest cgail run in outputs/."""
    from charctl.commands.evaluate import eval_command

    options = {"dtw": dtw, "confusion": confusion, "switch": switch, "curves": curves, "pose_error": pose_error,
               "push": push, "sweep": sweep, "episodes": episodes, "out": out}
    eval_command(list(targets or []), options)


# ---------------------------------------------------------------------------- export
@app.command()
def export(
    target: str = typer.Argument(..., help="'bvh' or 'video' (a clip), or a run directory / experiment name"),
    args: Optional[List[str]] = typer.Argument(None, help="the clip (for bvh/video), then key=value overrides", show_default=False),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="output file (clip export)"),
    fps: Optional[float] = typer.Option(None, "--fps", help="resample to this frame rate"),
    bvh: Optional[Path] = typer.Option(None, "--bvh", help="write a BVH of the policy/generated motion"),
    video: Optional[Path] = typer.Option(None, "--video", help="write an mp4 of the policy/generated motion"),
    onnx: Optional[Path] = typer.Option(None, "--onnx", help="export the policy (normaliser built in) as ONNX"),
    torchscript: Optional[Path] = typer.Option(None, "--torchscript", help="export the policy as TorchScript"),
    commands: Optional[str] = typer.Option(None, "--commands", help='command schedule, e.g. "walk:0,run:3,kick:6" (seconds)'),
    com_path: Optional[str] = typer.Option(None, "--com-path", help="com-cnn: CSV file or circle:r=2,speed=1.2"),
    crouch_at: Optional[float] = typer.Option(None, "--crouch-at", help="com-cnn: lower the COM from this time (s)"),
    seconds: Optional[float] = typer.Option(None, "--seconds", help="length of a generated rollout"),
) -> None:
    """Export clips (`export bvh walk -o walk.bvh`) or trained runs (`export RUN --onnx policy.onnx`)."""
    from charctl.commands.export import export_command

    options = {"output": output, "fps": fps, "bvh": bvh, "video": video, "onnx": onnx, "torchscript": torchscript,
               "commands": commands, "com_path": com_path, "crouch_at": crouch_at, "seconds": seconds}
    export_command(target, list(args or []), options)


# ---------------------------------------------------------------------------- play / config
@app.command()
def play(run_dir: Optional[Path] = typer.Argument(None, help="cgail run directory (default: latest)")) -> None:
    """Interactive command switching in a MuJoCo viewer (needs a display)."""
    from charctl.commands.export import play_command

    play_command(run_dir)


@app.command("config")
def show_config(
    experiment: str = typer.Argument(..., help="experiment name"),
    overrides: Optional[List[str]] = OverridesArg,
) -> None:
    """Print the resolved, validated config of an experiment."""
    from charctl.commands.train import print_config

    print_config(experiment, list(overrides or []))


def main() -> None:
    """Console entry point: CharctlError -> one line on stderr, exit code 2; never a traceback."""
    try:
        app(standalone_mode=False)
    except CharctlError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        sys.exit(130)
    except SystemExit:
        raise
    except Exception as exc:  # click usage errors and friends (typer >= 0.16 vendors click as typer._click)
        name = type(exc).__name__
        if name == "NoArgsIsHelpError":  # bare `charctl` / `charctl data`: show the help
            ctx = getattr(exc, "ctx", None)
            print(ctx.get_help() if ctx is not None else exc)
            sys.exit(0)
        if name == "Abort":
            print("aborted", file=sys.stderr)
            sys.exit(130)
        if hasattr(exc, "format_message") and hasattr(exc, "exit_code"):  # click.ClickException or typer's copy
            print(f"error: {exc.format_message()}", file=sys.stderr)
            sys.exit(exc.exit_code)
        raise


if __name__ == "__main__":
    main()
