"""How much does a skill's tracking reward still pay along its clip, and which body part is off?

    .venv/bin/python scripts/diag_track_parts.py RUN [--skill right_kick] [--every 3] [--checkpoint F]

One env, the skill held from its clip's frame 0 (RSI, heading 0), mean actions, evaluation rules (falls only), one
pass of the clip. At each control step t the disc observation is compared with the clip's frame t (its timed
reference): the summed squared rot6 error of each body part (`PARTS`: torso = chest + neck, each leg = hip + knee +
ankle, each arm = shoulder + elbow), each hand's distance (m), r_track (`rules.tracking_reward`, DeepMimic's form),
its pose term exp(-sum) and, beside it, the mean over the parts of exp(-part error). Prints every `--every`-th step
and the means over the pass. The pose term is one exponential of the summed error: at 2-4 off in sum (the ten-skill
kick's middle) it pays ~0.05 whatever one part does (docs/cgail.md, "Per-part tracking reward", where a per-part
form was tried). A diagnostic, not a target.
"""

from __future__ import annotations

import argparse

import numpy as np

PARTS = {  # body part -> its clip joints (the bodies whose rotations the disc observation holds)
    "torso": ("chest", "neck"),
    "right leg": ("right_hip", "right_knee", "right_ankle"),
    "right arm": ("right_shoulder", "right_elbow"),
    "left leg": ("left_hip", "left_knee", "left_ankle"),
    "left arm": ("left_shoulder", "left_elbow"),
}


def part_errors(obs: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((N, 5) summed squared rot6 error per body part (`PARTS`), (N, 4) end-effector distances (m; right foot,
    left foot, right hand, left hand)) between disc observations `obs` and `ref` (N, 133)."""
    from charctl.experiments.cgail import rules
    from charctl.motion.skeleton import load_skeleton

    skel = load_skeleton()
    joints = [skel.names[b] for b in skel.clip_joint_bodies]  # the order of the 12 rot6 blocks
    member = np.array([[j in names for names in PARTS.values()] for j in joints], dtype=float)  # (12, 5)
    sq = ((obs[:, rules.OBS_ROT] - ref[:, rules.OBS_ROT]) ** 2).reshape(len(obs), 12, 6).sum(axis=-1)
    ee = np.linalg.norm((obs[:, rules.OBS_EE] - ref[:, rules.OBS_EE]).reshape(len(obs), 4, 3), axis=-1)
    return sq @ member, ee


def one_pass(run, k: int) -> dict[str, np.ndarray]:
    """Per control step of one pass of skill `k`'s clip from frame 0: `parts` (T, 5), `ee` (T, 4) and r_track (T,)
    against the clip's frame t (step t = 1 .. clip length - 1), `alive` (T,)."""
    from charctl.experiments.cgail.drive import policy_steps
    from charctl.experiments.cgail.rules import tracking_reward

    clip = run.agent.skills[k].obs  # (L, 133) the clip's disc observations at the control rate
    env = run.held_env([k], len(clip) / float(run.cfg.env.control_hz) + 1.0, seed=7)
    rows: dict[str, list] = {"parts": [], "ee": [], "r_track": [], "alive": []}
    alive = True
    for step in policy_steps(run.agent, env, len(clip) - 1):
        alive = alive and not bool(step.result.terminated[0])
        obs, ref = np.asarray(env.obs[:1]), clip[step.t + 1][None]
        parts, ee = part_errors(obs, ref)
        rows["parts"].append(parts[0])
        rows["ee"].append(ee[0])
        rows["r_track"].append(float(tracking_reward(obs, ref)[0]))
        rows["alive"].append(alive)
    return {key: np.asarray(v) for key, v in rows.items()}


def main() -> None:
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.rollouts import load_eval_run

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run")
    ap.add_argument("--skill", default="right_kick")
    ap.add_argument("--every", type=int, default=3, help="print every n-th control step")
    ap.add_argument("--checkpoint", default=None, help="a file in RUN/checkpoints (default: last.pt)")
    args = ap.parse_args()
    if args.every < 1:
        raise SystemExit("error: --every must be >= 1")
    try:
        run = load_eval_run(args.run, device="cpu", checkpoint=args.checkpoint)
        k = run.skill_index(args.skill)
    except CharctlError as exc:
        raise SystemExit(f"error: {exc}") from None
    out = one_pass(run, k)
    n = len(out["r_track"])
    print(f"{args.skill}, one pass from frame 0 ({n} steps); per part summed squared rot6 error")
    print(
        "step  "
        + " ".join(f"{p:>9s}" for p in PARTS)
        + " |  sum | hands R/L (m) | r_track | exp(-sum) | mean exp(-part)"
    )
    for t in range(args.every - 1, n, args.every):
        p, e = out["parts"][t], out["ee"][t]
        print(
            f"{t + 1:4d}  " + " ".join(f"{x:9.2f}" for x in p) + f" | {p.sum():4.2f} | {e[2]:.2f} / {e[3]:.2f}"
            f"   | {out['r_track'][t]:7.2f} | {np.exp(-p.sum()):9.2f} | {np.exp(-p).mean():.2f}"
            + ("" if out["alive"][t] else "  (fallen)")
        )
    p = out["parts"]
    print("mean  " + " ".join(f"{x:9.2f}" for x in p.mean(axis=0)) + f" | {p.sum(axis=1).mean():4.2f} |")
    print(
        f"mean r_track {out['r_track'].mean():.3f}; pose term exp(-sum) {np.exp(-p.sum(axis=1)).mean():.3f}, "
        f"mean exp(-part) {np.exp(-p).mean():.3f}"
    )


if __name__ == "__main__":
    main()
