"""Throughput of the batched humanoid simulator vs raw mj_step, measured in one run.

    .venv/bin/python scripts/bench_sim.py [--envs 64] [--seconds 3] [--sweep]

Prints control steps/s of BatchedHumanoid (PD targets held over the substeps) at the default
rates, raw `mj_step` physics steps/s of the same model on one MjData, and their ratio in
physics steps. `--sweep` also runs the physics-rate stability sweep behind the default rate:
RSI from the walk clip, PD-tracking of the clip for 2 s with noisy targets, at 120..1200 Hz, and
with more joint armature (kg m^2 per hinge) at the low rates.
"""

from __future__ import annotations

import argparse
import time

from charctl.sim import CONTROL_HZ, JOINT_ARMATURE, PHYSICS_HZ


def raw_mj_step(physics_hz: float, seconds: float) -> float:
    import mujoco

    from charctl.motion.library import load_clip
    from charctl.sim.humanoid import clip_to_qpos_qvel, load_model

    m = load_model(physics_hz)
    d = mujoco.MjData(m)
    qpos, qvel = clip_to_qpos_qvel(load_clip("walk"))
    d.qpos[:], d.qvel[:] = qpos[0], qvel[0]
    d.ctrl[:] = qpos[0, 7:]
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        for _ in range(100):
            mujoco.mj_step(m, d)
        n += 100
        if n % 2000 == 0:
            d.qpos[:], d.qvel[:] = qpos[0], qvel[0]
    return n / (time.perf_counter() - t0)


def batched(
    envs: int,
    physics_hz: float,
    control_hz: float,
    seconds: float,
    noise: float = 0.0,
    seed: int = 0,
    armature: float = JOINT_ARMATURE,
):
    """(control steps/s, blow-ups, mean tracking error rad, substeps) of `seconds` of noisy clip tracking."""
    from charctl.sim.batch import BatchedHumanoid, SimSettings
    from charctl.sim.tracking import track_clip_with_noise

    sim = BatchedHumanoid(envs, SimSettings(physics_hz=physics_hz, control_hz=control_hz, armature=armature))
    r = track_clip_with_noise(sim, noise=noise, max_seconds=seconds, episode_steps=int(2 * control_hz), seed=seed)
    return r.control_steps * envs / r.seconds, r.blowups, r.mean_error, sim.substeps


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--envs", type=int, default=64)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--physics-hz", type=float, default=PHYSICS_HZ)
    ap.add_argument("--control-hz", type=float, default=CONTROL_HZ)
    ap.add_argument("--sweep", action="store_true")
    a = ap.parse_args()
    raw = raw_mj_step(a.physics_hz, a.seconds)
    ctrl, unstable, _, sub = batched(a.envs, a.physics_hz, a.control_hz, a.seconds)
    print(f"raw mj_step (1 MjData, 1 thread):        {raw:12,.0f} physics steps/s")
    print(
        f"BatchedHumanoid ({a.envs} envs, {a.physics_hz:.0f}/{a.control_hz:.0f} "
        f"Hz): {ctrl:12,.0f} control steps/s = {ctrl * sub:,.0f} physics steps/s"
    )
    print(f"ratio batched/raw (physics steps):        {ctrl * sub / raw:12.2f}x   (unstable resets: {unstable})")
    if a.sweep:
        print("\nphysics-rate sweep (64 envs, PD tracking of walk with 0.1 rad target noise, 2 s episodes):")
        print(
            f"{'physics Hz':>10} {'armature':>8} {'substeps':>8} {'ctrl steps/s':>13} {'blow-ups':>8} "
            f"{'mean |q - q_ref| rad':>21}"
        )
        rows = [(hz, JOINT_ARMATURE) for hz in (120.0, 150.0, 240.0, 300.0, 480.0, 600.0, 1200.0)]
        rows += [(120.0, 0.05), (150.0, 0.05), (150.0, 0.1), (300.0, 0.05)]  # the small preset: 150 Hz, 0.05
        for hz, arm in rows:
            rate, bad, err, sub = batched(64, hz, a.control_hz, a.seconds, noise=0.1, armature=arm)
            print(f"{hz:10.0f} {arm:8.2f} {sub:8d} {rate:13,.0f} {bad:8d} {err:21.4f}")


if __name__ == "__main__":
    main()
