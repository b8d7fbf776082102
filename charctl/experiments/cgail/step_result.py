"""What one control step of a cgail environment returns, the same for both backends."""

from __future__ import annotations

from dataclasses import dataclass

from charctl.motion.array_compat import Array


@dataclass
class StepResult:
    """One control step of all N envs: numpy arrays from `env.CgailEnv` over C MuJoCo, tensors on the simulation device
    from the torch form (`env.CgailDeviceEnv`)."""

    state: Array  # (N, state_dim) next policy state (after resets)
    obs: Array  # (N, 133) next disc obs (after resets)
    pair_next: Array  # (N, 133) o_t+1 of the transition just taken (before resets)
    final_state: Array  # (N, state_dim) s_t+1 before resets (for truncation bootstrapping)
    r_goal: Array  # (N,)
    r_track: Array  # (N,) tracking reward against the reference at the new phase (0 when not tracking)
    terminated: Array  # (N,) bool: fall, blow-up or a large pose error
    truncated: Array  # (N,) bool: time limit, or the end of a non-looping clip for the tracking baseline
    unstable: Array  # (N,) bool: simulator blow-up this step
    pose_ended: Array | None = None  # (N,) bool: ended by a large pose error (part of `terminated`, not a fall)
    # (N, 133) the reference disc obs the pose check compared `pair_next` with (before resets): the timed frame,
    # or the closest clip frame for heading-goal skills; None where the env has no pose check
    pose_reference: Array | None = None
