"""Does a command switch A -> B survive the run's training rules? When and why its episodes end.

    .venv/bin/python scripts/diag_switch.py RUN [--from walk] [--to right_kick] [--envs 32] [--switch-step 30]
                                               [--seconds 8]

`--envs` envs start at A's first frame (heading 0), are commanded A, and at control step `--switch-step` are
switched to B with the run's ramp (env.ramp_frames) — the switch study's protocol (`charctl eval RUN --switch A B`),
but under the run's *training* rules (the pose check with its radii, as `scripts/diag_terminations.py`), so the
ends show what training does with such an episode. During the ramp the pose check is off; when the ramp ends B's
reference starts at its frame 0 and is unchecked for its grace steps (rules.restart_after_ramp). Prints how many
envs ended by the pose check and by a fall, and when, in control steps after the ramp's end (30 Hz): an episode
that always ends there before B's motion is due (the right kick's chamber is at ~20 frames) never trains the
transition. A diagnostic for the ten-skill policy's walk -> right_kick switch (docs/cgail.md), not a target.
"""

from __future__ import annotations

import argparse

import numpy as np


def measure(run, ka: int, kb: int, envs: int, switch_step: int, steps: int) -> dict[str, np.ndarray | int]:
    """`envs` rollouts of A then B (module docstring). Returns `end_step` (envs,) the control step (from the
    reset, 0-based) at which each env's episode ended, -1 if it did not; `pose_end` (envs,) bool, ended by the
    pose check; `ramp_end` the step at which the ramp ends (switch_step + env.ramp_frames); `grace` the steps
    B's reference goes unchecked after it."""
    import torch

    from charctl.experiments.cgail.drive import policy_steps
    from charctl.experiments.cgail.env_rules import env_rules
    from charctl.experiments.cgail.rollouts import switch_at

    torch.manual_seed(0)
    rules = env_rules(run.cfg.reward, tracking=False, reference_reward=True)
    env = run.held_env(np.full(envs, ka), steps / run.cfg.env.control_hz + 1, seed=7, rules=rules)
    switch = switch_at(env, kb, switch_step, int(run.cfg.env.ramp_frames))  # the switch study's own switch

    alive = np.ones(envs, dtype=bool)
    end_step = np.full(envs, -1)
    pose_end = np.zeros(envs, dtype=bool)
    for step in policy_steps(run.agent, env, steps, before_step=switch):
        res = step.result
        ended = res.terminated & alive
        end_step[ended] = step.t
        pose_end |= ended & res.pose_ended
        alive &= ~res.terminated
        if not alive.any():
            break
    return {
        "end_step": end_step,
        "pose_end": pose_end,
        "ramp_end": switch_step + int(run.cfg.env.ramp_frames),
        "grace": int(env.pose_grace),
    }


def _summary(after: np.ndarray) -> str:
    """'n (median m, a..b)' of steps after the ramp's end."""
    if after.size == 0:
        return "0"
    return f"{after.size} (steps after the ramp's end: median {np.median(after):.0f}, {after.min()}..{after.max()})"


def main() -> None:
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.rollouts import load_eval_run

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run")
    ap.add_argument("--from", dest="skill_a", default="walk", help="skill before the switch")
    ap.add_argument("--to", dest="skill_b", default="right_kick", help="skill after the switch")
    ap.add_argument("--envs", type=int, default=32)
    ap.add_argument("--switch-step", type=int, default=30, help="control step of the switch (30 Hz)")
    ap.add_argument("--seconds", type=float, default=8.0, help="length of each rollout")
    args = ap.parse_args()
    if args.envs < 1 or args.switch_step < 0 or args.seconds <= 0:
        raise SystemExit("error: --envs must be >= 1, --switch-step >= 0 and --seconds > 0")
    run = load_eval_run(args.run, device="cpu")
    steps = int(round(args.seconds * run.cfg.env.control_hz))
    if steps <= args.switch_step:
        raise SystemExit(f"error: --seconds {args.seconds:g} ends before the switch at step {args.switch_step}")
    try:  # the run's own one-line error for a skill it does not have
        ka, kb = run.skill_index(args.skill_a), run.skill_index(args.skill_b)
    except CharctlError as exc:
        raise SystemExit(f"error: {exc}") from None
    if float(run.cfg.reward.pose_error_threshold) <= 0:
        raise SystemExit("error: this run has no pose check (reward.pose_error_threshold is 0)")
    m = measure(run, ka, kb, args.envs, args.switch_step, steps)
    ended, after = m["end_step"] >= 0, m["end_step"] - m["ramp_end"]
    print(
        f"{args.run}: {args.skill_a} -> {args.skill_b} at step {args.switch_step}, ramp ends at step "
        f"{m['ramp_end']}, then {m['grace']} grace steps; {args.envs} envs x {args.seconds:g} s, training rules"
    )
    print(f"  ended by the pose check: {_summary(after[ended & m['pose_end']])}")
    print(f"  ended by a fall:         {_summary(after[ended & ~m['pose_end']])}")
    print(f"  still up at the end:     {int((~ended).sum())}")


if __name__ == "__main__":
    main()
