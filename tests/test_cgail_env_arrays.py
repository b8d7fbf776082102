"""The cgail env's two array libraries (`env_arrays`): the numpy form draws its random numbers in the order the
numpy env always has (so seeded evaluations keep their numbers), the torch form draws for every env whatever the
subset (its stream does not depend on the data)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import torch

from charctl.experiments.cgail.env_arrays import HostArrays, TorchArrays


def _fake_env(xp_array, K=3, N=6):
    cfg = SimpleNamespace(start_failure_weight=0.0, goal_max_angle_deg=30.0, skill_fall_weight=0.0, switch_prob=0.5)
    env = SimpleNamespace(N=N, K=K, cfg=cfg, forced_command=None, start_frame=None, random_yaw=True)
    env.rsi_frames = xp_array([10, 20, 5])
    return env


def test_numpy_reset_draws_follow_the_numpy_env_order():
    arrays = HostArrays(sim=None, seed=11)
    env = _fake_env(lambda v: np.asarray(v, dtype=np.int64))
    env._sample_skills = lambda n: arrays.skills(n, env.K, None, 0.0)
    ids = np.array([4, 1, 2])
    skill, frames, yaw, goal = arrays.reset_draws(env, arrays.rows(ids))
    # the same stream by hand: commands, one integer draw per skill group (ascending skill), yaw, goal offset
    rng = np.random.default_rng(11)
    want_skill = rng.integers(0, 3, size=3)
    want_frames = np.empty(3, dtype=np.int64)
    for k in np.unique(want_skill):
        m = want_skill == k
        want_frames[m] = rng.integers(0, [10, 20, 5][k] - 1, size=int(m.sum()))
    want_yaw = rng.uniform(-np.pi, np.pi, size=3)
    want_goal = rng.uniform(-math.radians(30.0), math.radians(30.0), size=3)
    np.testing.assert_array_equal(skill, want_skill)
    np.testing.assert_array_equal(frames, want_frames)
    np.testing.assert_array_equal(yaw, want_yaw)
    np.testing.assert_array_equal(goal, want_goal)
    assert arrays.reset_draws(env, arrays.rows(np.array([], dtype=np.int64))) is None  # nothing drawn
    assert arrays.rng.random() == rng.random()


def test_torch_draws_do_not_depend_on_the_subset():
    N = 6
    sim = SimpleNamespace(device=torch.device("cpu"), num_envs=N, dtype=torch.float64)
    sim.as_mask = lambda ids: torch.as_tensor(ids) if torch.as_tensor(ids).dtype == torch.bool else None
    after = []
    for mask in (torch.zeros(N, dtype=torch.bool), torch.tensor([1, 0, 1, 0, 0, 1], dtype=torch.bool)):
        arrays = TorchArrays(sim, seed=3)
        env = _fake_env(lambda v: torch.as_tensor(v, dtype=torch.long), N=N)
        env._sample_skills = lambda n, a=arrays, e=env: a.skills(n, e.K, None, 0.0)
        out = arrays.reset_draws(env, arrays.rows(mask))
        if mask.any():
            skill, frames, yaw, goal = out
            assert skill.shape == (3,) and bool((frames < env.rsi_frames[skill] - 1).all())
            assert bool((yaw.abs() <= math.pi).all()) and bool((goal.abs() <= math.radians(30.0)).all())
        else:
            assert out is None  # the CPU's row form: an empty subset writes nothing
        after.append(torch.rand(4, generator=arrays.generator, dtype=torch.float64))
    torch.testing.assert_close(after[0], after[1], rtol=0, atol=0)
