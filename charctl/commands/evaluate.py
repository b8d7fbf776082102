"""`charctl eval EXPERIMENT|RUN_DIR [RUN_DIR ...] [options] [overrides]`: dispatch to the experiment."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from charctl.errors import CharctlError

if TYPE_CHECKING:
    from charctl.experiments import Experiment


def split_targets(targets: list[str]) -> tuple[list[str], list[str]]:
    """Separate key=value overrides from run directories / experiment names."""
    overrides = [t for t in targets if "=" in t and not Path(t).exists()]
    rest = [t for t in targets if t not in overrides]
    return rest, overrides


def eval_command(targets: list[str], options: dict) -> None:
    """The first target (an experiment name or a run directory) selects the experiment; the options
    it declares are checked and every target and override is handed to its `evaluate` (with
    --checkpoints: to charctl.commands.eval_checkpoints and the experiment's `checkpoints`)."""
    from charctl.experiments import experiment_of, select_options, supporting
    from charctl.options import check_options

    check_options(options)  # -k >= 1, finite numbers, a writable -o: before any work or file

    rest, overrides = split_targets(targets)
    if not rest:
        raise CharctlError("name an experiment or a run directory: charctl eval EXPERIMENT|RUN_DIR ...")
    exp = experiment_of(rest[0])
    _check_runs_belong(exp, rest[1:])
    if options.get("checkpoints") and not exp.checkpoints:
        raise CharctlError(
            f"{exp.name} does not evaluate its kept checkpoints; --checkpoints is supported by "
            f"{', '.join(supporting('checkpoints')) or 'no experiment'}"
        )
    chosen = select_options(exp, "eval", options)
    modes = [o for o in exp.eval_options if o.mode]
    if not any(chosen[o.name] not in (None, False) for o in modes):
        raise CharctlError(f"say what to evaluate: {', '.join(o.flag for o in modes)}")
    if chosen.get("checkpoints"):
        from charctl.commands.eval_checkpoints import eval_checkpoints

        return eval_checkpoints(exp, rest, chosen, overrides)
    exp.entry("evaluate")(rest, chosen, overrides)


def _check_runs_belong(exp: Experiment, targets: list[str]) -> None:
    """Every further target is the experiment's name, one of its runs, or a run of an experiment that
    provides a capability `exp` accepts (`Experiment.eval_accepts`, e.g. a full-body baseline run)."""
    from charctl.experiments import experiment_of

    found = {exp.name}
    for t in targets:
        other = experiment_of(t)
        if other.name != exp.name and not set(exp.eval_accepts) & set(other.provides):
            found.add(other.name)
    if len(found) > 1:
        raise CharctlError(f"evaluate runs of one experiment at a time (got {', '.join(sorted(found))})")
