"""Failure-weighted start frames (env.start_failure_weight, `cgail/start_frames.py`): the lead windows, the failure
counts and the start-frame distribution by hand, numpy and torch alike, and both envs drawing and recording them."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from charctl.experiments.cgail import start_frames as SF
from charctl.experiments.cgail.config import EnvConfig, SkillConfig
from charctl.experiments.cgail.env import CgailEnv
from charctl.experiments.cgail.skills import load_skills

# a 7-frame clip that does not loop (starts 0..5) and a 5-frame looping one (period 4: its frame 4 is its frame 0)
FRAMES, LOOPS = np.array([7, 5]), np.array([False, True])


def test_lead_windows_stop_at_a_clip_end_or_wrap_round_its_period():
    index, valid = SF.lead_window_index(FRAMES, LOOPS, lead=2)
    assert index.shape == valid.shape == (2, 7, 3)
    assert index[0, 4].tolist() == [4, 5, 6] and valid[0, 4].all()
    assert valid[0, 5].tolist() == [True, True, False] and valid[0, 6].tolist() == [True, False, False]
    assert (index[1, 2] - 7).tolist() == [2, 3, 0] and (index[1, 3] - 7).tolist() == [3, 0, 1]  # 7: row 1's offset
    assert not valid[1, 5:].any()  # past the 5-frame clip


@pytest.mark.parametrize("lib", ["numpy", "torch"])
def test_failures_decay_by_their_halflife_and_add_at_skill_and_frame(lib):
    arr = np.asarray if lib == "numpy" else torch.as_tensor
    counts = arr(np.full((2, 7), 4.0))
    skill, frame, failed = arr([0, 0, 1, 1]), arr([5, 5, 0, 3]), arr([True, True, True, False])
    out = np.asarray(SF.update_frame_failures(counts, skill, frame, failed, halflife=2.0))
    expected = np.full((2, 7), 4.0 * 0.5**0.5)
    expected[0, 5] += 2.0  # two failures of skill 0 at frame 5
    expected[1, 0] += 1.0  # the env of skill 1 at frame 3 did not fail
    np.testing.assert_allclose(out, expected)


@pytest.mark.parametrize("lib", ["numpy", "torch"])
def test_start_frames_are_drawn_just_before_the_failures(lib):
    """Skill 0 failed twice at frame 5, skill 1 once at frame 0; lead 2. Weight 1: skill 0 starts at 3, 4 or 5
    (windows 3-5, 4-6, 5-6 hold frame 5), a third each; skill 1 (looping) at 0, 2 or 3 (windows 0-2, 2-3-0,
    3-0-1). Weight 0.5: half that, half uniform over the start frames (6 and 4 of them)."""
    arr = np.asarray if lib == "numpy" else torch.as_tensor
    counts = np.zeros((2, 7))
    counts[0, 5], counts[1, 0] = 2.0, 1.0
    lead = tuple(arr(a) for a in SF.lead_window_index(FRAMES, LOOPS, lead=2))
    p = np.diff(np.asarray(SF.start_frame_cdf(arr(counts), *lead, arr(FRAMES), 1.0)), axis=1, prepend=0.0)
    third = 1.0 / 3.0
    np.testing.assert_allclose(p, [[0, 0, 0, third, third, third, 0], [third, 0, third, third, 0, 0, 0]])
    p = np.diff(np.asarray(SF.start_frame_cdf(arr(counts), *lead, arr(FRAMES), 0.5)), axis=1, prepend=0.0)
    np.testing.assert_allclose(p[0], 0.5 * np.array([0, 0, 0, third, third, third, 0]) + 0.5 * np.r_[np.ones(6) / 6, 0])
    none = np.diff(np.asarray(SF.start_frame_cdf(arr(np.zeros((2, 7))), *lead, arr(FRAMES), 1.0)), axis=1, prepend=0)
    np.testing.assert_allclose(none[1], [0.25] * 4 + [0] * 3)  # no failures on record: uniform


@pytest.mark.parametrize("lib", ["numpy", "torch"])
def test_sampling_inverts_the_cdf(lib):
    arr = np.asarray if lib == "numpy" else torch.as_tensor
    cdf = arr(np.array([[0.2, 0.5, 1.0, 1.0, 1.0], [0.0, 0.5, 1.0, 1.0, 1.0]]))
    skill, u = arr(np.array([0, 0, 0, 1, 1])), arr(np.array([0.1, 0.2, 0.99, 0.0, 0.5]))
    frames = SF.sample_start_frames(cdf, skill, u, arr(np.array([6, 6])))
    assert np.asarray(frames).tolist() == [0, 1, 2, 1, 2]


@pytest.fixture(scope="module")
def skills():
    return load_skills([SkillConfig("walk", "walk", heading_goal=True), SkillConfig("kick", "kick")], 30.0)


def _env_cfg(n: int, weight: float):
    return OmegaConf.structured(
        EnvConfig(num_envs=n, switch_prob=0.0, start_failure_weight=weight, start_failure_lead=4)
    )


def test_the_numpy_env_starts_before_recorded_failures_and_records_its_own(skills):
    env = CgailEnv(skills, _env_cfg(64, 1.0), seed=0, pose_error_threshold=0.5)
    env.forced_command = np.ones(64, dtype=np.int64)  # the kick
    env.frame_failures[1, 30] = 5.0
    env.reset(np.arange(64))
    assert set(env.ref_frame.tolist()) == {26, 27, 28, 29, 30}  # lead 4: windows 26-30 ... 30-34 hold frame 30
    strict = CgailEnv(skills, _env_cfg(4, 1.0), seed=0, pose_error_threshold=1e-3, pose_error_grace_steps=0)
    strict.forced_command = np.ones(4, dtype=np.int64)
    strict.start_frame = 10
    strict.reset(np.arange(4))
    assert strict.step(np.zeros((4, 28))).pose_ended.all()  # 1 mm: every checked pose fails
    assert strict.frame_failures[1, 11] == 4.0 and strict.frame_failures.sum() == 4.0  # one step on from frame 10


def test_the_torch_env_draws_the_same_distribution(skills):
    from charctl.experiments.cgail.env import CgailDeviceEnv
    from charctl.sim.torch_view import TorchBatchedHumanoid

    env = CgailDeviceEnv(
        skills, _env_cfg(64, 1.0), seed=0, device="cpu", sim=TorchBatchedHumanoid(64), pose_error_threshold=0.5
    )
    env.forced_command = torch.ones(64, dtype=torch.long)
    env.frame_failures[1, 30] = 5.0
    env.reset(torch.ones(64, dtype=torch.bool))
    assert set(env.ref_frame.tolist()) == {26, 27, 28, 29, 30}
    res = env.step(torch.zeros(64, 28))
    failed = res.terminated
    assert env.frame_failures.sum().item() == pytest.approx(5.0 * 0.5 ** (1 / 300) + failed.sum().item())


def test_uniform_rsi_is_unchanged_at_weight_zero(skills):
    a = CgailEnv(skills, _env_cfg(32, 0.0), seed=3, pose_error_threshold=0.5)
    b = CgailEnv(
        skills, OmegaConf.structured(EnvConfig(num_envs=32, switch_prob=0.0)), seed=3, pose_error_threshold=0.5
    )
    np.testing.assert_array_equal(a.ref_frame, b.ref_frame)
    assert len(set(a.ref_frame.tolist())) > 10


def test_a_weight_without_a_timed_reference_is_refused():
    from charctl.config import compose_config
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.config import Config

    with pytest.raises(CharctlError, match="env.start_failure_weight needs a timed reference"):
        compose_config(
            "cgail",
            ["scale=smoke", "env.start_failure_weight=0.5", "reward.pose_error_threshold=0", "env.phase_obs=false"],
            Config,
        )
    cfg = compose_config("cgail", ["scale=smoke", "env.start_failure_weight=0.5", "env.phase_obs=true"], Config)
    assert cfg.env.start_failure_weight == 0.5


def test_evaluation_envs_start_uniformly_whatever_the_training_weight():
    """A training rule: `make_env` without rules (evaluation) and the fidelity env set the weight to 0; a diagnostic
    passing the training rules keeps the run's."""
    from charctl.experiments.cgail.env_rules import env_rules
    from charctl.experiments.cgail.fidelity import _make_env
    from charctl.experiments.cgail.policy import load_trained_run

    from conftest import REPO

    tr = load_trained_run(REPO / "pretrained/cgail-3skill-fidelity")
    tr.cfg.env.start_failure_weight = 0.5
    assert tr.make_env(2).cfg.start_failure_weight == 0.0
    assert _make_env(tr.agent, 2, 0, 1.0).cfg.start_failure_weight == 0.0
    assert tr.make_env(2, rules=env_rules(tr.cfg.reward)).cfg.start_failure_weight == 0.5


@pytest.mark.parametrize("backend", ["cpu", "torch"])
def test_smoke_training_with_failure_weighted_starts(backend, tmp_path, charctl_main):
    res = charctl_main(
        "train", "cgail", "scale=smoke", "env.start_failure_weight=0.5", "env.phase_obs=true",
        f"env.backend={backend}", "device=cpu", f"output_root={tmp_path}",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "done: iterations=4" in res.stdout
