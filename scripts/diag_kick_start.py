"""Where does a kick start from? The skill's foot peak per pass of its clip, and how it depends on the start state.

    .venv/bin/python scripts/diag_kick_start.py RUN [--skill right_kick] [--envs 8] [--passes 3]
                                                [--checkpoint samples_N.pt]

Evaluation rules (falls only, mean actions), the skill held, every env started at its clip's frame 0 (RSI, heading 0).
Two tables:
- per pass of the clip (the timed reference restarts at frame 0 after the clip's last frame): the higher foot's peak
  (m, mean over the envs, against the clip's), how many envs reach 0.8 of the clip's peak, and at each restart the
  policy's distance from the clip's frame 0 (`rules.reference_pose_error`: the largest hand / foot / root-height
  distance, m) and its root height;
- the first pass from frame 0 with the RSI state changed: as recorded, velocities halved / zeroed, joint angles
  plus N(0, s) rad noise (each env its own draw; the root's position and orientation kept).
A diagnostic for the ten-skill policy's missing second kick and walk -> right_kick switch (docs/cgail.md, "It
kicks once"), not a target.
"""

from __future__ import annotations

import argparse

import numpy as np

from charctl.experiments.cgail.metrics import PERFORM_SHARE, clip_foot_peak, foot_peaks

START_VARIANTS = (  # (label, joint-angle noise std rad, velocity scale)
    ("as recorded", 0.0, 1.0),
    ("velocities x0.5", 0.0, 0.5),
    ("velocities zeroed", 0.0, 0.0),
    ("joints + N(0, 0.05)", 0.05, 1.0),
    ("joints + N(0, 0.1)", 0.1, 1.0),
    ("joints + N(0, 0.2)", 0.2, 1.0),
)


def perturbed_start(
    qpos: np.ndarray, qvel: np.ndarray, noise: float, vel_scale: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """A copy of an RSI state (`qpos` (nq,): root position 3 + quaternion 4, then hinge angles in rad; `qvel` (nv,))
    with N(0, `noise`) rad added to every hinge angle and every velocity times `vel_scale`."""
    q = qpos.copy()
    if noise > 0:
        q[7:] += rng.normal(0.0, noise, q[7:].shape)
    return q, qvel * vel_scale


def passes(run, k: int, envs: int, n_passes: int) -> list[dict]:
    """Per pass of skill `k`'s clip from frame 0: foot peaks (envs,), and at its start the pose distance (envs,) m
    from the clip's frame 0 and the root height (envs,) m. Envs that fell stop counting (`alive`)."""
    from charctl.experiments.cgail.drive import policy_steps
    from charctl.experiments.cgail.rules import reference_pose_error

    clip_len = len(run.agent.skills[k].obs)
    hz = float(run.cfg.env.control_hz)
    env = run.held_env(np.full(envs, k), n_passes * clip_len / hz + 1.0, seed=7)
    ref0 = np.broadcast_to(env.ref_obs[k, 0], env.obs.shape)
    out, pos, rot = [], [], []
    start = {"distance": reference_pose_error(env.obs, ref0), "root_height": env.obs[:, 0].copy()}
    alive = np.ones(envs, dtype=bool)
    for step in policy_steps(run.agent, env, n_passes * clip_len):
        alive &= ~step.result.terminated
        pos.append(env.sim.body_pos.copy())
        rot.append(env.sim.body_quat_xyzw.copy())
        if (step.t + 1) % clip_len == 0:  # the clip's last frame has been played: the next step restarts it
            out.append({**start, "foot_peak": foot_peaks(np.asarray(pos), np.asarray(rot), hz), "alive": alive.copy()})
            start = {"distance": reference_pose_error(env.obs, ref0), "root_height": env.obs[:, 0].copy()}
            pos, rot = [], []
    return out


def start_sensitivity(run, k: int, envs: int, seed: int = 0) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(label, foot peaks (envs,) m over the first pass, alive (envs,)) per `START_VARIANTS` entry."""
    from charctl.experiments.cgail.drive import policy_steps

    clip_len = len(run.agent.skills[k].obs)
    hz = float(run.cfg.env.control_hz)
    rows = []
    for label, noise, vel_scale in START_VARIANTS:
        env = run.held_env(np.full(envs, k), clip_len / hz + 1.0, seed=7)
        rng = np.random.default_rng(seed)
        q0, v0 = env.rsi_qpos[k, 0].copy(), env.rsi_qvel[k, 0].copy()
        for e in range(envs):  # one reset per env, each from its own perturbed frame-0 state
            env.rsi_qpos[k, 0], env.rsi_qvel[k, 0] = perturbed_start(q0, v0, noise, vel_scale, rng)
            env.reset(np.array([e]))
        env.rsi_qpos[k, 0], env.rsi_qvel[k, 0] = q0, v0
        pos, rot, alive = [], [], np.ones(envs, dtype=bool)
        for step in policy_steps(run.agent, env, clip_len):
            alive &= ~step.result.terminated
            pos.append(env.sim.body_pos.copy())
            rot.append(env.sim.body_quat_xyzw.copy())
        rows.append((label, foot_peaks(np.asarray(pos), np.asarray(rot), hz), alive))
    return rows


def main() -> None:
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.rollouts import load_eval_run

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run")
    ap.add_argument("--skill", default="right_kick")
    ap.add_argument("--envs", type=int, default=8)
    ap.add_argument("--passes", type=int, default=3, help="passes of the clip in the first table")
    ap.add_argument("--checkpoint", default=None, help="a file in RUN/checkpoints/ (default last.pt)")
    args = ap.parse_args()
    if args.envs < 1 or args.passes < 1:
        raise SystemExit("error: --envs and --passes must be >= 1")
    try:
        run = load_eval_run(args.run, device="cpu", checkpoint=args.checkpoint)
        k = run.skill_index(args.skill)
    except CharctlError as exc:
        raise SystemExit(f"error: {exc}") from None
    clip = clip_foot_peak(run.agent.skills[k])
    print(f"{args.run}: {args.skill} held from its clip's frame 0, {args.envs} envs; clip foot peak {clip:.2f} m")
    for i, p in enumerate(passes(run, k, args.envs, args.passes), 1):
        done = int(((p["foot_peak"] >= PERFORM_SHARE * clip) & p["alive"]).sum())
        print(
            f"  pass {i}: foot peak {p['foot_peak'].mean():.2f} m, kicked {done}/{args.envs}; at its start "
            f"{p['distance'].mean():.2f} m from frame 0, root {p['root_height'].mean():.3f} m "
            f"(clip {run.agent.skills[k].obs[0, 0]:.3f})"
        )
    print("  first pass from a changed start state:")
    for label, peak, alive in start_sensitivity(run, k, args.envs):
        done = int(((peak >= PERFORM_SHARE * clip) & alive).sum())
        print(f"    {label:20s} foot peak {peak.mean():.2f} m (min {peak.min():.2f}), kicked {done}/{args.envs}")


if __name__ == "__main__":
    main()
