"""Does a cgail policy walk its heading-goal clip's whole gait cycle? (docs/cgail.md, "Walk: a reference that moves on")

    .venv/bin/python scripts/diag_goal_reference.py RUN [--skill walk] [--envs 32] [--steps 300] [--window 3]

A heading-goal skill (walk, run) is scored by the pose check and the tracking reward (reward.w_track) against
a clip frame picked from the policy's own pose. This rolls `--envs` envs commanded with the skill (mean
actions, random start frames, no switches) under the run's own training rules (pose threshold, its radii,
the tracking reward) and reports, per picking rule (the closest frame anywhere: window 0; the closest of
`--window` frames from the reference advanced one step):

- `advance`: the picked frame's mean move along the clip per control step (clip frames; a policy walking
  the clip's cadence moves about 1, a shuffle that stays on a few frames about 0);
- `visited`: the share of the clip's frames ever picked after the first second;
- `r_track`: the mean tracking reward (in [0, 1]) against the picked frames where the reference is checked;
- `pose ends`: episodes ended by the pose check per 1000 control steps.

A diagnostic for the shuffle seen in the ten-skill radii run (its walk's picked frame did not advance),
not a target.
"""

from __future__ import annotations

import argparse

import numpy as np


def measure(run, skill: int, envs: int, steps: int, window: int) -> dict[str, float]:
    """The four figures of the module docstring for one picking rule (`window` 0: the closest frame anywhere)."""
    import torch

    from charctl.experiments.cgail.drive import policy_steps
    from charctl.experiments.cgail.env_rules import env_rules
    from charctl.experiments.cgail.rules import pose_key_error, pose_keys

    torch.manual_seed(0)
    r = run.cfg.reward
    rules = env_rules(
        r,
        tracking=False,
        pose_error_threshold=max(float(r.pose_error_threshold), 0.5),
        goal_reference_window=window,
        reference_reward=True,
    )
    env = run.make_env(envs, rules=rules, switch_prob=0.0, episode_seconds=20.0)
    env.forced_command = np.full(envs, skill)
    env.reset(np.arange(envs))
    clip_keys = pose_keys(env.skills[skill].obs)[None]  # (1, T, 13)
    period = max(int(env.clip_frames[skill]) - 1, 1)
    warmup = int(env.cfg.control_hz)  # one second
    prev, moves, visited = env.ref_frame.copy(), [], np.zeros(period, dtype=bool)
    r_track, pose_ends = [], 0
    for step in policy_steps(run.agent, env, steps):
        res = step.result
        if window:  # the env moves its reference on from the matched frame
            frame = env.ref_frame.copy()
        else:  # the env keeps the timed frame; the frame it scored against is the closest anywhere
            frame = pose_key_error(pose_keys(res.pair_next)[:, None], clip_keys, env.root_scale).argmin(axis=1)
        if step.t >= warmup:
            live = ~(res.terminated | res.truncated)  # reset envs start elsewhere: no move to count
            d = (frame - prev) % period
            d = np.where(d > period // 2, d - period, d)
            moves.append(d[live])
            visited[frame[live] % period] = True
            r_track.append(res.r_track.mean())
            pose_ends += int(res.pose_ended.sum())
        prev = frame
    counted = (steps - warmup) * envs
    return {
        "advance": float(np.concatenate(moves).mean()),
        "visited": float(visited.mean()),
        "r_track": float(np.mean(r_track)),
        "pose_ends_per_1k": 1000.0 * pose_ends / counted,
    }


def main() -> None:
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.rollouts import load_eval_run

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run")
    ap.add_argument("--skill", default="walk", help="a skill with a heading goal (walk, run)")
    ap.add_argument("--envs", type=int, default=32)
    ap.add_argument("--steps", type=int, default=300, help="control steps (30 Hz)")
    ap.add_argument("--window", type=int, default=3, help="reward.goal_reference_window to compare with 0")
    args = ap.parse_args()
    if min(args.envs, args.steps, args.window) < 1:
        raise SystemExit("error: --envs, --steps and --window must be >= 1")
    run = load_eval_run(args.run, device="cpu")
    try:  # the run's own one-line error for a skill it does not have
        skill = run.skill_index(args.skill)
    except CharctlError as exc:
        raise SystemExit(f"error: {exc}") from None
    if not run.agent.skills[skill].heading_goal:
        raise SystemExit(f"error: skill {args.skill!r} has no heading goal (it is scored against its timed frame)")
    print(f"{args.run} {args.skill}: {args.envs} envs x {args.steps} steps")
    print(f"{'picking rule':24s} {'advance':>8s} {'visited':>8s} {'r_track':>8s} {'pose ends/1k':>13s}")
    for window in (0, args.window):
        m = measure(run, skill, args.envs, args.steps, window)
        rule = "closest anywhere" if window == 0 else f"window {window}"
        print(f"{rule:24s} {m['advance']:8.2f} {m['visited']:8.2f} {m['r_track']:8.3f} {m['pose_ends_per_1k']:13.1f}")


if __name__ == "__main__":
    main()
