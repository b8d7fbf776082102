"""Pins of a shipped policy: what it computes on fixed simulator states, so a change to the features,
the normaliser, the simulator or the networks that keeps every shape still fails a test
(tests/test_pretrained_pins.py; regenerate with `python scripts/pin_pretrained.py pretrained/NAME`).

For each skill: RSI at clip frames 0 and the clip's middle, heading 0, command held; the pin holds the
policy state s (243 or 245 values) at reset, the mean action there, and the state after
`PIN_STEPS` control steps of mean actions (so the physics and the feature code are pinned together).
`pin_actions` gives the mean actions on stored states (the normaliser and networks pinned apart from the
features), `stay_up_rollout` a short rollout of every skill that the test checks for falls and root height.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from charctl.experiments.cgail.policy import TrainedRun

PIN_FILE = "pin.npz"
PIN_STEPS = 10
STAY_UP_SECONDS = 2.0  # stay_up_rollout: 60 control steps at 30 Hz


def compute_pins(run_dir: str | Path) -> dict[str, np.ndarray]:
    """{"skills", "start_frames", "state0" (K*2, S), "action0" (K*2, 28), "state_after" (K*2, S)} of
    the policy in `run_dir` (a run or a pretrained folder)."""
    from charctl.experiments.cgail.drive import policy_steps
    from charctl.experiments.cgail.policy import load_trained_run

    tr = load_trained_run(run_dir)
    K = len(tr.agent.skills)
    frames = np.array([[0, len(s.qpos) // 2] for s in tr.agent.skills]).reshape(-1)
    env = tr.make_env(2 * K, seed=0, switch_prob=0.0, episode_seconds=60.0)
    env.forced_command = pin_commands(K)
    env.random_yaw = False
    env.reset(np.arange(2 * K))
    # per-env start frames: reset each pair of envs from its own frames
    for i, f in enumerate(frames):
        env.start_frame = int(f)
        env.reset(np.array([i]))
    env.start_frame = None
    state0 = env.state.copy()
    action0 = tr.mean_action(env)
    for _ in policy_steps(tr.agent, env, PIN_STEPS):
        pass
    return {
        "skills": np.array(tr.skill_names),
        "start_frames": frames,
        "state0": state0,
        "action0": action0,
        "state_after": env.state.copy(),
    }


def pin_commands(K: int) -> np.ndarray:
    """(K*2,) the command of each pinned state: skill k at rows 2k (clip frame 0) and 2k + 1 (the middle)."""
    return np.repeat(np.arange(K), 2)


def pin_actions(tr: TrainedRun, states: np.ndarray) -> np.ndarray:
    """(K*2, 28) mean actions of `tr`'s policy on given policy states (K*2, S), e.g. a pin's stored state0,
    with the pins' held commands (`pin_commands`, a one-hot blend): the normaliser and networks alone, no
    simulator or feature code."""
    from types import SimpleNamespace

    from charctl.experiments.cgail.drive import mean_action

    K = len(tr.agent.skills)
    blend = np.eye(K)[pin_commands(K)]
    assert len(states) == len(blend), f"{len(states)} states for {K} skills ({len(blend)} expected)"
    # drive.mean_action reads only the env's state and its command blend
    return mean_action(tr.agent, SimpleNamespace(state=np.asarray(states), command_blend=lambda: blend))


def stay_up_rollout(tr: TrainedRun, seconds: float = STAY_UP_SECONDS) -> dict[str, np.ndarray]:
    """`seconds` of control of every skill of `tr` at once, one env per skill, as the fidelity evaluation
    starts them (fidelity._make_env): the skill commanded and held, RSI at the clip's frame 0, heading 0,
    mean actions (`drive.policy_steps`). An episode that ends by a non-looping clip's end (the tracking
    baseline truncates there) restarts at frame 0 and goes on. Returns {"skills", "terminated" (K,) bool: a
    fall (a non-foot body on the ground) or a simulator blow-up ended an episode, "unstable" (K,) bool:
    a blow-up, "min_root_height" (K,) m: the lowest root height at any control step, "clip_min_root_height"
    (K,) m: each skill's clip's lowest}."""
    from charctl.experiments.cgail.drive import policy_steps

    K = len(tr.agent.skills)
    env = tr.held_env(np.arange(K), 60.0)
    terminated = np.zeros(K, dtype=bool)
    unstable = np.zeros(K, dtype=bool)
    low = env.sim.qpos[:, 1].copy()  # y is up; qpos[:, :3] is the root position
    for step in policy_steps(tr.agent, env, int(round(seconds * env.cfg.control_hz))):
        terminated |= step.result.terminated
        unstable |= step.result.unstable
        # after the step's resets: a terminated env's last height is lost, but it failed already
        low = np.minimum(low, env.sim.qpos[:, 1])
    return {
        "skills": np.array(tr.skill_names),
        "terminated": terminated,
        "unstable": unstable,
        "min_root_height": low,
        "clip_min_root_height": np.array([s.qpos[:, 1].min() for s in tr.agent.skills]),
    }


def write_pins(run_dir: str | Path) -> Path:
    path = Path(run_dir) / PIN_FILE
    np.savez_compressed(path, **compute_pins(run_dir))
    return path
