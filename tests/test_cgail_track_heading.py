"""reward.track_heading: the tracking reward counts the yaw the root has gained on its reference (`rules.heading_gain`,
`env_rules.env_tracking_reward`), by hand on numpy and torch, in both envs alike, and the config's applicability."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from charctl.experiments.cgail import rules
from charctl.experiments.cgail.config import EnvConfig, SkillConfig
from charctl.experiments.cgail.env import CgailEnv
from charctl.experiments.cgail.skills import load_skills

LIBS = [pytest.param(np.asarray, id="numpy"), pytest.param(torch.as_tensor, id="torch")]


@pytest.mark.parametrize("arr", LIBS)
def test_heading_gain_adds_the_yaw_rate_missed_where_counted(arr):
    """dt 0.1 s, the reference turning at 5 rad/s: standing still adds -0.5 rad, turning with it adds 0, an env not
    counted (a heading goal) restarts at 0."""
    obs, ref = np.zeros((3, 133)), np.zeros((3, 133))
    ref[:, rules.OBS_YAW_RATE] = 5.0
    obs[1, rules.OBS_YAW_RATE] = 5.0
    out = rules.heading_gain(arr([-1.0, 0.3, 2.0]), arr(obs), arr(ref), arr([True, True, False]), 0.1)
    np.testing.assert_allclose(np.asarray(out), [-1.5, 0.3, 0.0], atol=1e-12)


@pytest.mark.parametrize("arr", LIBS)
def test_the_heading_error_counts_in_the_pose_term(arr):
    """obs = ref: every term is 1, r = 1; a heading error of 0.5 rad takes the pose term (weight 0.65) to
    exp(-0.25): r = 0.65 exp(-0.25) + 0.35; None leaves r as without the option."""
    obs = np.random.default_rng(0).normal(size=(2, 133))
    r = rules.tracking_reward(arr(obs), arr(obs), arr([0.5, 0.0]))
    np.testing.assert_allclose(np.asarray(r), [0.65 * math.exp(-0.25) + 0.35, 1.0], atol=1e-12)
    np.testing.assert_allclose(np.asarray(rules.tracking_reward(arr(obs), arr(obs))), [1.0, 1.0], atol=1e-12)


@pytest.fixture(scope="module")
def skills():
    return load_skills([SkillConfig("walk", "walk", heading_goal=True), SkillConfig("spindance", "dance_a")], 30.0)


def _steps(env, n: int, actions):
    """(n, N) r_track and (n, N) the root's yaw rate (rad/s) after each of `n` steps."""
    rewards, yaw_rates = [], []
    for _ in range(n):
        res = env.step(actions)
        rewards.append(np.asarray(res.r_track, dtype=float).copy())
        yaw_rates.append(np.asarray(res.pair_next, dtype=float)[:, rules.OBS_YAW_RATE].copy())
    return np.stack(rewards), np.stack(yaw_rates)


def test_the_heading_error_sums_the_yaw_rate_missed_on_the_clip(skills):
    """Spindance from frame 0 with zero actions for 5 steps: the heading error is the sum over the steps of (the
    root's yaw rate - the clip's at frames 1-5) / 30 Hz; the walk (a heading goal) counts none; the reward is lower
    than without the option (same physics: the option changes the reward only)."""
    cfg = OmegaConf.structured(EnvConfig(num_envs=2, switch_prob=0.0))
    envs = [CgailEnv(skills, cfg, seed=0, tracking=True, track_heading=h) for h in (True, False)]
    for env in envs:
        env.forced_command = np.array([1, 0])
        env.start_frame, env.random_yaw = 0, False
        env.reset(np.arange(2))
    (on, yaw_on), (off, yaw_off) = (_steps(env, 5, np.zeros((2, 28))) for env in envs)
    np.testing.assert_array_equal(yaw_on, yaw_off)
    expected = (yaw_on[:, 0] - skills[1].obs[1:6, rules.OBS_YAW_RATE]).sum() / 30.0
    assert abs(expected) > 0.05
    assert envs[0].yaw_err[0] == pytest.approx(expected, abs=1e-12)
    assert envs[0].yaw_err[1] == 0.0
    assert on[-1, 0] < off[-1, 0] and on[-1, 1] == off[-1, 1]


def test_the_torch_env_gains_the_same_heading(skills):
    from charctl.experiments.cgail.env_torch import CgailDeviceEnv
    from charctl.sim.torch_view import TorchBatchedHumanoid

    cfg = OmegaConf.structured(EnvConfig(num_envs=2, switch_prob=0.0))
    ref = CgailEnv(skills, cfg, seed=0, tracking=True, track_heading=True)
    env = CgailDeviceEnv(skills, cfg, seed=0, tracking=True, track_heading=True, sim=TorchBatchedHumanoid(2))
    for e, cmd in ((ref, np.array([1, 0])), (env, torch.tensor([1, 0]))):
        e.forced_command = cmd
        e.start_frame, e.random_yaw = 3, False
        e.reset(np.arange(2) if e is ref else torch.ones(2, dtype=torch.bool))
    a, _ = _steps(ref, 4, np.zeros((2, 28)))
    b, _ = _steps(env, 4, torch.zeros(2, 28))
    np.testing.assert_allclose(b, a, atol=1e-6)
    np.testing.assert_allclose(env.yaw_err.numpy(), ref.yaw_err, atol=1e-6)


def test_track_heading_applies_to_the_tracking_baseline_only():
    from charctl.config import compose_config
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.config import Config

    with pytest.raises(CharctlError, match="track_heading"):
        compose_config("cgail", ["scale=smoke", "reward.track_heading=true"], Config)
    on = ["scale=smoke", "reward.kind=tracking", "reward.track_heading=true", "env.switch_prob=0"]
    cfg = compose_config("cgail", on, Config)
    assert cfg.reward.track_heading is True


def test_smoke_training_with_the_heading_term(tmp_path, charctl_main):
    res = charctl_main(
        "train", "cgail", "scale=smoke", "reward.kind=tracking", "reward.track_heading=true", "env.switch_prob=0",
        "device=cpu",
        f"output_root={tmp_path}",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "done: iterations=4" in res.stdout
