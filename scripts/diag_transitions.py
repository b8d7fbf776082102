"""After a command switch, does the character leave the old skill? Per second: the higher foot's peak and the root's
horizontal speed, for each ordered pair of the run's skills (or the pairs given).

    .venv/bin/python scripts/diag_transitions.py RUN [--pairs walk:right_kick run:right_kick ...]
                                                [--before 2] [--after 6]

One rollout per pair as `charctl export RUN --commands "A:0,B:BEFORE"` makes it (deterministic mean actions, RSI in
A's clip at frame 0, the env's command ramp after the switch), the bodies by the shared forward kinematics of the
recorded qpos (`qpos_to_local_rot` and `motion.fk`, as `--bvh` and the fidelity references; y-up world). Each row:
the seconds after the switch, "foot m / speed m/s" per second, and the falls. The policy holding each skill (from
its clip's frame 0) is printed first, for scale. A diagnostic for the switches the targets do not measure
(docs/cgail.md, "The late-switch command at seeds 1 and 2"), not a target: `charctl eval RUN --switch-matrix` is
the measured study.
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np


def per_second(values: np.ndarray, hz: float, reduce=np.max) -> np.ndarray:
    """(S,) `reduce` of `values` (T,) over each whole second of frames at `hz` (a trailing part second is dropped)."""
    n = int(hz)
    whole = len(values) // n
    return reduce(values[: whole * n].reshape(whole, n), axis=1)


def horizontal_speed(qpos: np.ndarray, hz: float) -> np.ndarray:
    """(S,) mean horizontal root speed (m/s) per whole second: the x-z distance from each second's first frame to the
    next second's first frame (qpos (T, nq), the free root's position in qpos[:, 0:3], y up)."""
    n = int(hz)
    starts = qpos[::n, [0, 2]]
    return np.linalg.norm(np.diff(starts, axis=0), axis=1)[: (len(qpos) - 1) // n]


def foot_heights(qpos: np.ndarray, shoulder_frame) -> np.ndarray:
    """(T,) the higher of the two ankle bodies' heights (m, world y) per frame of `qpos` (T, nq)."""
    from charctl.motion.fk import forward_kinematics
    from charctl.motion.skeleton import BODY_NAMES, FEET, load_skeleton
    from charctl.sim.humanoid import qpos_to_local_rot

    root, rot = qpos_to_local_rot(qpos, shoulder_frame)
    pos, _ = forward_kinematics(load_skeleton(), root, rot)
    return pos[:, [BODY_NAMES.index(f) for f in FEET], 1].max(axis=1)


def transition(tr, a: int, b: int, before: float, after: float) -> dict:
    """One rollout: skill `a` from its clip's frame 0, `b` commanded at `before` s, watched `after` s more."""
    from charctl.experiments.cgail.export import schedule_rollout

    qpos, stats = schedule_rollout(tr, [(0.0, a), (before, b)], before + after)
    hz = stats["fps"]
    cut = int(round(before * hz))
    tail = qpos[cut:]
    return {
        "foot": per_second(foot_heights(tail, tr.cfg.env.shoulder_frame), hz),
        "speed": horizontal_speed(tail, hz),
        "falls": stats["falls"],
    }


def main() -> None:
    from charctl.experiments.cgail.policy import load_trained_run

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", help="a cgail run folder or pretrained/ policy")
    parser.add_argument("--pairs", nargs="*", default=None, help="A:B skill pairs (default: every ordered pair)")
    parser.add_argument("--before", type=float, default=2.0, help="seconds of A before B is commanded")
    parser.add_argument("--after", type=float, default=6.0, help="seconds watched after the switch")
    args = parser.parse_args()
    tr = load_trained_run(args.run)
    names = tr.skill_names
    pairs = [p.split(":") for p in args.pairs] if args.pairs else list(itertools.permutations(names, 2))
    bad = [":".join(p) for p in pairs if len(p) != 2 or not set(p) <= set(names)]
    if bad:
        parser.error(f"--pairs takes A:B of the run's skills ({', '.join(names)}), not: {', '.join(bad)}")
    if args.before <= 0 or args.after < 1:
        parser.error("--before must be > 0 and --after >= 1 (seconds)")
    print(f"{args.run}: B commanded {args.before:g} s after A's clip frame 0; per second after: foot m / speed m/s")
    for name in names:  # the skill held: what B looks like when done
        held = transition(tr, names.index(name), names.index(name), 1.0, 3.0)
        print(f"  {name} held: " + " ".join(f"{f:.2f}/{s:.2f}" for f, s in zip(held["foot"], held["speed"])))
    for a, b in pairs:
        res = transition(tr, names.index(a), names.index(b), args.before, args.after)
        cells = " ".join(f"{f:.2f}/{s:.2f}" for f, s in zip(res["foot"], res["speed"]))
        print(f"  {a} -> {b}: {cells}  falls {res['falls']}")


if __name__ == "__main__":
    main()
