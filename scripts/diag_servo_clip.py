"""Can the humanoid's PD servos follow a clip's arms? Right-wrist error when the joints servo to the clip.

    .venv/bin/python scripts/diag_servo_clip.py [--clips dance_a,spinkick,walk] [--loops 3] [--shoulder-frame parent]

Each control step (30 Hz) the root is put at the clip's pose and velocity, then every hinge's PD target is held at
the clip's next frame (the hinge angles as stored, each in (-pi, pi]) for the physics substeps (150 Hz, armature
0.05: the small preset's). No policy and no feedforward: the servo's own lag. Prints, per clip, the mean right-wrist
error (m, relative to the root) of each loop, the largest, and the largest |hinge angle| the right shoulder reached
(beyond pi: a hinge wound a turn away from every stored frame's angle). A diagnostic for spindance (docs/cgail.md,
"Spindance"), not a target.
"""

from __future__ import annotations

import argparse

import numpy as np


def servo(clip_name: str, loops: int, shoulder_frame: str) -> tuple[np.ndarray, float]:
    """(loops,) mean right-wrist errors (m) and the right shoulder's largest |hinge angle| (rad)."""
    import mujoco

    from charctl.motion.library import load_clip
    from charctl.sim.batch import BatchedHumanoid, SimSettings
    from charctl.sim.humanoid import clip_to_qpos_qvel, layout

    clip = load_clip(clip_name).resample(30.0)
    qpos, qvel = clip_to_qpos_qvel(clip, shoulder_frame)
    period = len(qpos) - 1 if clip.loop else len(qpos)
    sim = BatchedHumanoid(1, SimSettings(physics_hz=150.0, armature=0.05, shoulder_frame=shoulder_frame))
    model, data = sim.model, mujoco.MjData(sim.model)
    root, wrist = sim.model.body("root").id, sim.model.body("right_wrist").id
    shoulder = layout().qpos_slices["right_shoulder"]
    sim.set_state(np.arange(1), qpos[:1], qvel[:1])
    errors, widest = [], 0.0
    for step in range(loops * period):
        now, nxt = step % period, (step + 1) % period
        q, v = sim.qpos.copy(), sim.qvel.copy()
        q[:, :7], v[:, :6] = qpos[now, :7], qvel[now, :6]
        sim.set_state(np.arange(1), q, v)
        sim.step(qpos[nxt : nxt + 1, 7:])
        data.qpos[:] = qpos[nxt]
        mujoco.mj_kinematics(model, data)
        ref = data.xpos[wrist] - data.xpos[root]
        errors.append(np.linalg.norm(sim.xpos[0, wrist] - sim.xpos[0, root] - ref))
        widest = max(widest, float(np.abs(sim.qpos[0, shoulder]).max()))
    return np.asarray(errors).reshape(loops, period), widest


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clips", default="dance_a,spinkick,dance_b,kick,walk")
    ap.add_argument("--loops", type=int, default=3)
    ap.add_argument("--shoulder-frame", default="parent", choices=["parent", "rotated"])
    args = ap.parse_args()
    if args.loops < 1:
        raise SystemExit("error: --loops must be >= 1")
    from charctl.errors import CharctlError

    for name in [c for c in args.clips.split(",") if c]:
        try:
            err, widest = servo(name, args.loops, args.shoulder_frame)
        except CharctlError as exc:
            raise SystemExit(f"error: {exc}") from None
        loops = " ".join(f"{e:.3f}" for e in err.mean(axis=1))
        print(
            f"{name:10s} {args.shoulder_frame:8s} right-wrist error per loop (m): {loops}; largest {err.max():.3f}; "
            f"right shoulder's largest |hinge| {widest:.2f} rad"
        )


if __name__ == "__main__":
    main()
