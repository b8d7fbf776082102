"""`charctl eval RUN --checkpoints [--after N] [options of the experiment]`: evaluate every kept checkpoint of
a run and pick one.

The run's checkpoints/samples_<n>.pt (train.keep_checkpoint_every) and last.pt, from `--after` samples on,
are evaluated in order of samples by the experiment's `checkpoints` entry point (what it measures, its
options and its selection rules: `charctl.experiments.CheckpointEvaluation`), each into OUT/<checkpoint>/
(OUT: -o, default RUN/eval/) with its row.json, so a second call while the training goes on evaluates only
the new checkpoints (and last.pt when it has moved on). Before the first one is evaluated, every one of them
is loaded once, so a missing, unreadable or mismatched checkpoint is a one-line error with nothing written.
The checkpoint with the largest rank key is chosen (the first, fewest samples, of equals). Picking the best
of many noisy estimates favours a lucky one, so an evaluation that draws random starts evaluates the chosen
checkpoint again on fresh starts (`--confirm-seed`, into OUT/<checkpoint>_confirm/); a deterministic one
(confirm_seed None) has nothing to confirm. OUT/checkpoints.json keeps every row, the choice and its
confirmation (null without one), and the experiment writes its table and plot beside it.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from charctl.errors import CharctlError

if TYPE_CHECKING:
    from charctl.experiments import CheckpointEvaluation, Experiment


def eval_checkpoints(exp: Experiment, targets: list[str], options: dict, overrides: list[str]) -> dict:
    """Every argument is checked (by the experiment's factory, then the checkpoints to evaluate are listed
    and loaded) before anything is written. Returns what checkpoints.json holds."""
    from charctl.files import atomic_write_text, strict_json

    ev = exp.entry("checkpoints")(targets, options, overrides)
    found = checkpoints_to_evaluate(ev, exp.name, float(options.get("after") or 0.0))
    rows = []
    for n, name in found:
        print(f"--- {name} ({n:,} samples)", flush=True)
        rows.append(ev.evaluate(name, n, ev.out / Path(name).stem, ev.seed))
    chosen = max(rows, key=ev.rank_key)  # the first (fewest samples) of equals
    confirm = confirm_choice(ev, chosen)
    result = {"rows": rows, "chosen": chosen, "confirm": confirm}
    atomic_write_text(ev.out / "checkpoints.json", strict_json(result))
    print(ev.write_report(rows, chosen, confirm))
    return result


def checkpoints_to_evaluate(ev: CheckpointEvaluation, experiment: str, after: float) -> list[tuple[int, str]]:
    """(samples, file name) of the run's kept checkpoints from `after` samples on, each one loaded once by
    the evaluation's `check`: a one-line CharctlError (none to evaluate, one that does not load) before
    anything is written."""
    from charctl.checkpoints import kept_checkpoints

    found = [(n, f) for n, f in kept_checkpoints(ev.run_dir, experiment, ev.samples_key) if n >= after]
    if not found:
        since = f" from {after:,.0f} samples on" if after else ""
        raise CharctlError(f"{ev.run_dir}/checkpoints has no checkpoint to evaluate{since}")
    for _, name in found:
        ev.check(name)
    return found


def confirm_choice(ev: CheckpointEvaluation, chosen: dict) -> dict | None:
    """The chosen checkpoint evaluated again on fresh starts (`confirm_seed`), or None for an evaluation
    that draws no starts (the same numbers again)."""
    if ev.confirm_seed is None:
        return None
    return ev.evaluate(
        chosen["checkpoint"],
        chosen["samples"],
        ev.out / f"{Path(chosen['checkpoint']).stem}_confirm",
        ev.confirm_seed,
        confirm=True,
    )
