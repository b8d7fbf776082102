"""env.rsi_joint_noise: Gaussian noise on the hinge angles of a training RSI start (root and velocities kept), its
statistics against the std asked for, and evaluation envs starting exactly on the clip."""

from __future__ import annotations

import types

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from charctl.experiments.cgail.config import EnvConfig, SkillConfig
from charctl.experiments.cgail.env import CgailEnv
from charctl.experiments.cgail.env_arrays import TorchArrays
from charctl.experiments.cgail.skills import load_skills

from conftest import REPO


@pytest.fixture(scope="module")
def skills():
    return load_skills([SkillConfig("kick", "kick")], 30.0)


def _reset_at_frame_zero(skills, noise: float, n: int = 256) -> CgailEnv:
    cfg = OmegaConf.structured(EnvConfig(num_envs=n, switch_prob=0.0, rsi_joint_noise=noise))
    env = CgailEnv(skills, cfg, seed=0)
    env.forced_command = np.zeros(n, dtype=int)
    env.start_frame, env.random_yaw = 0, False
    env.reset(np.arange(n))
    return env


def test_without_noise_the_start_is_the_clip_state(skills):
    env = _reset_at_frame_zero(skills, 0.0, n=4)
    np.testing.assert_array_equal(env.sim.qpos[:, 7:], np.broadcast_to(env.rsi_qpos[0, 0, 7:], env.sim.qpos[:, 7:].shape))


def test_noise_moves_only_the_hinges_by_the_std_asked_for(skills):
    env = _reset_at_frame_zero(skills, 0.1)
    clip = env.rsi_qpos[0, 0]
    np.testing.assert_allclose(env.sim.qpos[:, 1], clip[1])  # root height (x, z are zeroed by every reset)
    np.testing.assert_allclose(np.abs(env.sim.qpos[:, 3:7]), np.abs(np.broadcast_to(clip[3:7], (256, 4))), atol=1e-12)
    np.testing.assert_array_equal(env.sim.qvel, np.broadcast_to(env.rsi_qvel[0, 0], env.sim.qvel.shape))
    d = env.sim.qpos[:, 7:] - clip[7:]  # 256 x 28 draws: the sample std within 3 % of 0.1, the mean within 0.005
    assert d.std() == pytest.approx(0.1, rel=0.03) and abs(d.mean()) < 0.005


def test_the_torch_arrays_draw_the_same_distribution():
    arrays = TorchArrays(types.SimpleNamespace(device=torch.device("cpu"), dtype=torch.float64), seed=0)
    x = arrays.normal((256, 28), 0.1)
    assert x.shape == (256, 28) and x.dtype == torch.float64
    assert float(x.std()) == pytest.approx(0.1, rel=0.03) and abs(float(x.mean())) < 0.005


def test_evaluation_envs_start_on_the_clip_and_rule_replays_keep_the_noise():
    from charctl.experiments.cgail.policy import load_trained_run

    run = load_trained_run(REPO / "pretrained/cgail-3skill-fidelity")
    run.cfg.env.rsi_joint_noise = 0.2
    assert run.make_env(2).cfg.rsi_joint_noise == 0.0
    assert run.make_env(2, rules={}).cfg.rsi_joint_noise == 0.2
