"""Print each shoulder's hinge-chain frame R0 (charctl.sim.humanoid.SHOULDER_FRAMES["rotated"]).

    .venv/bin/python scripts/choose_shoulder_frames.py [--candidates 4000]

A shoulder is a chain of three hinges in EULER_ORDER (XYZ: R = Rx Ry Rz), singular where the middle angle is +-90
deg; near there the first and third hinges must turn fast for a slow arm. Each shoulder's chain can work in a frame
R0 (R = R0 E R0^-1). Of the identity and `--candidates` random rotations (seed 1), this prints, per shoulder, the
frame that keeps the middle angle farthest from +-90 deg over the ten paper skills' clips (walk, run, jump, dance_a,
dance_b, spinkick, punch and kick with their mirrors, at 30 Hz), with that worst middle angle under the identity and
under the chosen frame, and the fastest hinge of dance_a (rad/s) under each.
"""

from __future__ import annotations

import argparse

import numpy as np

CLIPS = ("walk", "run", "jump", "dance_a", "dance_b", "spinkick", "punch", "punch:mirror", "kick", "kick:mirror")


def worst_middle_deg(frame, rotations) -> float:
    """Largest |middle angle| (deg) of the XYZ chain over `rotations` in `frame`."""
    return float(np.degrees(np.abs((frame.inv() * rotations * frame).as_euler("XYZ")[:, 1])).max())


def fastest_hinge(frame, rotations, hz: float = 30.0) -> float:
    """Largest hinge rate (rad/s) of the chain along a clip's frames."""
    angles = np.unwrap((frame.inv() * rotations * frame).as_euler("XYZ"), axis=0)
    return float(np.abs(np.diff(angles, axis=0)).max() * hz)


def main() -> None:
    from scipy.spatial.transform import Rotation

    from charctl.motion.library import load_clip
    from charctl.motion.skeleton import load_skeleton

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--candidates", type=int, default=4000)
    args = ap.parse_args()
    if args.candidates < 0:
        raise SystemExit("error: --candidates must be >= 0")
    skel = load_skeleton()
    clips = {c: load_clip(c).resample(30.0) for c in CLIPS}
    frames = Rotation.concatenate([Rotation.identity(), Rotation.random(args.candidates, random_state=1)])
    for joint in ("right_shoulder", "left_shoulder"):
        b = skel.index(joint)
        rotations = Rotation.from_quat(np.concatenate([c.local_rot[:, b] for c in clips.values()]))
        scores = np.array([worst_middle_deg(frames[i], rotations) for i in range(len(frames))])
        best = frames[int(scores.argmin())]
        dance = Rotation.from_quat(clips["dance_a"].local_rot[:, b])
        print(
            f"{joint}: R0 (xyzw) {np.round(best.as_quat(), 4).tolist()}; worst middle angle {scores[0]:.1f} deg "
            f"(parent axes) -> {scores.min():.1f} deg; dance_a's fastest hinge "
            f"{fastest_hinge(frames[0], dance):.1f} -> {fastest_hinge(best, dance):.1f} rad/s"
        )


if __name__ == "__main__":
    main()
