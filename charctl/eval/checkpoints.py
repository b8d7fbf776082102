"""What the experiments' `charctl eval RUN --checkpoints` entry points share (the listing of the kept
checkpoints, the loop, the choice and its confirmation: charctl/commands/eval_checkpoints.py).

- `single_run` / `refuse_other_modes`: the argument checks every entry point makes (one run of the
  experiment; --checkpoints alone among the evaluation modes);
- `write_checkpoints_md`: OUT/checkpoints.md;
- `ScalarCheckpoints`: a whole `charctl.experiments.CheckpointEvaluation` for an experiment that ranks its
  kept checkpoints by one deterministic number its own evaluation code measures from a checkpoint's state
  (com-cnn: the held-out pose error; hopper-ga: the best individual's fitness). It writes OUT/<checkpoint>/
  row.json (reused while the checkpoint's samples and the settings match), checkpoints.md (a table, the
  chosen checkpoint named) and checkpoints.png (the number against samples).

    ev = ScalarCheckpoints(run_dir, out, "my-exp", Metric("error_m", "error (m)", lower_is_better=True,
                           note="how it is measured"), measure=lambda state: {"error_m": ...})
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from charctl.errors import CharctlError


# ---------------------------------------------------------------------------- argument checks
def single_run(run_dirs: Sequence[Path], experiment: str) -> Path:
    """The one run directory `--checkpoints` evaluates, a run of `experiment` (one-line errors otherwise)."""
    from charctl.runs import run_experiment

    if len(run_dirs) != 1:
        raise CharctlError(f"--checkpoints evaluates the kept checkpoints of one run, got {len(run_dirs)}")
    run_dir = Path(run_dirs[0])
    made_by = run_experiment(run_dir)
    if made_by != experiment:
        raise CharctlError(f"{run_dir} is a {made_by!r} run, not a {experiment} run")
    return run_dir


def refuse_other_modes(options: dict, modes: Sequence[str], measured: str) -> None:
    """A one-line error when one of the evaluation `modes` is given beside --checkpoints, which measures
    `measured` (words for the message) per checkpoint."""
    other = [m for m in modes if options.get(m)]
    if other:
        flag = "--" + other[0].replace("_", "-")
        raise CharctlError(f"--checkpoints measures {measured} per checkpoint; it does not combine with {flag}")


# ---------------------------------------------------------------------------- files
def write_checkpoints_md(out: Path, lines: Sequence[str]) -> str:
    """OUT/checkpoints.md from its lines (written atomically); returns its text without the final newline."""
    from charctl.files import atomic_write_text

    text = "\n".join(lines)
    atomic_write_text(Path(out) / "checkpoints.md", text + "\n")
    return text


def settings_digest(settings: dict) -> str:
    """A short fingerprint of `settings` (JSON values) that a row keeps to tell whether it still applies."""
    return hashlib.sha1(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:16]


def cached_row(out: Path, name: str, samples: int, settings: str) -> dict | None:
    """The row.json an earlier evaluation of checkpoint `name` at `samples` samples wrote into `out` with
    the same `settings` (a `settings_digest`), or None."""
    path = Path(out) / "row.json"
    if not path.is_file():
        return None
    row = json.loads(path.read_text())
    same = row.get("checkpoint") == name and row.get("samples") == samples and row.get("settings") == settings
    return row if same else None


# ---------------------------------------------------------------------------- one deterministic number
@dataclass(frozen=True)
class Metric:
    """The number `ScalarCheckpoints` ranks kept checkpoints by, and the further numbers its table shows."""

    key: str  # the number's key in a row, e.g. "pose_error_deg"
    label: str  # its table column and plot axis, with its unit, e.g. "held-out pose error (deg)"
    lower_is_better: bool
    note: str  # how it is measured, one paragraph of checkpoints.md
    columns: tuple[tuple[str, str], ...] = ()  # further (row key, column label with unit) of the table


@dataclass
class ScalarCheckpoints:
    """A `charctl.experiments.CheckpointEvaluation` ranking kept checkpoints by `metric`, which
    `measure(state)` computes from a loaded checkpoint's state with the experiment's own evaluation code.
    The number is deterministic, so no starts are drawn (`seed` and `confirm_seed` None) and the chosen
    row needs no second evaluation. `signature` is what a checkpoint must match to load
    (charctl.checkpoints.load_checkpoint); `settings` is what the numbers depend on besides the
    checkpoint (a row.json is reused while they match; JSON values only). With `cheap` (a measurement that
    takes milliseconds), `check` measures too, so a checkpoint whose number cannot be measured is refused
    before anything is written."""

    run_dir: Path
    out: Path
    experiment: str
    metric: Metric
    measure: Callable[[dict], dict]  # a checkpoint's state -> {metric.key: number, column key: value, ...}
    signature: dict | None = None
    settings: dict = field(default_factory=dict)
    samples_key: str = "samples"  # the state's sample count (charctl.checkpoints.kept_checkpoints)
    samples_label: str = "samples"  # what the samples count (the table's first column, the plot's x axis)
    cheap: bool = False
    seed: int | None = None
    confirm_seed: int | None = None

    def load(self, name: str) -> dict:
        """The state of checkpoint file `name` of the run (one-line CharctlError if it does not load)."""
        from charctl.checkpoints import load_checkpoint

        return load_checkpoint(self.run_dir / "checkpoints" / name, self.experiment, self.signature)

    def check(self, name: str) -> None:
        state = self.load(name)
        if self.cheap:
            self.measure(state)

    def evaluate(self, name: str, samples: int, out: Path, seed: int | None, confirm: bool = False) -> dict:  # noqa: ARG002
        """The row of checkpoint `name`: out/row.json when it matches, else measured (then written there)."""
        from charctl.files import atomic_write_text, strict_json

        digest = settings_digest(self.settings)
        row = cached_row(out, name, samples, digest)
        if row is None:
            numbers = self.measure(self.load(name))
            row = {"checkpoint": name, "samples": int(samples), **numbers, "settings": digest}
            atomic_write_text(Path(out) / "row.json", strict_json(row))
        return row

    def rank_key(self, row: dict) -> tuple:
        value = float(row[self.metric.key])
        return (-value,) if self.metric.lower_is_better else (value,)

    def write_report(self, rows: list[dict], chosen: dict, confirm: dict | None) -> str:  # noqa: ARG002
        """checkpoints.md (the table, the chosen checkpoint named) and checkpoints.png; returns the .md text."""
        text = write_checkpoints_md(self.out, self.report_lines(rows, chosen))
        self.plot(rows, chosen, self.out / "checkpoints.png")
        return text

    def report_lines(self, rows: list[dict], chosen: dict) -> list[str]:
        """checkpoints.md: title, how the number is measured, the selection rule, the table, the choice."""
        from charctl.eval.report import fmt_cell

        m = self.metric
        best = "lowest" if m.lower_is_better else "highest"
        return [
            f"# Kept checkpoints of {self.run_dir.name}",
            "",
            m.note,
            "",
            f"Selection: the {best} {m.label}; of equals, the one with the fewest {self.samples_label}. "
            "The number is deterministic, so the chosen checkpoint is not evaluated again.",
            "",
            *self.table(rows).split("\n"),
            "",
            f"Chosen: {chosen['checkpoint']} ({chosen['samples']:,} {self.samples_label}): "
            f"{m.label} {fmt_cell(chosen[m.key])}.",
        ]

    def table(self, rows: list[dict]) -> str:
        """One row per checkpoint: its sample count, file, the ranked number and the further columns."""
        from charctl.eval.report import fmt_cell, markdown_grid

        keys = [self.metric.key, *(k for k, _ in self.metric.columns)]
        header = [self.samples_label, "checkpoint", self.metric.label, *(label for _, label in self.metric.columns)]
        cells = [[f"{r['samples']:,}", r["checkpoint"], *(fmt_cell(r.get(k)) for k in keys)] for r in rows]
        return markdown_grid(header, cells, align="r-" + "r" * len(keys))

    def plot(self, rows: list[dict], chosen: dict, path: Path) -> None:
        """The ranked number against the sample count, the chosen checkpoint circled."""
        from charctl.viz.plots import new_figure, save_figure

        fig, ax = new_figure(1, 1, figsize=(7, 3.5))
        ax.plot([r["samples"] for r in rows], [r[self.metric.key] for r in rows], "o-")
        ax.plot([chosen["samples"]], [chosen[self.metric.key]], "o", ms=14, mfc="none", mec="C3", label="chosen")
        ax.set_xlabel(self.samples_label)
        ax.set_ylabel(self.metric.label)
        ax.legend(loc="best")
        ax.set_title(f"{self.run_dir.name}: kept checkpoints")
        save_figure(fig, path)
