"""PD tracking of a clip with noisy targets: the physics-rate stability check.

Used by scripts/bench_sim.py --sweep (the table behind PHYSICS_HZ / JOINT_ARMATURE) and by
tests/test_sim.py (150 Hz needs the larger armature).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from charctl.sim.batch import BatchedHumanoid


@dataclass
class TrackingResult:
    control_steps: int  # control steps run (each over all envs)
    seconds: float  # wall time of the stepping loop
    blowups: int  # envs reset by the simulator's blow-up detection
    mean_error: float  # mean |q - q_ref| over actuated joints, envs and steps (rad)


def track_clip_with_noise(
    sim: BatchedHumanoid,
    clip_name: str = "walk",
    noise: float = 0.1,
    max_steps: int | None = None,
    max_seconds: float | None = None,
    episode_steps: int = 60,
    seed: int = 0,
) -> TrackingResult:
    """From the clip's first frame, hold PD targets = the clip's joint angles + `noise` rad Gaussian
    noise, frame by frame at the control rate; every env restarts after `episode_steps` control
    steps. Stops after `max_steps` control steps or `max_seconds` of wall time, whichever is first."""
    from charctl.motion.library import load_clip
    from charctl.sim.humanoid import clip_to_qpos_qvel

    if max_steps is None and max_seconds is None:
        raise ValueError("give max_steps or max_seconds")
    clip = load_clip(clip_name).resample(sim.settings.control_hz)
    qpos, qvel = clip_to_qpos_qvel(clip)
    ids = np.arange(sim.num_envs)
    first = np.zeros(sim.num_envs, dtype=int)
    sim.reset_fn = lambda idx: sim.set_state(idx, qpos[first[: len(idx)]], qvel[first[: len(idx)]])
    sim.reset_fn(ids)
    rng, errors = np.random.default_rng(seed), []
    start, k = time.perf_counter(), 0
    while (max_steps is None or k < max_steps) and (max_seconds is None or time.perf_counter() - start < max_seconds):
        ref = qpos[k % len(qpos), 7:]
        sim.step(ref + noise * rng.standard_normal((sim.num_envs, ref.shape[0])))
        errors.append(np.abs(sim.qpos[:, 7:] - ref).mean())
        k += 1
        if k % episode_steps == 0:
            sim.reset_fn(ids)
    return TrackingResult(k, time.perf_counter() - start, sim.unstable_count, float(np.mean(errors)))
