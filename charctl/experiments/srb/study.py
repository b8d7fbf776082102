"""`charctl eval SRB_RUN [CGAIL_RUN] --push` and `charctl export SRB_RUN --video`.

The push study runs the protocol of push.py on the trained SRB policy (batched: every case x trial
is one environment of one SRBEnv, stepped together) and, when a cgail run is given (second run
directory or push.baseline_run=DIR) and charctl.experiments.cgail.push exists, on the full-body
baseline through `make_push_simulator(run_dir)`.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.experiments.srb import fastmath as F
from charctl.experiments.srb.push import (
    PushCase, PushTable, comparison_markdown, iter_chunks, make_cases, plot_comparison, run_push_study, save_tables, window_fraction,
)

CHUNK = 512  # push episodes stepped together per SRBEnv


# ---------------------------------------------------------------------------- the SRB side of the protocol
def zero_actions(model, obs: np.ndarray) -> np.ndarray:
    """The 'no policy' ablation: feet at the reference placement, no velocity offsets (QP + PD only)."""
    return np.zeros((obs.shape[0], 10))


def srb_push_batch(run, jobs: list[tuple[PushCase, int]], record: bool = False, zero_action: bool = False) -> list[bool] | tuple[list[bool], dict]:
    """Survival of the trained SRB policy for every (case, seed): deterministic policy, episode from
    reference frame 0 with a seed-drawn perturbation of the initial velocities (push.init_noise).
    `zero_action` replaces the policy by zero actions (what the QP tracker alone achieves)."""
    from charctl.experiments.srb.env import SRBEnv
    from charctl.experiments.srb.trainer import load_policy, policy_actions

    agent, _ = load_policy(run)
    act = zero_actions if zero_action else policy_actions
    cfg = run.cfg
    results: list[bool] = []
    traces = None
    proto = SRBEnv(cfg, 1, seed=0, auto_reset=False)
    for chunk in iter_chunks(jobs, CHUNK):
        env = SRBEnv(cfg, len(chunk), seed=0, reference=proto.ref, body=proto.body, auto_reset=False, max_steps=10**9)
        survived, traces = _simulate_chunk(env, agent.model, chunk, float(cfg.push.init_noise), act, record)
        results.extend(survived.tolist())
    return (results, traces) if record else results


def _simulate_chunk(env, model, chunk, init_noise: float, act, record: bool, seconds: float | None = None):
    """Step one SRBEnv whose environment e runs chunk[e] = (case, seed); survived (n,) and, with
    `record`, the trajectory (then every environment runs `seconds` or the longest case in full)."""
    n = len(chunk)
    env.reset(frames=np.zeros(n, dtype=int))
    for e, (_, seed) in enumerate(chunk):
        rng = np.random.default_rng(seed)
        env.vel[e] += rng.normal(0.0, init_noise, 3)
        env.ang_vel[e] += rng.normal(0.0, init_noise, 3)
    force = np.array([c.force_n for c, _ in chunk])
    duration = np.array([c.duration_s for c, _ in chunk])
    phase = np.array([c.phase for c, _ in chunk])
    settle = np.array([c.settle_s for c, _ in chunk])
    observe = np.array([c.observe_s for c, _ in chunk])
    direction = np.radians([c.direction_deg for c, _ in chunk])
    start = np.full(n, np.inf)
    push_dir = np.zeros((n, 3))
    fallen = np.zeros(n, dtype=bool)
    dt, cycle = env.dt, env.ref.cycle
    steps = int(math.ceil((seconds if seconds else max(c.total_s for c, _ in chunk)) / dt)) + 1
    trace = {"pos": [], "rot": [], "feet": [], "stance": [], "forces": [], "push": []} if record else None
    obs = env.observe()
    for k in range(steps):
        t = k * dt
        u = env.frame / cycle
        if k > 0:  # the push opens at the first step after settle_s whose reference phase reached `phase`
            crossed = np.floor(u - phase) > np.floor(u_prev - phase)
            opening = ~np.isfinite(start) & (t >= settle) & (crossed | (np.abs((u - phase) % 1.0) < 1e-9))
            if opening.any():
                start[opening] = t
                a = F.yaw_of(env.rot) + direction
                push_dir[opening] = np.stack([np.cos(a), np.zeros_like(a), -np.sin(a)], axis=-1)[opening]
        u_prev = u
        frac = window_fraction(np.full(n, t), dt, start, duration)
        push = (force * frac)[:, None] * push_dir
        obs, _, terminal, _, _ = env.step(act(model, obs), push)
        fallen |= terminal & ~fallen & (t < start + duration + observe)
        if record:
            for key, val in (("pos", env.pos), ("rot", env.rot), ("feet", env.contact_points()), ("stance", env.stance),
                             ("forces", env.last_forces), ("push", push)):
                trace[key].append(np.array(val, copy=True))
        if not record and np.all(fallen | (t + dt >= start + duration + observe)):
            break
        if fallen.any() and not record:  # keep fallen bodies numerically tame; their outcome is recorded
            env.reset(np.flatnonzero(fallen), frames=env.frame[fallen])
            obs = env.observe()
    never = ~np.isfinite(start)  # the phase never came (cannot happen with settle + one cycle, kept honest)
    survived = ~fallen & ~never
    if record:
        trace = {k: np.stack(v) for k, v in trace.items()}
        trace["dt"] = dt
        trace["start"], trace["duration"] = start, duration
    return survived, trace


# ---------------------------------------------------------------------------- CLI entry points
def _resolve_targets(targets: list[str], overrides: list[str]) -> tuple[Path, str]:
    """(srb run dir, cgail run dir or '') from the positional targets."""
    from charctl.runs import latest_run, run_experiment

    srb_runs, other = [], []
    for t in targets:
        if t == "srb":
            srb_runs.append(latest_run("outputs", "srb"))
        elif Path(t).is_dir():
            (srb_runs if run_experiment(t) == "srb" else other).append(Path(t))
        else:
            raise CharctlError(f"{t!r} is neither a run directory nor 'srb'")
    if not srb_runs:
        raise CharctlError("give an srb run directory (or 'srb' for the latest one)")
    if len(srb_runs) > 1:
        raise CharctlError("give one srb run (and optionally one cgail run for the full-body baseline)")
    if len(other) > 1 or (other and run_experiment(other[0]) != "cgail"):
        raise CharctlError("the baseline must be one cgail run directory")
    return srb_runs[0], str(other[0]) if other else ""


def evaluate(targets: list[str], options: dict, overrides: list[str]) -> None:
    from charctl.experiments import unsupported_options

    unsupported_options("srb", options, {"push", "episodes", "out"})
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
    print(f"push study: {len(cases)} cases x {trials} trials on {run_dir}")
    t0 = time.perf_counter()
    srb = run_push_study(None, cases, trials, seed=int(cfg.seed), simulate_batch=lambda jobs: srb_push_batch(run, jobs), label="SRB")
    srb.meta = {"run": str(run_dir), "seconds": time.perf_counter() - t0}
    named: dict[str, PushTable | None] = {"srb": srb}
    labels = ["SRB (trained policy)"]
    if cfg.push.zero_action_column:
        named["srb_zero_action"] = run_push_study(None, cases, trials, seed=int(cfg.seed), label="SRB zero action",
                                                  simulate_batch=lambda jobs: srb_push_batch(run, jobs, zero_action=True))
        labels.append("SRB, zero action (QP + PD only)")
    full, note = _baseline_table(baseline, cases, trials, int(cfg.seed))
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
    (out_dir / "report.md").write_text(report)
    print(md)
    print(f"wrote {out_dir / 'report.md'}, push.md, push.png, push.json ({time.perf_counter() - t0:.0f} s)")


def find_baseline_run(output_root: Path) -> str:
    """The latest cgail run under `output_root` (any depth) that is the paper's kind of full-body
    baseline: AMP mode (cgail.conditional=false), the walk skill only, with a checkpoint; '' if none."""
    from charctl.runs import read_run_config

    runs = [p.parent for p in output_root.glob("**/cgail/*/config.yaml")]
    for d in sorted(runs, key=lambda p: p.name, reverse=True):
        if not (d / "checkpoints" / "last.pt").is_file():
            continue
        try:
            c = read_run_config(d)
        except CharctlError:
            continue
        cg, skills = c.get("cgail") or {}, list(c.get("use_skills") or [])
        if not cg.get("conditional", True) and skills == ["walk"]:
            return str(d)
    return ""


def _baseline_label(baseline: str) -> str:
    if not baseline:
        return "full body (cgail walk)"
    from charctl.runs import read_run_config

    c = read_run_config(baseline)
    mode = "cGAIL" if (c.get("cgail") or {}).get("conditional", True) else "AMP"
    return f"full body ({mode} walk, {Path(baseline).name})"


def _baseline_table(baseline: str, cases, trials: int, seed: int) -> tuple[PushTable | None, str]:
    if not baseline:
        return None, "no cgail run given (or none found for push.baseline_run=auto: an AMP walk run, cgail.conditional=false use_skills=[walk])"
    try:
        from charctl.experiments.cgail.push import make_push_simulator
    except ImportError:
        return None, "charctl.experiments.cgail.push is not available in this version"
    t0 = time.perf_counter()
    table = run_push_study(make_push_simulator(baseline), cases, trials, seed=seed, label="full body")
    table.meta = {"run": baseline, "seconds": time.perf_counter() - t0}
    return table, ""


def _report(run, cfg, srb: PushTable, full: PushTable | None, md: str, note: str, trials: int) -> str:
    metrics_path = run.dir / "metrics.json"
    m = json.loads(metrics_path.read_text()) if metrics_path.is_file() else {}
    lines = [f"# srb reproduction report\n\nrun: `{run.dir}` (scale={cfg.scale}, seed={cfg.seed})\n\n## Training\n\n"]
    if m:
        lines.append(f"- samples: {m.get('samples', 0):,} in {m.get('wall_s', float('nan')):.0f} s of training "
                     f"({m.get('samples', 0) / max(m.get('wall_s', 1e-9), 1e-9):,.0f} samples/s; rollout alone "
                     f"{m.get('rollout_samples_per_s', float('nan')):,.0f} samples/s)\n")
        lines.append(f"- final mean episode length {m.get('episode_length', float('nan')):.1f} steps (limit {cfg.termination.max_steps}), "
                     f"reward per step {m.get('reward_per_step_last25', m.get('reward_per_step', float('nan'))):.2f} "
                     f"(mean of the last 25 iterations where recorded; max {cfg.reward.w_stand:g})\n")
        lines.append("- curves: `training_curve.png` (episode length and reward per step against samples)\n\n![training](training_curve.png)\n")
    else:
        lines.append("- no metrics.json in the run (training interrupted?)\n")
    lines.append(f"\n## Push study (paper §9, Table 1)\n\nK = {trials} trials per case; directions {list(cfg.push.directions)} deg, "
                 f"phases {list(cfg.push.phases)}; 'impulse' = force held {cfg.push.impulse_duration:g} s; settle {cfg.push.settle:g} s, "
                 f"observe {cfg.push.observe:g} s. SRB study took {srb.meta.get('seconds', 0):.0f} s.\n")
    lines.append("Rows: 'no push' = the same episodes unpushed (a simulator that falls there has no robustness to "
                 "measure); a cell pools every direction, phase and trial. Columns: the trained SRB policy; the same SRB "
                 "with zero actions (QP + PD tracker alone, what the policy adds); the full-body baseline.\n")
    if full is None:
        lines.append(f"\n**Full-body baseline missing**: {note}.\n")
    else:
        lines.append(f"\nFull-body baseline: `{full.meta.get('run')}` ({full.meta.get('seconds', 0):.0f} s for its trials).\n")
    lines.append(md)
    lines.append("\n![push](push.png)\n")
    return "".join(lines)


def export(target: str, options: dict, overrides: list[str]) -> None:
    from charctl.experiments import unsupported_options

    unsupported_options("srb", options, {"video", "seconds"})
    if not options.get("video"):
        raise CharctlError("srb exports --video (the box, its feet and contact forces walking and being pushed)")
    from charctl.experiments.srb.config import Config
    from charctl.experiments.srb.render import render_push_video
    from charctl.runs import latest_run, open_run

    run_dir = latest_run("outputs", "srb") if target == "srb" else Path(target)
    run = open_run(run_dir, Config, overrides)
    seconds = float(options.get("seconds") or 6.0)
    if seconds <= 0:
        raise CharctlError("--seconds must be positive")
    info = render_push_video(run, options["video"], seconds)
    print(f"wrote {options['video']} ({info['frames']} frames, pushes: {info['pushes']})")
