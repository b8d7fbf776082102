"""The training rules a cgail env enforces, read from the run's `reward` config in one place.

`CgailEnv` takes these as keyword arguments; training (`train.CgailLearner`) and the
diagnostic scripts that replay a run under its training rules (`scripts/diag_terminations.py`,
`scripts/diag_goal_reference.py`) build them here, so a new termination or reference knob is wired once; both envs
apply the pose check through `env_reference_check`.
Evaluation envs (`policy.TrainedRun.make_env` without `rules`, `fidelity`) take none of them: they judge a
policy by its falls only; the diagnostic scripts pass these to `make_env`.
"""

from __future__ import annotations

from typing import Any

from charctl.experiments.cgail.rules import reference_check


def env_rules(reward, **overrides: Any) -> dict[str, Any]:
    """Env keyword arguments for the reward config `reward` (a `Config.reward` node), `overrides` replacing
    single entries (a diagnostic that varies one rule). Units: thresholds in m (pose, root height) and rad
    (yaw), grace in control steps, the window in clip frames (0: the closest frame anywhere)."""
    rules = dict(
        tracking=str(reward.kind) == "tracking",
        pose_error_threshold=float(reward.pose_error_threshold),
        pose_error_grace_steps=int(reward.pose_error_grace_steps),
        root_height_threshold=float(reward.root_height_threshold),
        yaw_error_threshold=float(reward.yaw_error_threshold),
        goal_reference_window=int(reward.goal_reference_window),
        reference_reward=float(reward.w_track) > 0 or any(float(v) > 0 for v in reward.w_track_skills.values()),
    )
    unknown = set(overrides) - set(rules)
    if unknown:
        raise TypeError(f"env_rules: not a rule: {', '.join(sorted(unknown))}")
    return {**rules, **overrides}


def env_reference_check(
    env: Any, pair_next: Any, ref: Any, r_track: Any, fell: Any, unstable: Any
) -> tuple[Any, Any, Any]:
    """One step's pose-error check of the env (`env.CgailEnv`, numpy or torch;
    reward.pose_error_threshold, `rules.reference_check`) on its own arrays: (r_track with the tracking reward where
    the reference is checked, (N,) bool ended by the check, (N, 133) the reference each env was scored against);
    updates `env.yaw_err`."""
    err, scored = env._pose_error(pair_next, ref)
    per_env = (env.yaw_err, env.ref_active, env.ref_grace, env.has_goal[env.cmd], fell, unstable)
    rule = dict(threshold=env.pose_threshold, yaw_error_scale=env.yaw_scale, dt=1.0 / env.cfg.control_hz)
    r_track, pose_ended, _, env.yaw_err = reference_check(
        err, scored, pair_next, ref, r_track, *per_env, **rule, reference_reward=env.reference_reward
    )
    return r_track, pose_ended, scored
