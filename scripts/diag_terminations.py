"""Why do a cgail policy's episodes end under its training rules? Per skill, ends per 1000 control steps by cause.

    .venv/bin/python scripts/diag_terminations.py RUN [--skills spindance,breakdance] [--envs 32] [--steps 300]

Rolls `--envs` envs per skill, each commanded with the skill (mean actions, training's random start frames and
headings, no switches), under the run's own training rules (pose threshold and its radii, the goal-reference
window), and splits every episode end by what ended it:

- `fall`: a non-foot body touched the ground (or the simulation blew up);
- `effector`: the pose check, a hand or foot farther than the pose threshold from the reference (m, relative to
  the root in the heading frame); `worst` names the end effector that was farthest at those ends;
- `root`: the pose check, the root height off by more than reward.root_height_threshold;
- `heading`: the pose check, neither of those: the heading gained on the timed reference passed
  reward.yaw_error_threshold;
- `len`: the mean episode length in control steps of the episodes that ended (the 30-Hz steps from a reset);
- `where`: the 5 reference frames (of the timed reference: the clip frame the env scores against) in which a
  step most often ended by the pose check, and that share of the steps taken there.

The low-style termination (reward.low_style_threshold) is applied by the training rollout, not the env, and is
not counted here. A diagnostic for the skills the ten-skill runs do not learn (spindance, breakdance), not a target.
"""

from __future__ import annotations

import argparse

import numpy as np

EFFECTORS = ("R foot", "L foot", "R hand", "L hand")  # rules.pose_keys' order (skeleton.END_EFFECTORS: ankles, wrists)


def measure(run, skill: int, envs: int, steps: int) -> dict[str, float | str]:
    """The figures of the module docstring for one skill."""
    import torch

    from charctl.experiments.cgail.drive import policy_steps
    from charctl.experiments.cgail.env_rules import env_rules
    from charctl.experiments.cgail.rules import pose_keys

    torch.manual_seed(0)
    threshold = float(run.cfg.reward.pose_error_threshold)
    env = run.make_env(envs, rules=env_rules(run.cfg.reward, tracking=False, reference_reward=True), switch_prob=0.0)
    env.forced_command = np.full(envs, skill)
    env.reset(np.arange(envs))
    counts = {"fall": 0, "effector": 0, "root": 0, "heading": 0}
    worst = np.zeros(len(EFFECTORS), dtype=int)
    lengths: list[np.ndarray] = []
    frames = int(env.clip_frames[skill])
    visits, pose_ends = np.zeros(frames, dtype=int), np.zeros(frames, dtype=int)
    for step in policy_steps(run.agent, env, steps, before_step=lambda t: (env.steps.copy(), env.ref_frame.copy())):
        res = step.result
        steps_before, frame = step.before
        lengths.append(steps_before[res.terminated] + 1)
        np.add.at(visits, frame, 1)
        np.add.at(pose_ends, frame[res.pose_ended], 1)
        counts["fall"] += int((res.terminated & ~res.pose_ended).sum())
        ended = np.flatnonzero(res.pose_ended)
        if ended.size:
            keys, ref = pose_keys(res.pair_next[ended]), pose_keys(res.pose_reference[ended])
            dist = np.linalg.norm((keys[:, 1:] - ref[:, 1:]).reshape(-1, 4, 3), axis=-1)  # (n, 4) m
            root = np.abs(keys[:, 0] - ref[:, 0]) * env.root_scale
            by_effector = dist.max(axis=1) > threshold
            by_root = ~by_effector & (root > threshold)
            counts["effector"] += int(by_effector.sum())
            counts["root"] += int(by_root.sum())
            counts["heading"] += int((~by_effector & ~by_root).sum())
            np.add.at(worst, dist[by_effector].argmax(axis=1), 1)
    per_1k = {k: 1000.0 * v / (envs * steps) for k, v in counts.items()}
    ended_lengths = np.concatenate(lengths)
    return {
        "where": _worst_frames(visits, pose_ends),
        **per_1k,
        "worst": EFFECTORS[int(worst.argmax())] if worst.any() else "-",
        "len": float(ended_lengths.mean()) if ended_lengths.size else float("nan"),
    }


def _worst_frames(visits: np.ndarray, ends: np.ndarray, width: int = 5) -> str:
    """'a-b (share)': the `width` consecutive frames with the highest share of visited steps that ended there."""
    if not ends.any():
        return "-"
    kernel = np.ones(width, dtype=int)
    v, e = np.convolve(visits, kernel, "valid"), np.convolve(ends, kernel, "valid")
    share = e / np.maximum(v, 1)
    a = int(share.argmax())
    return f"{a}-{a + width - 1} ({share[a]:.2f})"


def main() -> None:
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.rollouts import load_eval_run

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run")
    ap.add_argument("--skills", default="", help="comma-separated skills (default: all of the run's)")
    ap.add_argument("--envs", type=int, default=32)
    ap.add_argument("--steps", type=int, default=300, help="control steps (30 Hz)")
    args = ap.parse_args()
    if args.envs < 1 or args.steps < 1:
        raise SystemExit("error: --envs and --steps must be >= 1")
    run = load_eval_run(args.run, device="cpu")
    try:  # the run's own one-line error for a skill it does not have
        wanted = [run.skill_index(s) for s in args.skills.split(",") if s] or range(len(run.skill_names))
    except CharctlError as exc:
        raise SystemExit(f"error: {exc}") from None
    if float(run.cfg.reward.pose_error_threshold) <= 0:
        raise SystemExit("error: this run has no pose check (reward.pose_error_threshold is 0)")
    print(f"{args.run}: {args.envs} envs x {args.steps} steps per skill; ends per 1000 steps")
    print(f"{'skill':12s} {'fall':>6s} {'effector':>9s} {'root':>6s} {'heading':>8s} {'worst':>7s} {'len':>6s}  where")
    for skill in wanted:
        name, m = run.skill_names[skill], measure(run, skill, args.envs, args.steps)
        print(
            f"{name:12s} {m['fall']:6.1f} {m['effector']:9.1f} {m['root']:6.1f} {m['heading']:8.1f} "
            f"{m['worst']:>7s} {m['len']:6.1f}  {m['where']}"
        )


if __name__ == "__main__":
    main()
