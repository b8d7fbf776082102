"""`charctl eval SRB_RUN [FULL_BODY_RUN] --push`: the push-robustness study and its report.

The study runs the protocol of push.py on the trained SRB policy (batched through rollout.py:
every case x trial is one environment of one SRBEnv, stepped together) and, when a full-body run
is given (second run directory or push.baseline_run=DIR|auto), on that baseline through the
registry: the run's experiment provides the `push_rollout` capability (cgail does), so srb never
imports another experiment.
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

from charctl.errors import CharctlError
from charctl.eval.report import write_report
from charctl.experiments import PushRollout, latest_run_dir, load, providers
from charctl.experiments.srb.push import (
    PushTable,
    comparison_markdown,
    make_cases,
    plot_comparison,
    run_push_study,
    save_tables,
)
from charctl.experiments.srb.rollout import srb_push_batch

NAME = "srb"
CAPABILITY = "push_rollout"
NO_BASELINE = (
    "no cgail run given (or none found for push.baseline_run=auto: an AMP walk run, "
    "cgail.conditional=false use_skills=[walk])"
)


# ---------------------------------------------------------------------------- CLI entry points
def _resolve_targets(targets: list[str], overrides: list[str]) -> tuple[Path, str]:
    """(srb run dir, full-body baseline run dir or '') from the positional targets."""
    from charctl.runs import run_experiment

    srb_runs, other = [], []
    for t in targets:
        if t == NAME:
            srb_runs.append(latest_run_dir(NAME, overrides))
        elif Path(t).is_dir():
            (srb_runs if run_experiment(t) == NAME else other).append(Path(t))
        else:
            raise CharctlError(f"{t!r} is neither a run directory nor {NAME!r}")
    if not srb_runs:
        raise CharctlError("give an srb run directory (or 'srb' for the latest one)")
    if len(srb_runs) > 1:
        raise CharctlError("give one srb run (and optionally one full-body run for the baseline)")
    baselines = [p.name for p in providers(CAPABILITY)]
    if len(other) > 1 or (other and run_experiment(other[0]) not in baselines):
        raise CharctlError(f"the baseline must be one {' or '.join(baselines)} run directory")
    return srb_runs[0], str(other[0]) if other else ""


def evaluate(targets: list[str], options: dict, overrides: list[str]) -> None:
    """`--push`: the push study of the srb run (and a full-body baseline) -> push.md/png/json, report.md."""
    if not options.get("push"):
        raise CharctlError("srb evaluates with --push (the push-robustness study)")
    from charctl.experiments.srb.config import Config
    from charctl.runs import open_run

    run_dir, baseline = _resolve_targets(targets, overrides)
    run = open_run(run_dir, Config, overrides)
    cfg = run.cfg
    baseline = baseline or str(cfg.push.baseline_run or "")
    if baseline == "auto":
        baseline = find_baseline_run(Path(str(cfg.output_root)))
    trials = int(options.get("episodes") or cfg.push.trials)
    if trials < 1:
        raise CharctlError("-k/--episodes must be >= 1")
    out_dir = Path(options.get("out") or run.path("push"))
    cases = make_cases(cfg.push)
    simulator = _baseline_simulator(baseline)  # the baseline run checked before the study starts
    print(f"push study: {len(cases)} cases x {trials} trials on {run_dir}")
    t0 = time.perf_counter()
    srb = run_push_study(
        None, cases, trials, seed=int(cfg.seed), simulate_batch=lambda jobs: srb_push_batch(run, jobs), label="SRB"
    )
    srb.meta = {"run": str(run_dir), "seconds": time.perf_counter() - t0}
    named: dict[str, PushTable | None] = {"srb": srb}
    labels = ["SRB (trained policy)"]
    if cfg.push.zero_action_column:
        named["srb_zero_action"] = run_push_study(
            None,
            cases,
            trials,
            seed=int(cfg.seed),
            label="SRB zero action",
            simulate_batch=lambda jobs: srb_push_batch(run, jobs, zero_action=True),
        )
        labels.append("SRB, zero action (QP + PD only)")
    full, note = _baseline_table(baseline, cases, trials, int(cfg.seed), simulator)
    named["full_body"] = full
    labels.append(_baseline_label(baseline))
    tables = list(named.values())
    md = comparison_markdown(tables, labels, float(cfg.push.survive_rate), note)
    out_dir.mkdir(parents=True, exist_ok=True)
    save_tables(named, out_dir / "push.json")
    plot_comparison(tables, labels, out_dir / "push.png")
    report = _report(run, cfg, srb, full, md, note, trials)
    (out_dir / "push.md").write_text(md)
    curve = run.dir / "training_curve.png"
    if curve.is_file() and out_dir.resolve() != run.dir.resolve():
        shutil.copyfile(curve, out_dir / "training_curve.png")
    write_report(out_dir, report)
    print(md)
    print(f"wrote {out_dir / 'report.md'}, push.md, push.png, push.json ({time.perf_counter() - t0:.0f} s)")


def find_baseline_run(output_root: Path) -> str:
    """The newest full-body baseline run under `output_root` that an experiment providing
    `push_rollout` finds suitable (cgail: an AMP walk run); '' if none."""
    found = [provider.capability(CAPABILITY).find_baseline_run(Path(output_root)) for provider in providers(CAPABILITY)]
    return max((f for f in found if f), key=lambda d: Path(d).name, default="")


def _push_rollout(baseline: str) -> PushRollout | None:
    """The `push_rollout` capability of the experiment that made the run `baseline`, if it has one."""
    from charctl.runs import run_experiment

    exp = load(run_experiment(baseline))
    return exp.capability(CAPABILITY) if CAPABILITY in exp.provides else None


def _baseline_label(baseline: str) -> str:
    if not baseline:
        return "full body (cgail walk)"
    rollout = _push_rollout(baseline)
    return rollout.baseline_label(baseline) if rollout is not None else f"full body ({Path(baseline).name})"


def _baseline_simulator(baseline: str):
    """(the full-body baseline's push simulator, or None; the note the report gives when there is none).
    A baseline that is not a run, or a run its experiment cannot push, is a one-line error here."""
    if not baseline:
        return None, NO_BASELINE
    rollout = _push_rollout(baseline)
    if rollout is None:
        return None, f"{baseline} is not a run of an experiment that provides a push rollout"
    return rollout.make_push_simulator(baseline), ""


def _baseline_table(
    baseline: str, cases, trials: int, seed: int, simulator: tuple | None = None
) -> tuple[PushTable | None, str]:
    """The baseline's push table and the report's note (`simulator`: `_baseline_simulator(baseline)` when made)."""
    simulate, note = simulator if simulator is not None else _baseline_simulator(baseline)
    if simulate is None:
        return None, note
    t0 = time.perf_counter()
    table = run_push_study(simulate, cases, trials, seed=seed, label="full body")
    table.meta = {"run": baseline, "seconds": time.perf_counter() - t0}
    return table, ""


def _report(run, cfg, srb: PushTable, full: PushTable | None, md: str, note: str, trials: int) -> str:
    metrics_path = run.dir / "metrics.json"
    m = json.loads(metrics_path.read_text()) if metrics_path.is_file() else {}
    lines = [f"# srb reproduction report\n\nrun: `{run.dir}` (scale={cfg.scale}, seed={cfg.seed})\n\n## Training\n\n"]
    if m:
        lines.append(
            f"- samples: {m.get('samples', 0):,} in {m.get('wall_s', float('nan')):.0f} s of training "
            f"({m.get('samples', 0) / max(m.get('wall_s', 1e-9), 1e-9):,.0f} samples/s; rollout alone "
            f"{m.get('rollout_samples_per_s', float('nan')):,.0f} samples/s)\n"
        )
        lines.append(
            f"- final mean episode length {m.get('episode_length', float('nan')):.1f} steps "
            f"(limit {cfg.termination.max_steps}), "
            f"reward per step {m.get('reward_per_step_last25', m.get('reward_per_step', float('nan'))):.2f} "
            f"(mean of the last 25 iterations where recorded; max {cfg.reward.w_stand:g})\n"
        )
        lines.append(
            "- curves: `training_curve.png` (episode length and reward per step against samples)\n\n"
            "![training](training_curve.png)\n"
        )
    else:
        lines.append("- no metrics.json in the run (training interrupted?)\n")
    lines.append(
        f"\n## Push study (paper §9, Table 1)\n\nK = {trials} trials per case; "
        f"directions {list(cfg.push.directions)} deg, phases {list(cfg.push.phases)}; "
        f"'impulse' = force held {cfg.push.impulse_duration:g} s; settle {cfg.push.settle:g} s, "
        f"observe {cfg.push.observe:g} s. SRB study took {srb.meta.get('seconds', 0):.0f} s.\n"
    )
    lines.append(
        "Rows: 'no push' = the same episodes unpushed (a simulator that falls there has no robustness to "
        "measure); a cell pools every direction, phase and trial. Columns: the trained SRB policy; the same SRB "
        "with zero actions (QP + PD tracker alone, what the policy adds); the full-body baseline.\n"
    )
    if full is None:
        lines.append(f"\n**Full-body baseline missing**: {note}.\n")
    else:
        lines.append(
            f"\nFull-body baseline: `{full.meta.get('run')}` ({full.meta.get('seconds', 0):.0f} s for its trials).\n"
        )
    lines.append(md)
    lines.append("\n![push](push.png)\n")
    return "".join(lines)
