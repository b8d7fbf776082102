"""`charctl tune EXP key=choice(a,b) key=range(lo,hi) key=loguniform(lo,hi) [key=value ...] --trials N`.

Everything that can be checked is checked before Ray starts: the search-space syntax, the metric
(declared by the experiment, or any logged scalar with an explicit --mode), the options, and the
config at every bound of every searched key (so an unknown key or an out-of-range bound is a
one-line error, not N failed trials). The search itself is charctl.launch.tune.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from charctl.errors import CharctlError
from charctl.launch.tune_setup import SearchSettings

MODES = ("max", "min")


@dataclass(frozen=True)
class TuneOptions:
    """The command-line options of `charctl tune`: the metric and the search's settings."""

    metric: str | None = None
    mode: str | None = None
    settings: SearchSettings = SearchSettings()


def resolve_metric(experiment: str, declared: dict[str, str], metric: str | None, mode: str | None) -> tuple[str, str]:
    """(metric, mode): the experiment's first declared metric by default; an undeclared one needs --mode."""
    if mode is not None and mode not in MODES:
        raise CharctlError(f"--mode must be max or min, got {mode!r}")
    if metric is None:
        if not declared:
            raise CharctlError(f"{experiment} declares no metric to tune; give --metric NAME --mode max|min")
        metric = next(iter(declared))
    if mode is None:
        if metric not in declared:
            names = ", ".join(declared) or "none"
            raise CharctlError(
                f"--metric {metric!r} is not one {experiment} declares ({names}); give --mode max|min with it"
            )
        mode = declared[metric]
    return metric, mode


def check_settings(settings: SearchSettings) -> None:
    """One-line errors for search settings out of range (before Ray starts)."""
    if settings.trials < 1:
        raise CharctlError(f"--trials must be >= 1, got {settings.trials}")
    if not settings.cpus > 0:
        raise CharctlError(f"--cpus-per-trial must be > 0, got {settings.cpus:g}")
    if settings.gpus < 0:
        raise CharctlError(f"--gpus-per-trial must be >= 0, got {settings.gpus:g}")
    if settings.grace_period < 1:
        raise CharctlError(f"--grace-period must be >= 1, got {settings.grace_period}")
    if settings.max_reports is not None and settings.max_reports < settings.grace_period:
        raise CharctlError(
            f"--max-reports must be >= --grace-period ({settings.grace_period}), got {settings.max_reports}"
        )


def validate_space(experiment: str, fixed: list[str], dims, schema: type):
    """Compose the config with every bound of every searched key; the fixed-overrides config."""
    from charctl.config import compose_config

    cfg = compose_config(experiment, fixed, schema)
    for dim in dims:
        for value in dim.extremes():
            try:
                compose_config(experiment, [*fixed, f"{dim.key}={value}"], schema)
            except CharctlError as exc:
                raise CharctlError(f"{dim.key}={value} (a value the search can pick): {exc}") from None
    return cfg


def tune_command(experiment: str, overrides: list[str], opts: TuneOptions) -> Path:
    """Check everything, run the search, print the table and the best trial's command line."""
    import os

    from charctl.config import check_experiment
    from charctl.experiments import load
    from charctl.launch.search_space import parse_overrides
    from charctl.launch.tune import make_out_dir, run_tune
    from charctl.launch.tune_setup import TuneSetup
    from charctl.paths import check_writable_dir

    check_experiment(experiment)
    exp = load(experiment)
    check_settings(opts.settings)
    fixed, dims = parse_overrides(overrides)
    if not dims:
        raise CharctlError(
            "nothing to search: give at least one key=choice(a,b), key=range(lo,hi) or key=loguniform(lo,hi)"
        )
    metric, mode = resolve_metric(experiment, dict(exp.tune_metrics), opts.metric, opts.mode)
    cfg = validate_space(experiment, fixed, dims, exp.config_class())
    check_writable_dir(cfg.output_root, "output_root")
    out = make_out_dir(cfg.output_root, experiment)
    fixed = [o for o in fixed if o.split("=", 1)[0].lstrip("+~") != "output_root"]  # trials: <out>/runs
    setup = TuneSetup(
        experiment=experiment,
        fixed=tuple(fixed),
        dims=tuple(dims),
        metric=metric,
        mode=mode,
        out_dir=str(out),
        settings=replace(opts.settings, address=opts.settings.address or None),
        report_keys=tuple(k for k in exp.tune_metrics if k != metric),
        cwd=os.getcwd(),
    )
    records, best = run_tune(setup)
    print((out / "trials.md").read_text(), end="")
    print(f"plot: {out / 'tune.png'}")
    if best is None:
        raise CharctlError(f"no trial reported {metric!r}; see {out / 'trials.md'}")
    print(f"best: trial {best.number + 1}, {metric} = {best.metric:.6g} -> {out / 'best.yaml'}")
    command = (out / "best.yaml").read_text().splitlines()[2].lstrip("# ").strip()
    print(f"rerun: {command}")
    failed = [r for r in records if r.state == "failed"]
    if failed:
        print(f"note: {len(failed)} trial(s) failed; first: {failed[0].message}")
    return out
