"""`charctl train EXPERIMENT [overrides] [--resume RUN] [-m]` and `charctl config`."""

from __future__ import annotations

from pathlib import Path

from charctl.errors import CharctlError


def _schema(experiment: str) -> type:
    from charctl.experiments import load

    return load(experiment).config_class()


def train_command(
    experiment: str, overrides: list[str], resume: Path | None = None, multirun: bool = False
) -> list[Path]:
    """Compose/validate the config, create (or reopen) the run directory, hand over to the experiment."""
    from charctl.config import check_experiment, compose_config, expand_multirun
    from charctl.experiments import load
    from charctl.runs import new_run, open_run, run_experiment

    check_experiment(experiment)
    train_fn = load(experiment).entry("train")
    schema = _schema(experiment)
    if resume is not None:
        if multirun:
            raise CharctlError("--resume and --multirun cannot be combined")
        found = run_experiment(resume)
        if found != experiment:
            raise CharctlError(f"{resume} is a {found!r} run, not {experiment!r}")
        run = open_run(resume, schema, overrides)
        if not run.has_checkpoint():
            raise CharctlError(f"{resume} has no checkpoint to resume from (checkpoints/last.pt)")
        print(f"resuming {run.dir}")
        _run(train_fn, run)
        return [run.dir]
    jobs = expand_multirun(overrides) if multirun else [overrides]
    cfgs = [compose_config(experiment, job, schema) for job in jobs]  # validate every job before starting any
    dirs = []
    for i, (job, cfg) in enumerate(zip(jobs, cfgs)):
        if multirun:
            print(f"[{i + 1}/{len(jobs)}] {experiment} {' '.join(job)}")
        run = new_run(cfg, experiment)
        print(f"run directory: {run.dir}")
        _run(train_fn, run)
        dirs.append(run.dir)
    return dirs


def _run(train_fn, run) -> None:
    from charctl.runs import capture_mujoco_log, stop_signal

    capture_mujoco_log(run.dir)  # MuJoCo warnings go to <run>/mujoco.log, not ./MUJOCO_LOG.TXT
    try:
        metrics = train_fn(run.cfg, run)
    finally:
        run.close()
        _report_mujoco_warnings(run)
    if stop_signal() is not None:  # a loop that broke out on Ctrl-C / SIGTERM and returned: still an interruption
        from charctl.errors import Interrupted

        raise Interrupted(
            f"interrupted: checkpoint written to {run.checkpoint_path}; continue with --resume {run.dir}",
            signum=stop_signal(),
        )
    if metrics:
        summary = ", ".join(
            f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
            for k, v in list(metrics.items())[:8]
            if not isinstance(v, (dict, list))
        )
        print(f"done: {summary}")


def _report_mujoco_warnings(run) -> None:
    from charctl.runs import MUJOCO_LOG, count_mujoco_warnings

    n = count_mujoco_warnings(run.dir)
    if n:
        print(
            f"note: MuJoCo reported {n} simulator warning(s) (unstable states, reset and counted); "
            f"see {run.dir / MUJOCO_LOG}"
        )


def print_config(experiment: str, overrides: list[str]) -> None:
    from charctl.config import compose_config, to_yaml

    print(to_yaml(compose_config(experiment, overrides, _schema(experiment))), end="")
