"""`charctl eval RUN... --dtw --confusion --switch A B --curves --survival S --fidelity` for cgail (docs/cgail.md;
the paper's chapter 6; --fidelity: charctl/experiments/cgail/fidelity.py; --checkpoints: eval_checkpoints.py).

Every mode writes JSON (+ CSV / PNG) into the output folder (default `<first run>/eval/`) and
appends its table to `report.md` there, with the command that produced it and the paper's
numbers alongside. Each mode is a rollout (rollouts.py: the policy and discriminator on the torch
device of `device`, each run's config or a `device=cpu|cuda|auto` override; the simulator on the
host), its metrics (metrics.py: DTW, no-fall, confusion, switch latency) and what is written
(report.py, with the shared table / JSON / CSV helpers of charctl.eval.report). Every argument of
every mode is checked before the first file is written.
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

import numpy as np
import torch

from charctl.checkpoints import checkpoint_file_name
from charctl.errors import CharctlError
from charctl.experiments.cgail.metrics import (
    PERFORM_COVERAGE,
    PERFORM_SECONDS,
    PERFORM_SHARE,
    PERFORM_SPEED_RANGE,
    confusion_matrices,
    dtw_table,
    survival_table,
    switch_curves,
    switch_summary,
)
from charctl.experiments.cgail.policy import resolve_run_dirs
from charctl.experiments.cgail.report import (
    append_report,
    write_confusion,
    write_curves,
    write_dtw,
    write_survival,
    write_switch,
    write_switch_matrix,
)
from charctl.experiments.cgail.rollouts import (
    DeviceRun,
    load_eval_run,
    split_eval_overrides,
    switch_rollout,
)
from charctl.progress import TrainingProgress

__all__ = [
    "check_mode_arguments",
    "eval_confusion",
    "eval_curves",
    "eval_dtw",
    "eval_survival",
    "eval_switch",
    "eval_switch_matrix",
    "evaluate",
]


# ---------------------------------------------------------------------------- modes
def eval_dtw(runs: list[DeviceRun], episodes: int, out: Path) -> dict:
    """Table 6.1: DTW pose error per skill and run against the clips (dtw.json, dtw.csv, report.md)."""
    return write_dtw(out, dtw_table(runs, episodes), episodes, runs)


def eval_survival(runs: list[DeviceRun], episodes: int, seconds: float, out: Path, seed: int = 4321) -> dict:
    """Share of episodes without a fall (and classifier accuracy on policy motion) per skill and run;
    `seed` draws the RSI frames and headings (the same for every run, so runs are compared on equal starts)."""
    return write_survival(out, survival_table(runs, episodes, seconds, seed), episodes, seconds, seed, runs)


def eval_confusion(tr: DeviceRun, episodes: int, out: Path, seed: int = 99) -> dict:
    """Fig 6.8: mean classifier probabilities per commanded skill (policy) and per clip (data)."""
    if not tr.agent.conditional:
        raise CharctlError(f"{tr.run_dir} is an AMP (unconditional) run: it has no classifier for --confusion")
    policy, data = confusion_matrices(tr, episodes, seed)
    return write_confusion(out, tr, policy, data)


@torch.no_grad()
def eval_switch(
    tr: DeviceRun, a: str, b: str, trials: int, out: Path, before_s: float = 1.0, after_s: float = 2.0
) -> dict:
    """Fig 6.10/6.11: command A -> B mid-episode with and without the ramp; latency and falls.

    Each trial runs `before_s` seconds of A, then the switch, then the ramp (in the ramp condition)
    and `after_s` seconds more. Both conditions are watched over the same window, which ends
    `after_s` after the ramp has finished, so a policy that follows the blended command and turns to
    B near the end of the ramp is seen doing it."""
    if not tr.agent.conditional:
        raise CharctlError(f"{tr.run_dir} is an AMP run: it takes no command, so --switch does not apply")
    ka, kb = tr.skill_index(a), tr.skill_index(b)
    frames = switch_frames(tr, before_s, after_s)
    curves, summary = {}, {}
    for name, ramp in (("ramp", frames["ramp_frames"]), ("no_ramp", 0)):
        rec = _switch_recording(tr, ka, kb, trials, ramp, frames)
        summary[name] = switch_summary(tr, kb, rec, frames["switch_frame"], ramp, trials)
        curves[name] = switch_curves(rec)
    return write_switch(out, tr, a, b, ka, kb, summary, curves, frames)


@torch.no_grad()
def eval_switch_matrix(tr: DeviceRun, trials: int, out: Path, before_s: float = 1.0, after_s: float = 3.0) -> dict:
    """The switch study with the ramp for every ordered pair A -> B of the run's skills (`eval_switch`'s rollouts and
    `performed` rule, watched `after_s` after the ramp and judged over all of it, where `--switch` judges the first
    `PERFORM_SECONDS`): switch_matrix.json, switch_matrix.png and a report section. The targets' walk -> kick
    alone misses a policy that cannot leave the kick or enter it from the run (docs/cgail.md, "The late-switch
    command at seeds 1 and 2")."""
    if not tr.agent.conditional:
        raise CharctlError(f"{tr.run_dir} is an AMP run: it takes no command, so --switch-matrix does not apply")
    frames = switch_frames(tr, before_s, after_s, perform_seconds=None)
    names = tr.skill_names
    t_switch, ramp = frames["switch_frame"], frames["ramp_frames"]
    pairs = np.array([(i, j) for i in range(len(names)) for j in range(len(names)) if i != j])
    # every pair at once, `trials` envs each: one batched rollout (`switch_rollout`), judged pair by pair
    with TrainingProgress(frames["end_frame"], f"switch matrix ({len(pairs)} pairs x {trials})", unit="frames") as bar:
        rec = _switch_recording(tr, pairs[:, 0], pairs[:, 1], trials, ramp, frames, progress=bar)
    cells = {}
    for p, (ka, kb) in enumerate(pairs):
        cells[(names[ka], names[kb])] = switch_summary(
            tr, kb, rec.pair(p, trials), t_switch, ramp, trials, coverage_from=ramp
        )
    return write_switch_matrix(out, tr, cells, frames)


def switch_frames(
    tr: DeviceRun, before_s: float, after_s: float, perform_seconds: float | None = PERFORM_SECONDS
) -> dict:
    """The switch study's timing in control frames: the switch after `before_s` of A, the run's command ramp, the
    end `after_s` after the ramp; and the rules of `metrics.performed_after_switch`: the window after the switch
    (`perform_seconds`; None: to the end), the foot-peak share and the speed range."""
    hz = tr.cfg.env.control_hz
    ramp_frames = int(tr.cfg.env.ramp_frames) or 60
    t_switch = int(before_s * hz)
    t_end = t_switch + ramp_frames + int(after_s * hz)
    return {
        "switch_frame": t_switch,
        "end_frame": t_end,
        "ramp_frames": ramp_frames,
        "before_s": before_s,
        "after_s": after_s,
        "perform_seconds": (t_end - t_switch) / hz if perform_seconds is None else perform_seconds,
        "perform_share": PERFORM_SHARE,
        "perform_speed_range": list(PERFORM_SPEED_RANGE),
        "perform_coverage": PERFORM_COVERAGE,  # the switch matrix only
    }


def _switch_recording(tr: DeviceRun, ka, kb, trials: int, ramp: int, frames: dict, progress=None):
    hz = tr.cfg.env.control_hz
    t_switch, t_end = frames["switch_frame"], frames["end_frame"]
    perform = int(round(frames["perform_seconds"] * hz))
    return switch_rollout(tr, ka, kb, trials, ramp, t_switch, t_end, perform, progress)


def eval_curves(run_dirs: list[Path], out: Path) -> dict:
    """Training-curve figures from the TensorBoard logs (Fig 6.3, 6.4, 6.6/6.7, 6.9)."""
    return write_curves(run_dirs, out)


# ---------------------------------------------------------------------------- entry point
def evaluate(targets: list[str], options: dict, overrides: list[str]) -> None:
    """The modes given in `options` (--dtw, --confusion, --switch, --curves, --survival, --fidelity) over the runs."""
    device, overrides = split_eval_overrides(overrides)
    run_dirs = resolve_run_dirs(targets, overrides, "eval")
    if options.get("fidelity"):
        from charctl.viz.video import check_can_render

        check_can_render()  # the filmstrips: a machine that cannot render says so before anything is written
    checkpoint = options.get("checkpoint")
    for d in run_dirs if checkpoint else []:  # also for the modes that load no policy (--curves)
        if not (d / "checkpoints" / checkpoint_file_name(checkpoint)).is_file():
            raise CharctlError(f"checkpoint not found: {d / 'checkpoints' / checkpoint_file_name(checkpoint)}")
    default_out = (
        run_dirs[0] / "eval" / Path(checkpoint_file_name(checkpoint)).stem if checkpoint else run_dirs[0] / "eval"
    )
    out = Path(options.get("out") or default_out)
    episodes = int(options["episodes"]) if options.get("episodes") is not None else 4
    if episodes < 1:
        raise CharctlError(f"-k must be >= 1 episode, got {episodes}")
    needs_policy = any(options.get(m) for m in ("dtw", "confusion", "switch", "switch_matrix", "survival", "fidelity"))
    runs = [load_eval_run(d, device, checkpoint) for d in run_dirs] if needs_policy else []
    switch_run = check_mode_arguments(runs, options)  # every argument checked before anything is written
    out.mkdir(parents=True, exist_ok=True)
    append_report(
        out,
        None,
        None,
        None,
        command="charctl eval " + " ".join(shlex.quote(a) for a in sys.argv[2:])
        if sys.argv and sys.argv[0].endswith("charctl")
        else None,
    )
    if options.get("curves"):
        eval_curves(run_dirs, out)
    if options.get("survival"):
        eval_survival(runs, episodes, float(options["survival"]), out)
    if options.get("dtw"):
        eval_dtw(runs, episodes, out)
    if options.get("confusion"):
        eval_confusion(next(t for t in runs if t.agent.conditional), episodes, out)
    if options.get("fidelity"):
        from charctl.experiments.cgail.fidelity import eval_fidelity

        eval_fidelity(runs, episodes, out)
    if switch_run is not None and options.get("switch"):
        a, b = options["switch"]
        eval_switch(switch_run, a, b, max(episodes, 2), out)
    if switch_run is not None and options.get("switch_matrix"):
        eval_switch_matrix(switch_run, max(episodes, 2), out)
    print(f"results in {out}/ (report.md)")


def check_mode_arguments(runs: list[DeviceRun], options: dict) -> DeviceRun | None:
    """One-line CharctlError for a mode the loaded runs cannot serve (--confusion / --switch without a
    conditional run, a --switch skill a run does not have), before any output is written. Returns the
    run --switch and --switch-matrix study (the first conditional one), or None without either."""
    conditional = next((t for t in runs if t.agent.conditional), None)
    if options.get("confusion") and conditional is None:
        raise CharctlError("--confusion needs a conditional (cGAIL) run")
    if not options.get("switch") and not options.get("switch_matrix"):
        return None
    if conditional is None:
        mode = "--switch" if options.get("switch") else "--switch-matrix"
        raise CharctlError(f"{mode} needs a conditional (cGAIL) run")
    for name in options.get("switch") or ():
        conditional.skill_index(name)
    return conditional
