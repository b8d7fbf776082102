"""Pins of a shipped policy: what it computes on fixed simulator states, so a change to the features,
the normaliser, the simulator or the networks that keeps every shape still fails a test
(tests/test_pretrained_pins.py; regenerate with `python scripts/pin_pretrained.py pretrained/NAME`).

For each skill: RSI at clip frames 0 and the clip's middle, heading 0, command held; the pin holds the
policy state s (243 or 245 values) at reset, the mean action there, and the state after
`PIN_STEPS` control steps of mean actions (so the physics and the feature code are pinned together).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

PIN_FILE = "pin.npz"
PIN_STEPS = 10


def compute_pins(run_dir: str | Path) -> dict[str, np.ndarray]:
    """{"skills", "start_frames", "state0" (K*2, S), "action0" (K*2, 28), "state_after" (K*2, S)} of
    the policy in `run_dir` (a run or a pretrained folder)."""
    from charctl.experiments.cgail.drive import policy_steps
    from charctl.experiments.cgail.policy import load_trained_run

    tr = load_trained_run(run_dir)
    K = len(tr.agent.skills)
    frames = np.array([[0, len(s.qpos) // 2] for s in tr.agent.skills]).reshape(-1)
    env = tr.make_env(2 * K, seed=0, switch_prob=0.0, episode_seconds=60.0)
    env.forced_command = np.repeat(np.arange(K), 2)
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


def write_pins(run_dir: str | Path) -> Path:
    path = Path(run_dir) / PIN_FILE
    np.savez_compressed(path, **compute_pins(run_dir))
    return path
