"""How a cgail policy's flight phases compare with its clips', measured three ways (docs/cgail.md, "Flight").

    .venv/bin/python scripts/diag_flight.py RUN [-k 2]

Per skill, the share of frames (clip: one loop of a looping clip, from the middle of three; policy: -k
5-s episodes at the clip's frame 0, mean actions, as `charctl eval --fidelity` records them):

- `feet > 5 cm`: the fidelity signature's `airborne` (both foot soles 5 cm above standing: the floor for
  the policy, the clip's own 10th-percentile sole height for the clip, whose feet sink up to 7 cm);
- `ballistic`: the root's vertical acceleration below -0.7 g (finite differences at the control rate):
  the body falls freely, as it does in flight, but also in a quick drop into a crouch;
- `both`: feet > 5 cm and ballistic; `feet > 2 cm and ballistic` the same with a 2-cm margin;
- `touchdowns/s`: how often a foot's sole comes down to within 2 cm of standing (the cadence, both feet), and
  `flight s`: the mean length of the stretches with both soles more than 2 cm up (s).

A clip whose stance feet sink (the run's by up to 4 cm) reads long flights against its 10th-percentile ground;
a simulated foot on the floor reads 0, so the last two columns say whether a policy steps at the clip's rate.

A diagnostic for the airborne signature (the clip's sunk stance feet can count as "airborne"), not a
target: a policy that drops into a crouch without leaving the ground scores on `ballistic` alone.
"""

from __future__ import annotations

import argparse

import numpy as np

G = 9.81
BALLISTIC = 0.7  # fraction of g
LOW_MARGIN = 0.02  # m: a sole this far above standing is off the ground for the 2-cm columns and the step timing


def tile_loop(pos: np.ndarray, rot: np.ndarray, loop: bool) -> tuple[np.ndarray, np.ndarray]:
    """A looping clip three times over (so finite differences and flights see the wrap), else as given."""
    reps = 3 if loop else 1
    return np.concatenate([pos] * reps), np.concatenate([rot] * reps)


def flight_shares(pos: np.ndarray, rot: np.ndarray, dt: float, ground: float, loop: bool) -> tuple[float, ...]:
    """(feet > 5 cm, ballistic, both, feet > 2 cm and ballistic) shares of the frames of one sequence
    (`pos` (T, 15, 3), `rot` (T, 15, 4) world; `ground` the standing sole height)."""
    from charctl.eval.fidelity import AIRBORNE_MARGIN as UP
    from charctl.eval.fidelity import foot_sole_heights

    pos, rot = tile_loop(pos, rot, loop)  # a loop is scored on the middle of its three copies
    sole = foot_sole_heights(pos, rot).min(axis=1) - ground
    accel = np.gradient(np.gradient(pos[:, 0, 1], dt), dt)
    ballistic = accel < -BALLISTIC * G
    n = len(sole) // 3 if loop else 0
    keep = slice(n, 2 * n) if loop else slice(None)
    parts = (sole > UP, ballistic, (sole > UP) & ballistic, (sole > LOW_MARGIN) & ballistic)
    return tuple(float(p[keep].mean()) for p in parts)


def step_timing(pos: np.ndarray, rot: np.ndarray, dt: float, ground: float) -> tuple[float, float]:
    """(touchdowns per second over both feet, mean flight length in s) of one sequence: a touchdown is a
    frame where a foot's sole comes to within 2 cm of `ground` after being above it; a flight is a stretch
    of frames with both soles more than 2 cm up (0 when there is none)."""
    from charctl.eval.fidelity import foot_sole_heights

    sole = foot_sole_heights(pos, rot) - ground  # (T, 2)
    down = sole < LOW_MARGIN
    touchdowns = int(np.sum(down[1:] & ~down[:-1]))
    air = np.concatenate([[False], (~down).all(axis=1), [False]]).astype(np.int8)
    starts, ends = np.flatnonzero(np.diff(air) == 1), np.flatnonzero(np.diff(air) == -1)
    flight = float(np.mean(ends - starts)) * dt if len(starts) else 0.0
    return touchdowns / (len(sole) * dt), flight


def main() -> None:
    from charctl.experiments.cgail import fidelity as F
    from charctl.experiments.cgail.rollouts import load_eval_run

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run")
    ap.add_argument("-k", type=int, default=2, help="policy episodes per skill")
    args = ap.parse_args()
    run = load_eval_run(args.run, device="cpu")
    skills = run.agent.skills
    recs = F.record_rollouts(run, list(range(len(skills))), args.k, [5.0] * len(skills))
    print(f"{'skill':12s} {'':8s} feet>5cm ballistic both feet>2cm&ballistic touchdowns/s flight s")
    for skill, rec in zip(skills, recs):
        ref = F.clip_reference(skill)
        clip = flight_shares(ref.body_pos, ref.body_rot, ref.dt, ref.ground, ref.loop)
        clip += step_timing(*tile_loop(ref.body_pos, ref.body_rot, ref.loop), ref.dt, ref.ground)
        eps = []
        for e in range(args.k):
            pos, rot = rec.body_pos[e, : rec.lengths[e]], rec.body_rot[e, : rec.lengths[e]]
            eps.append(flight_shares(pos, rot, rec.dt, 0.0, False) + step_timing(pos, rot, rec.dt, 0.0))
        print(f"{skill.name:12s} {'clip':8s}", " ".join(f"{v:8.2f}" for v in clip))
        print(f"{'':12s} {'policy':8s}", " ".join(f"{v:8.2f}" for v in np.mean(eps, axis=0)))


if __name__ == "__main__":
    main()
