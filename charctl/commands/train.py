"""`charctl train EXPERIMENT [overrides] [--resume RUN] [-m]` and `charctl config`."""

from __future__ import annotations

from pathlib import Path

from charctl.errors import CharctlError


def _schema(experiment: str) -> type:
    from charctl.experiments import load

    return load(experiment).config_class()


LAUNCHERS = ("basic", "ray")


def train_command(
    experiment: str,
    overrides: list[str],
    resume: Path | None = None,
    multirun: bool = False,
    launcher: str = "basic",
    address: str | None = None,
    cpus_per_job: float = 1.0,
    gpus_per_job: float = 0.0,
) -> list[Path]:
    """Compose/validate the config, run the experiment's `preflight` on it (every job of a sweep before the
    first run directory), create (or reopen) the run directory, hand over to the experiment.

    `launcher="ray"` runs the job(s) - every combination of a `-m` sweep - side by side on Ray
    (charctl.launch.ray_jobs) instead of one after another in this process."""
    from charctl.config import check_experiment, compose_config, expand_multirun
    from charctl.experiments import load
    from charctl.runs import new_run, open_run, run_experiment

    check_experiment(experiment)
    _check_launcher(launcher, address, resume, (cpus_per_job, gpus_per_job) != (1.0, 0.0))
    if launcher == "ray":
        # every job is `charctl train` in a child process: its preflight runs there, before its run directory
        return _train_on_ray(experiment, overrides, multirun, address, cpus_per_job, gpus_per_job)
    exp = load(experiment)
    train_fn = exp.entry("train")
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
        exp.preflight_check(run.cfg)  # before anything is written to the run
        run.resume_overrides = list(overrides)  # into config.yaml once the checkpoint loads (Run.load_checkpoint)
        print(f"resuming {run.dir}")
        _run(train_fn, run)
        return [run.dir]
    jobs = expand_multirun(overrides) if multirun else [overrides]
    cfgs = [compose_config(experiment, job, schema) for job in jobs]  # validate every job before starting any
    for cfg in cfgs:  # and check it against its data (the schema cannot see that)
        exp.preflight_check(cfg)
    dirs = []
    for i, (job, cfg) in enumerate(zip(jobs, cfgs)):
        if multirun:
            print(f"[{i + 1}/{len(jobs)}] {experiment} {' '.join(job)}")
        run = new_run(cfg, experiment)
        print(f"run directory: {run.dir}")
        _run(train_fn, run)
        dirs.append(run.dir)
    return dirs


def _check_launcher(launcher: str, address: str | None, resume: Path | None, resources: bool = False) -> None:
    """One-line errors for options that do not go together (`resources`: --cpus/--gpus-per-job given)."""
    if launcher not in LAUNCHERS:
        raise CharctlError(f"unknown launcher {launcher!r}; choose one of: {', '.join(LAUNCHERS)}")
    if address and launcher != "ray":
        raise CharctlError("--address needs --launcher ray")
    if resources and launcher != "ray":
        raise CharctlError("--cpus-per-job / --gpus-per-job need --launcher ray")
    if resume is not None and launcher != "basic":
        raise CharctlError("--resume runs in this process; drop --launcher ray")


def _train_on_ray(
    experiment: str, overrides: list[str], multirun: bool, address: str | None, cpus: float, gpus: float
) -> list[Path]:
    """Every job on Ray; the run directories of the finished ones, or a one-line error if any failed."""
    from charctl.config import expand_multirun
    from charctl.launch.ray_jobs import Resources, run_on_ray, summary_error

    jobs = expand_multirun(overrides) if multirun else [overrides]
    results = run_on_ray(experiment, jobs, address=address or None, resources=Resources(cpus, gpus))
    error = summary_error(results)
    if error is not None:
        raise error
    return [Path(r.run_dir) for r in results]


def _run(train_fn, run) -> None:
    from charctl.mujoco_log import capture_mujoco_log
    from charctl.signals import stop_signal

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
    from charctl.mujoco_log import MUJOCO_LOG, count_mujoco_warnings

    n = count_mujoco_warnings(run.dir)
    if n:
        print(
            f"note: MuJoCo reported {n} simulator warning(s) (unstable states, reset and counted); "
            f"see {run.dir / MUJOCO_LOG}"
        )


def explain_config(experiment: str, key: str, overrides: list[str]) -> None:
    from charctl.config import check_experiment
    from charctl.config_help import explain

    check_experiment(experiment)
    print(explain(experiment, key, overrides, _schema(experiment)))


def print_config(experiment: str, overrides: list[str]) -> None:
    from charctl.config import compose_config, to_yaml

    print(to_yaml(compose_config(experiment, overrides, _schema(experiment))), end="")
