"""Where does a tracking policy's reward go? The four terms of its tracking reward, and the reward by time since start.

    .venv/bin/python scripts/diag_tracking_terms.py RUN [--checkpoint F] [--envs 32] [--steps 150]

Rolls `--envs` envs of a `reward.kind=tracking` run for `--steps` control steps (mean actions, training's random
start frames, the run's skills drawn as in training) and prints, over the steps of envs that did not just end, the
mean squared error and the mean value of each term of `rules.tracking_reward` (pose: joint rotations as rot6; body
velocities; end effectors; root height and velocity), the pose error per joint, and r_track by control steps since
the env's start (bins of 5). A diagnostic for spindance (docs/cgail.md, "Spindance"), not a target.
"""

from __future__ import annotations

import argparse

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run")
    ap.add_argument("--checkpoint", default=None, help="a file in RUN/checkpoints (default: last.pt)")
    ap.add_argument("--envs", type=int, default=32)
    ap.add_argument("--steps", type=int, default=150, help="control steps (30 Hz)")
    args = ap.parse_args()
    if args.envs < 1 or args.steps < 1:
        raise SystemExit("error: --envs and --steps must be >= 1")
    import torch

    from charctl.errors import CharctlError
    from charctl.experiments.cgail import rules
    from charctl.experiments.cgail.drive import policy_steps
    from charctl.experiments.cgail.rollouts import load_eval_run
    from charctl.motion.skeleton import load_skeleton

    try:
        run = load_eval_run(args.run, device="cpu", checkpoint=args.checkpoint)
    except CharctlError as exc:
        raise SystemExit(f"error: {exc}") from None
    if run.cfg.reward.kind != "tracking":
        raise SystemExit("error: not a tracking run (reward.kind is not tracking)")
    torch.manual_seed(0)
    env = run.make_env(args.envs, switch_prob=0.0)
    env.reset(np.arange(args.envs))
    k, parts = rules.TRACK_SCALES, {"pose": rules.OBS_ROT, "vel": rules.OBS_VEL, "ee": rules.OBS_EE}
    sq_sum: dict[str, list] = {name: [] for name in (*parts, "root height", "root velocity")}
    joints, by_step = [], {}
    for st in policy_steps(run.agent, env, args.steps, before_step=lambda t: env.steps.copy()):
        res = st.result
        for s, r in zip(st.before, np.asarray(res.r_track)):
            by_step.setdefault(min(int(s) // 5, 12), []).append(float(r))
        going = ~(res.terminated | res.truncated)
        obs, ref = np.asarray(res.pair_next)[going], env._reference_obs()[going]  # the reference the reward used
        for name, sl in (*parts.items(), ("root height", rules.OBS_ROOT_H), ("root velocity", rules.OBS_ROOT_V)):
            sq_sum[name].append(((obs[:, sl] - ref[:, sl]) ** 2).sum(axis=1))
        joints.append(((obs[:, rules.OBS_ROT] - ref[:, rules.OBS_ROT]) ** 2).reshape(-1, 12, 6).sum(axis=-1))
    sq = {name: np.concatenate(v) for name, v in sq_sum.items()}
    terms = {
        "pose": np.exp(-k["pose"] * sq["pose"]),
        "vel": np.exp(-k["vel"] * sq["vel"]),
        "ee": np.exp(-k["ee"] * sq["ee"]),
        "root": np.exp(-k["root_height"] * sq["root height"] - k["root_vel"] * sq["root velocity"]),
    }
    for name in sq:
        print(f"{name:14s} mean squared error {sq[name].mean():8.3f}")
    for name, value in terms.items():
        print(f"{name:14s} mean term {value.mean():.3f} (weight {rules.TRACK_WEIGHTS[name]})")
    skel = load_skeleton()
    per_joint = np.concatenate(joints).mean(axis=0)
    names = [skel.names[b] for b in skel.clip_joint_bodies]
    order = np.argsort(-per_joint)
    print("pose error per joint (rot6 squared): " + ", ".join(f"{names[i]} {per_joint[i]:.2f}" for i in order))
    print(
        "r_track by steps since the start: "
        + " ".join(f"{b * 5}+: {np.mean(v):.3f}" for b, v in sorted(by_step.items()))
    )


if __name__ == "__main__":
    main()
