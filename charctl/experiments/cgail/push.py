"""Push trials on a trained cgail walk policy: the full-body baseline of the srb push study.

`make_push_simulator(run_dir)` returns `simulate(case, seed) -> survived` following the
protocol of charctl.experiments.srb.push.PushCase: the character starts from walk frame 0
(RSI, heading +x), walks `settle_s + phase * cycle_s` seconds, a constant horizontal force of
`force_n` newtons acts on the root (pelvis) body for `duration_s` seconds (applied per physics
substep, so windows shorter than a control step deliver exactly force x duration), in the
direction `direction_deg` of the heading frame at push onset (0 forward, 90 left), and the
trial survives if no fall (a non-foot body touching the ground) happens before `observe_s`
after the window closes. The seed sets the env's random generator only.

This module is cgail's `push_rollout` capability (charctl.experiments.PushRollout), declared in
the package's EXPERIMENT: the srb push study reaches it through the registry, never by import.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.experiments.cgail.config import method_label
from charctl.experiments.cgail.drive import ForceSchedule, policy_steps
from charctl.experiments.cgail.env import CgailEnv
from charctl.experiments.cgail.policy import load_trained_run
from charctl.motion import rotations as R


def make_push_simulator(run_dir: str | Path, skill: str = "walk") -> Callable[[object, int], bool]:
    """`simulate(case, seed) -> survived` of the run's `skill` policy (the module docstring's protocol)."""
    tr = load_trained_run(run_dir)
    if skill not in tr.skill_names:
        raise CharctlError(
            f"{run_dir} has no {skill!r} skill (skills: {', '.join(tr.skill_names)}); train one with use_skills=[walk]"
        )
    k = tr.skill_index(skill)

    def simulate(case, seed: int) -> bool:
        env = tr.held_env([k], 1e6, seed=int(seed))
        _, end = push_window(case)
        steps = int(np.ceil((end + case.observe_s) * env.cfg.control_hz))
        for step in policy_steps(tr.agent, env, steps, force=push_schedule(env, case)):
            if step.result.terminated[0]:
                return False
        return True

    return simulate


def push_window(case) -> tuple[float, float]:
    """(start, end) s after the reset of the push of `case`: settle_s + phase * cycle_s, plus duration_s."""
    start = case.settle_s + case.phase * case.cycle_s
    return start, start + case.duration_s


def push_schedule(env: CgailEnv, case) -> ForceSchedule:
    """The `force` schedule of `case` for `drive.policy_steps` on a one-character env: (wrench (1, nbody, 6),
    physics substeps) for control step t. A control step [t / hz, (t + 1) / hz) s that overlaps the push
    window pushes the root (pelvis) with `force_n` newtons, horizontally along `direction_deg` of the heading
    at the first such step (then fixed in the world); other steps get (None, 0)."""
    hz = env.cfg.control_hz
    sub_dt = 1.0 / env.cfg.physics_hz
    start, end = push_window(case)
    root = env.sim.body_ids[0]
    force = np.zeros((1, env.sim.model.nbody, 6))
    direction = None

    def force_at(step: int) -> tuple[np.ndarray | None, int]:
        nonlocal direction
        t0 = step / hz
        t1 = t0 + 1.0 / hz
        if not (t1 > start and t0 < end):
            return None, 0
        if direction is None:  # fixed in the world at the push onset
            a = R.yaw_about_y(env.sim.body_quat_xyzw[0, 0]) + np.radians(case.direction_deg)
            direction = np.array([np.cos(a), 0.0, -np.sin(a)])
        # physics substeps of this control step inside the window; the onset is quantised
        # to the control step, the length to the physics substep (round(duration / dt))
        n_sub = max(1, int(round((min(t1, end) - max(t0, start)) / sub_dt)))
        force[0, root, :3] = case.force_n * direction
        return force, n_sub

    return force_at


def find_baseline_run(output_root: Path) -> str:
    """The latest cgail run under `output_root` (any depth) that is the paper's kind of full-body
    baseline: AMP mode (cgail.conditional=false), the walk skill only, with a checkpoint; '' if none."""
    from charctl.runs import read_run_config

    runs = [p.parent for p in Path(output_root).glob("**/cgail/*/config.yaml")]
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


def baseline_label(run_dir: str) -> str:
    """'full body (<method> walk, <run>)', the method as `config.method_label` names it (AMP, cGAIL, ...)."""
    from charctl.runs import read_run_config

    return f"full body ({method_label(read_run_config(run_dir))} walk, {Path(run_dir).name})"
