"""`charctl eval RUN --checkpoints [--after N] [--rank R] [--seed S] [--confirm-seed S]`: evaluate every
kept checkpoint of a run and pick one.

The run's checkpoints/samples_<n>.pt (train.keep_checkpoint_every) and last.pt, from `--after` samples on,
are evaluated in order of samples by the experiment's `checkpoints` entry point (what it measures, its
options and its selection rules: `charctl.experiments.CheckpointEvaluation`), each into OUT/<checkpoint>/
(OUT: -o, default RUN/eval/) with its row.json, so a second call while the training goes on evaluates only
the new checkpoints (and last.pt when it has moved on). The checkpoint with the largest rank key is chosen
(the first, fewest samples, of equals). Picking the best of many noisy estimates favours a lucky one, so
the chosen checkpoint is evaluated again on fresh starts (`--confirm-seed`, into OUT/<checkpoint>_confirm/);
OUT/checkpoints.json keeps every row, the choice and its confirmation, and the experiment writes its table
and plot beside it.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from charctl.errors import CharctlError

if TYPE_CHECKING:
    from charctl.experiments import Experiment


def eval_checkpoints(exp: Experiment, targets: list[str], options: dict, overrides: list[str]) -> dict:
    """Every argument is checked (by the experiment's factory, then the checkpoints to evaluate are listed)
    before anything is written. Returns what checkpoints.json holds."""
    from charctl.checkpoints import kept_checkpoints
    from charctl.files import atomic_write_text, strict_json

    ev = exp.entry("checkpoints")(targets, options, overrides)
    after = float(options.get("after") or 0.0)
    found = [(n, f) for n, f in kept_checkpoints(ev.run_dir, exp.name) if n >= after]
    if not found:
        since = f" from {after:,.0f} samples on" if after else ""
        raise CharctlError(f"{ev.run_dir}/checkpoints has no checkpoint to evaluate{since}")
    rows = []
    for n, name in found:
        print(f"--- {name} ({n:,} samples)", flush=True)
        rows.append(ev.evaluate(name, n, ev.out / Path(name).stem, ev.seed))
    chosen = max(rows, key=ev.rank_key)  # the first (fewest samples) of equals
    confirm = ev.evaluate(
        chosen["checkpoint"],
        chosen["samples"],
        ev.out / f"{Path(chosen['checkpoint']).stem}_confirm",
        ev.confirm_seed,
        confirm=True,
    )
    result = {"rows": rows, "chosen": chosen, "confirm": confirm}
    atomic_write_text(ev.out / "checkpoints.json", strict_json(result))
    print(ev.write_report(rows, chosen, confirm))
    return result
