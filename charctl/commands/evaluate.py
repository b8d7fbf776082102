"""`charctl eval [RUN_DIR ... | EXPERIMENT] [flags] [overrides]`: dispatch to the experiment."""

from __future__ import annotations

from pathlib import Path

from charctl.errors import CharctlError


def split_targets(targets: list[str]) -> tuple[list[str], list[str]]:
    """Separate key=value overrides from run directories / experiment names."""
    overrides = [t for t in targets if "=" in t and not Path(t).exists()]
    rest = [t for t in targets if t not in overrides]
    return rest, overrides


def eval_command(targets: list[str], options: dict) -> None:
    from charctl.experiments import EXPERIMENTS, entry
    from charctl.runs import latest_run, run_experiment

    rest, overrides = split_targets(targets)
    if not rest:
        rest = [str(latest_run("outputs", "cgail"))]
    experiments = set()
    for t in rest:
        if t in EXPERIMENTS:
            experiments.add(t)
        elif Path(t).is_dir():
            experiments.add(run_experiment(t))
        else:
            raise CharctlError(f"{t!r} is neither a run directory nor an experiment ({', '.join(sorted(EXPERIMENTS))})")
    if len(experiments) > 1:
        first = rest[0] if rest[0] in EXPERIMENTS else run_experiment(rest[0])
        if not (options.get("push") and first == "srb" and experiments == {"srb", "cgail"}):
            raise CharctlError(f"evaluate runs of one experiment at a time (got {', '.join(sorted(experiments))})")
        experiments = {first}  # srb's push study takes a cgail run as its full-body baseline
    experiment = experiments.pop()
    if not any(v not in (None, False) for k, v in options.items() if k not in ("episodes", "out")):
        raise CharctlError("say what to evaluate: --dtw, --confusion, --switch A B, --curves, --pose-error, --push or --sweep")
    entry(experiment, "evaluate")(rest, options, overrides)
