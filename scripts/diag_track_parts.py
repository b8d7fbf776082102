"""How much does a skill's tracking reward still pay along its clip, whole and per body part?

    .venv/bin/python scripts/diag_track_parts.py RUN [--skill right_kick] [--every 3] [--checkpoint F]

One env, the skill held from its clip's frame 0 (RSI, heading 0), mean actions, evaluation rules (falls only), one
pass of the clip. At each control step t the disc observation is compared with the clip's frame t (its timed
reference): the summed squared rot6 error of each body part (torso = chest + neck, each leg = hip + knee + ankle, each
arm = shoulder + elbow; rad^2-like, `rules.TRACK_PART_ENDS`), each end effector's distance (m), and r_track in
DeepMimic's whole form and in the per-part form (`rules.tracking_reward`, reward.track_form). Prints every
`--every`-th step and the means over the pass. In the whole form one exponential of the summed error pays ~0 once
the pose is 2-4 off in sum, whatever one part does; the per-part form keeps each part's term (docs/cgail.md,
"Per-part tracking reward"). A diagnostic, not a target.
"""

from __future__ import annotations

import argparse

import numpy as np

PARTS = ("torso", "right leg", "right arm", "left leg", "left arm")
EFFECTORS = ("right foot", "left foot", "right hand", "left hand")


def part_errors(obs: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((N, 5) summed squared rot6 error per body part (`PARTS`), (N, 4) end-effector distances (m, `EFFECTORS`))
    between disc observations `obs` and `ref` (N, 133)."""
    from charctl.experiments.cgail import rules

    sq = ((obs[:, rules.OBS_ROT] - ref[:, rules.OBS_ROT]) ** 2).reshape(len(obs), 12, 6).sum(axis=-1)
    parts = sq @ np.asarray(rules._part_matrix(rules.TRACK_PART_ENDS))
    ee = np.linalg.norm((obs[:, rules.OBS_EE] - ref[:, rules.OBS_EE]).reshape(len(obs), 4, 3), axis=-1)
    return parts, ee


def one_pass(run, k: int) -> dict[str, np.ndarray]:
    """Per control step of one pass of skill `k`'s clip from frame 0: `parts` (T, 5), `ee` (T, 4), `whole` and
    `per_part` r_track (T,) against the clip's frame t (step t = 1 .. clip length - 1), `alive` (T,)."""
    from charctl.experiments.cgail.drive import policy_steps
    from charctl.experiments.cgail.rules import tracking_reward

    clip = run.agent.skills[k].obs  # (L, 133) the clip's disc observations at the control rate
    env = run.make_env(1, seed=7, switch_prob=0.0, episode_seconds=len(clip) / float(run.cfg.env.control_hz) + 1.0)
    env.forced_command = np.full(1, k)
    env.start_frame, env.random_yaw = 0, False
    env.reset(np.arange(1))
    rows: dict[str, list] = {"parts": [], "ee": [], "whole": [], "per_part": [], "alive": []}
    alive = True
    for step in policy_steps(run.agent, env, len(clip) - 1):
        alive = alive and not bool(step.result.terminated[0])
        obs, ref = np.asarray(env.obs[:1]), clip[step.t + 1][None]
        parts, ee = part_errors(obs, ref)
        rows["parts"].append(parts[0])
        rows["ee"].append(ee[0])
        rows["whole"].append(float(tracking_reward(obs, ref)[0]))
        rows["per_part"].append(float(tracking_reward(obs, ref, per_part=True)[0]))
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
    print(f"{args.skill}, one pass from frame 0 ({len(out['whole'])} steps); per part summed squared rot6 error")
    print("step  " + " ".join(f"{p:>9s}" for p in PARTS) + " |  sum | hands R/L (m) | r whole / per part")
    for t in range(args.every - 1, len(out["whole"]), args.every):
        p, e = out["parts"][t], out["ee"][t]
        print(
            f"{t + 1:4d}  " + " ".join(f"{x:9.2f}" for x in p) + f" | {p.sum():4.2f} | {e[2]:.2f} / {e[3]:.2f}"
            f"     | {out['whole'][t]:.2f} / {out['per_part'][t]:.2f}" + ("" if out["alive"][t] else "  (fallen)")
        )
    p = out["parts"].mean(axis=0)
    print("mean  " + " ".join(f"{x:9.2f}" for x in p) + f" | {p.sum():4.2f} |")
    print(f"mean r_track: whole {out['whole'].mean():.3f}, per part {out['per_part'].mean():.3f}")


if __name__ == "__main__":
    main()
