"""`charctl` command line. Thin: parse, then hand over to charctl.commands / the experiments.

Heavy imports (torch, mujoco, hydra) happen inside the commands so `charctl --help` is fast.
Overrides (`key=value`, Hydra syntax) follow the positional arguments of train/eval/export.
"""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from charctl.commands.dispatch import EvalGroup, ExportGroup, clip_export
from charctl.errors import CharctlError
from charctl.experiments import EXPERIMENTS

app = typer.Typer(
    name="charctl",
    help=f"Train and evaluate character-animation research systems: {', '.join(EXPERIMENTS)}.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)
data_app = typer.Typer(
    help="Inspect the motion clips (DeepMimic clips shipped in pybullet) and import your own mocap files.",
    no_args_is_help=True,
)
app.add_typer(data_app, name="data")

OverridesArg = typer.Argument(None, help="Hydra overrides, e.g. scale=smoke ppo.lr=1e-4", show_default=False)
AddressOpt = typer.Option(
    None,
    "--address",
    help="Ray cluster address (auto, HOST:PORT, ray://HOST:10001); none: a local Ray",
    show_default=False,
)


# ---------------------------------------------------------------------------- data
@data_app.command("list")
def data_list() -> None:
    """List every clip: frames, fps, duration, loop, class label."""
    from charctl.commands.data import list_clips

    list_clips()


@data_app.command("show")
def data_show(
    clip: str = typer.Argument(..., help="clip name (see `charctl data list`), file path, optional ':mirror'"),
) -> None:
    """Facts about one clip, with root travel, mean speed and COM height range."""
    from charctl.commands.data import show_clip

    show_clip(clip)


@data_app.command("import")
def data_import(
    file: Path = typer.Argument(..., help="a BVH motion-capture file of any skeleton"),
    skeleton: str | None = typer.Option(
        None,
        "--skeleton",
        help="joint map: cmu|mixamo|lafan1|biovision|neuron|unity|daz|smpl|charctl or MAP.yaml (default: detected)",
    ),
    name: str | None = typer.Option(None, "--name", help="clip name (default: the file's stem)"),
    output: Path | None = typer.Option(None, "-o", "--output", help="clip file to write (default imported/NAME.txt)"),
    fps: float | None = typer.Option(None, "--fps", help="frame rate of the clip (default 60)"),
    up: str | None = typer.Option(None, "--up", help="the file's up axis: y|z|x|-y|-z|-x (default: detected)"),
    units: str | None = typer.Option(None, "--units", help="m|cm|mm|in|cmu or metres per unit (default: detected)"),
    start: float | None = typer.Option(None, "--start", help="first second of the file to import"),
    stop: float | None = typer.Option(None, "--stop", help="last second of the file to import"),
    label: str | None = typer.Option(None, "--label", help="motion class label (default: the name)"),
    ground: bool = typer.Option(
        True, "--ground/--no-ground", help="plant the feet, fit the height, keep bodies above the ground"
    ),
    report: bool = typer.Option(True, "--report/--no-report", help="write NAME.report.md, filmstrip and quality JSON"),
    tracking: bool = typer.Option(True, "--tracking/--no-tracking", help="measure the PD tracking error (a few s)"),
) -> None:
    """Retarget a mocap file of any skeleton onto the humanoid: a clip every experiment takes, and its
    quality report (docs/motion_import.md)."""
    from charctl.commands.data import import_motion

    import_motion(file, skeleton, name, output, fps, up, units, start, stop, label, report, tracking, ground)


# ---------------------------------------------------------------------------- train
@app.command()
def train(
    experiment: str = typer.Argument(..., help=" | ".join(EXPERIMENTS)),
    overrides: list[str] | None = OverridesArg,
    resume: Path | None = typer.Option(None, "--resume", help="continue this run directory from its last checkpoint"),
    multirun: bool = typer.Option(False, "-m", "--multirun", help="sweep: a=1,2 b=x,y runs every combination in turn"),
    launcher: str = typer.Option(
        "basic", "--launcher", help="basic: jobs one after another here | ray: side by side on Ray (README)"
    ),
    address: str | None = AddressOpt,
    cpus_per_job: float = typer.Option(1.0, "--cpus-per-job", help="CPUs each job reserves on Ray"),
    gpus_per_job: float = typer.Option(0.0, "--gpus-per-job", help="GPUs each job reserves on Ray (fractions allowed)"),
) -> None:
    """Train an experiment: `charctl train EXPERIMENT scale=smoke ppo.lr=1e-4`."""
    from charctl.commands.train import train_command

    train_command(
        experiment,
        list(overrides or []),
        resume=resume,
        multirun=multirun,
        launcher=launcher,
        address=address,
        cpus_per_job=cpus_per_job,
        gpus_per_job=gpus_per_job,
    )


# ---------------------------------------------------------------------------- tune
@app.command()
def tune(
    experiment: str = typer.Argument(..., help=" | ".join(EXPERIMENTS)),
    overrides: list[str] | None = typer.Argument(
        None,
        help="key=choice(a,b) | key=range(lo,hi) | key=loguniform(lo,hi) are searched, other key=value are fixed",
        show_default=False,
    ),
    metric: str | None = typer.Option(
        None, "--metric", help="scalar to optimise (default: the experiment's first declared one)", show_default=False
    ),
    mode: str | None = typer.Option(
        None, "--mode", help="max | min (default: the declared direction of the metric)", show_default=False
    ),
    trials: int = typer.Option(8, "--trials", help="number of sampled configurations"),
    address: str | None = AddressOpt,
    cpus_per_trial: float = typer.Option(1.0, "--cpus-per-trial", help="CPUs each trial reserves"),
    gpus_per_trial: float = typer.Option(0.0, "--gpus-per-trial", help="GPUs each trial reserves"),
    grace_period: int = typer.Option(1, "--grace-period", help="ASHA: reports a trial makes before it can be stopped"),
    max_reports: int | None = typer.Option(
        None, "--max-reports", help="ASHA max_t: stop every trial after this many reports", show_default=False
    ),
    seed: int = typer.Option(0, "--search-seed", help="seed of the random search"),
) -> None:
    """Hyper-parameter search on Ray Tune with ASHA early stopping: `charctl tune EXP key=loguniform(1e-5,1e-3)`."""
    from charctl.commands.tune import TuneOptions, tune_command
    from charctl.launch.tune_setup import SearchSettings

    settings = SearchSettings(
        trials=trials,
        address=address,
        cpus=cpus_per_trial,
        gpus=gpus_per_trial,
        grace_period=grace_period,
        max_reports=max_reports,
        seed=seed,
    )
    tune_command(experiment, list(overrides or []), TuneOptions(metric=metric, mode=mode, settings=settings))


# ---------------------------------------------------------------------------- eval / export
# The first argument (an experiment name or a run directory) selects the experiment; the options are
# the ones that experiment declares (charctl.experiments), so `charctl eval NAME --help` lists only those.
eval_app = typer.Typer(
    cls=EvalGroup,
    help="Evaluate runs: `charctl eval EXPERIMENT|RUN_DIR ...` then more run directories, the experiment's "
    "options and key=value overrides; `charctl eval EXPERIMENT --help` lists that experiment's options.",
    no_args_is_help=True,
    subcommand_metavar="EXPERIMENT|RUN_DIR [ARGS]...",
)
app.add_typer(eval_app, name="eval")

export_app = typer.Typer(
    cls=ExportGroup,
    help="Export clips (`export bvh walk -o walk.bvh`) or trained runs (`export EXPERIMENT|RUN_DIR ...`); "
    "`charctl export EXPERIMENT --help` lists that experiment's options.",
    no_args_is_help=True,
    subcommand_metavar="bvh|video|EXPERIMENT|RUN_DIR [ARGS]...",
)
app.add_typer(export_app, name="export")

ClipArg = typer.Argument(
    None, help="clip name (see `charctl data list`), file path, optional ':mirror'", show_default=False
)
OutputOpt = typer.Option(None, "-o", "--output", help="output file", show_default=False)
FpsOpt = typer.Option(None, "--fps", help="resample to this frame rate", show_default=False)


@export_app.command("bvh")
def export_bvh(clip: str | None = ClipArg, output: Path | None = OutputOpt, fps: float | None = FpsOpt) -> None:
    """A clip as BVH: `charctl export bvh walk -o walk.bvh [--fps 60]`."""
    clip_export("bvh", clip, output, fps)


@export_app.command("video")
def export_video(clip: str | None = ClipArg, output: Path | None = OutputOpt, fps: float | None = FpsOpt) -> None:
    """A clip rendered to mp4: `charctl export video walk -o walk.mp4`."""
    clip_export("video", clip, output, fps)


# ---------------------------------------------------------------------------- play / config
@app.command()
def play(target: str = typer.Argument(..., help="run directory, or an experiment name for its latest run")) -> None:
    """Interactive viewer of a trained policy (needs a display), where the experiment has one."""
    from charctl.commands.export import play_command

    play_command(target)


@app.command("config")
def show_config(
    experiment: str = typer.Argument(..., help="experiment name"),
    overrides: list[str] | None = OverridesArg,
    explain: str | None = typer.Option(
        None,
        "--explain",
        help="KEY or section (e.g. reward): each knob's help, type, default, value and the layer that set it",
        show_default=False,
    ),
) -> None:
    """Print the resolved, validated config of an experiment (or, with --explain, what its knobs mean)."""
    from charctl.commands.train import explain_config, print_config

    if explain is not None:
        explain_config(experiment, explain, list(overrides or []))
    else:
        print_config(experiment, list(overrides or []))


_TERMINATED = []  # set by the SIGTERM handler: a KeyboardInterrupt that was really a SIGTERM


def _on_sigterm(signum, frame) -> None:  # noqa: ARG001
    _TERMINATED.append(signum)
    raise KeyboardInterrupt


def _os_error_line(exc: OSError) -> str:
    cause = exc.strerror or str(exc) or type(exc).__name__
    paths = [str(p) for p in (exc.filename, getattr(exc, "filename2", None)) if p]
    return f"{' -> '.join(paths)}: {cause}" if paths else cause


def main() -> None:
    """Console entry point: every failure is one line on stderr and an exit status, never a traceback.

    CharctlError -> "error: ..." and exit 2 (Diverged: 3); Interrupted (Ctrl-C / SIGTERM after the
    checkpoint was written) -> its "interrupted at ..." line and exit 130 / 143; Ctrl-C or SIGTERM
    outside a training loop -> 130 / 143; an OSError -> "error: PATH: cause", exit 2; click usage
    errors -> their code; `typer.Exit(code)` -> code.
    """
    import signal

    from charctl.errors import Interrupted

    try:
        old_term = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:  # not the main thread (tests calling main() from a worker)
        old_term = None
    try:
        rc = app(standalone_mode=False)
    except Interrupted as exc:
        for sig in (signal.SIGINT, signal.SIGTERM):  # a further Ctrl-C must not change the exit code
            signal.signal(sig, signal.SIG_IGN)
        print(str(exc), file=sys.stderr)
        sys.exit(exc.exit_code)
    except CharctlError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(exc.exit_code)
    except KeyboardInterrupt:
        _exit_interrupted()
    except SystemExit:
        raise
    except OSError as exc:  # a path that cannot be read or written, a full disk ...
        print(f"error: {_os_error_line(exc)}", file=sys.stderr)
        sys.exit(2)
    except Exception as exc:  # click usage errors and friends (typer >= 0.16 vendors click as typer._click)
        name = type(exc).__name__
        if name == "NoArgsIsHelpError":  # bare `charctl` / `charctl data`: show the help
            ctx = getattr(exc, "ctx", None)
            print(ctx.get_help() if ctx is not None else exc)
            sys.exit(0)
        if name == "Abort":  # click's form of a KeyboardInterrupt
            _exit_interrupted()
        if hasattr(exc, "format_message") and hasattr(exc, "exit_code"):  # click.ClickException or typer's copy
            print(f"error: {exc.format_message()}", file=sys.stderr)
            sys.exit(exc.exit_code)
        raise
    finally:
        if old_term is not None and signal.getsignal(signal.SIGTERM) is _on_sigterm:
            signal.signal(signal.SIGTERM, old_term)  # in-process callers (tests) get their handler back
    # standalone_mode=False makes click *return* the code of typer.Exit / click.exceptions.Exit
    sys.exit(rc if isinstance(rc, int) and not isinstance(rc, bool) else 0)


def _exit_interrupted() -> None:
    import signal

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    terminated = bool(_TERMINATED)
    print("terminated" if terminated else "interrupted", file=sys.stderr)
    sys.exit(128 + int(signal.SIGTERM if terminated else signal.SIGINT))


if __name__ == "__main__":
    main()
