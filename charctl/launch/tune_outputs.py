"""`charctl tune`'s result files: trials.md|csv|json (best first), best.yaml and tune.png."""

from __future__ import annotations

import csv
import json
import math
from dataclasses import asdict
from pathlib import Path

from charctl.launch.tune_setup import TrialRecord, TuneSetup


# ---------------------------------------------------------------------------- outputs
def ranked(records: list[TrialRecord], mode: str) -> list[TrialRecord]:
    """Best first: finished trials by metric, then those ASHA stopped, then the rest."""
    order = {"done": 0, "stopped": 1}

    def key(r: TrialRecord):
        value = r.metric if r.metric is not None else math.inf * (1 if mode == "min" else -1)
        return (order.get(r.state, 2), value if mode == "min" else -value, r.number)

    return sorted(records, key=key)


def best_trial(records: list[TrialRecord], mode: str) -> TrialRecord | None:
    rows = [r for r in ranked(records, mode) if r.metric is not None and r.state in ("done", "stopped")]
    return rows[0] if rows else None


def write_outputs(setup: TuneSetup, records: list[TrialRecord]) -> TrialRecord | None:
    """trials.md / .csv / .json, tune.png and best.yaml; returns the best trial."""
    out = Path(setup.out_dir)
    rows = ranked(records, setup.mode)
    keys = [d.name for d in setup.dims]
    table = [_row(r, keys, setup.metric) for r in rows]
    (out / "trials.json").write_text(json.dumps([asdict(r) for r in rows], indent=2) + "\n")
    with open(out / "trials.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(table[0]) if table else ["trial"])
        writer.writeheader()
        writer.writerows(table)
    (out / "trials.md").write_text(markdown_table(setup, table))
    plot(setup, rows, out / "tune.png")
    best = best_trial(records, setup.mode)
    if best is not None:
        write_best(setup, best, out / "best.yaml")
    return best


def _row(r: TrialRecord, keys: list[str], metric: str) -> dict[str, str]:
    return {
        "trial": str(r.number + 1),
        "state": r.state,
        **{k: r.values.get(k, "") for k in keys},
        metric: "" if r.metric is None else f"{r.metric:.6g}",
        "reports": str(r.reports),
        "run_dir": r.run_dir,
        "message": r.message if r.state != "done" else "",
    }


def markdown_table(setup: TuneSetup, table: list[dict[str, str]]) -> str:
    """The trials as a markdown table, best first."""
    head = (
        f"# tune {setup.experiment}: {setup.metric} ({setup.mode}), {len(table)} trial(s)\n\n"
        f"Fixed overrides: `{' '.join(setup.fixed) or '(none)'}`; searched: "
        + ", ".join(f"`{d.key}` {d.kind}" for d in setup.dims)
        + "\n\n"
    )
    if not table:
        return head + "(no trial started)\n"
    cols = [c for c in table[0] if c != "message" or any(r["message"] for r in table)]
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    lines += ["| " + " | ".join(r[c].replace("|", "\\|") for c in cols) + " |" for r in table]
    return head + "\n".join(lines) + "\n"


def write_best(setup: TuneSetup, best: TrialRecord, path: Path) -> None:
    """best.yaml: the best trial's overrides as `key: value` lines, the command line in a comment."""
    import yaml

    overrides = [*setup.fixed, *(f"{d.key}={best.values[d.name]}" for d in setup.dims)]
    mapping = {}
    for o in overrides:
        key, _, value = o.partition("=")
        try:
            mapping[key] = yaml.safe_load(value)
        except yaml.YAMLError:
            mapping[key] = value
    command = f"charctl train {setup.experiment} " + " ".join(_shell_quote(o) for o in overrides)
    header = (
        f"# best of {setup.settings.trials} trial(s) of `charctl tune {setup.experiment}`: {setup.metric} = "
        f"{best.metric:.6g} ({setup.mode}); run {best.run_dir}\n"
        f"# run it again with these overrides:\n#   {command.strip()}\n"
    )
    path.write_text(header + yaml.safe_dump(mapping, default_flow_style=False, sort_keys=False))


def _shell_quote(text: str) -> str:
    import shlex

    return shlex.quote(text)


def plot(setup: TuneSetup, rows: list[TrialRecord], path: Path) -> None:
    """The metric against each searched key: filled = finished, hollow = stopped early, star = best."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dims = list(setup.dims)
    fig, axes = plt.subplots(1, len(dims), figsize=(4.2 * len(dims), 3.4), squeeze=False)
    best = best_trial(rows, setup.mode)
    for ax, dim in zip(axes[0], dims):
        xs_all = [r.values.get(dim.name, "") for r in rows if r.metric is not None]
        numeric = all(_number(x) is not None for x in xs_all)
        cats = list(dict.fromkeys(dim.values)) if dim.kind == "choice" else []
        for state, style in (("done", {"marker": "o"}), ("stopped", {"marker": "o", "facecolors": "none"})):
            pts = [(r.values.get(dim.name, ""), r.metric) for r in rows if r.state == state and r.metric is not None]
            if not pts:
                continue
            xs = [_number(x) if numeric else cats.index(x) if x in cats else 0 for x, _ in pts]
            ax.scatter(xs, [y for _, y in pts], edgecolors="C0", label=state, **style)
        if best is not None:
            x = best.values.get(dim.name, "")
            bx = _number(x) if numeric else cats.index(x) if x in cats else 0
            ax.scatter([bx], [best.metric], marker="*", s=160, color="C3", label="best", zorder=3)
        if not numeric and cats:
            ax.set_xticks(range(len(cats)), cats, rotation=20)
        if dim.log:
            ax.set_xscale("log")
        ax.set_xlabel(dim.name)
        ax.set_ylabel(f"{setup.metric} ({setup.mode})")
        ax.grid(alpha=0.3)
    if axes[0][0].get_legend_handles_labels()[0]:
        axes[0][0].legend(fontsize=8)
    fig.suptitle(f"tune {setup.experiment}: {len(rows)} trial(s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _number(text: str) -> float | None:
    try:
        value = float(text)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None
