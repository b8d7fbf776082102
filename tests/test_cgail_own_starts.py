"""Starts from the policy's own states (env.own_start_weight, `charctl.experiments.cgail.own_starts`): the ring by
hand values, the draw keeping each start's skill, the restart detection, and the env keeping a restart's physics
state and starting an episode from it at frame 0 with the restart's grace steps."""

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from charctl.experiments.cgail.config import EnvConfig, SkillConfig
from charctl.experiments.cgail.env import CgailEnv
from charctl.experiments.cgail.own_starts import OwnStarts, restarted_here
from charctl.experiments.cgail.skills import load_skills


def _ring(capacity: int, num_skills: int = 5, lib=np):
    if lib is np:
        return OwnStarts(capacity, 1, 1, num_skills, np.zeros, np.float64, np.int64)
    return OwnStarts(capacity, 1, 1, num_skills, lambda s, d: torch.zeros(s, dtype=d), torch.float32, torch.int64)


@pytest.mark.parametrize("lib", [np, torch])
def test_the_ring_keeps_the_newest_fresh_rows(lib):
    ring = _ring(3, lib=lib)
    a = lib.tensor if lib is torch else np.array
    q = a([[0.0], [1.0], [9.0]])
    ring.keep(q, q + 10, a([0, 0, 4]), a([True, True, False]))  # row 2 is not fresh
    ring.keep(a([[2.0], [3.0]]), a([[12.0], [13.0]]), a([1, 1]), a([True, True]))  # 3 replaces 0 (slot 0)
    assert ring.qpos[:3, 0].tolist() == [3.0, 1.0, 2.0] and ring.qvel[:3, 0].tolist() == [13.0, 11.0, 12.0]
    assert ring.skill.tolist() == [1, 0, 1, -1] and int(ring.written) == 4
    five = lib.arange(5.0)[:, None] + 20
    # more than fit: the last three, each where it would be had all five been written in turn (slots 1, 2, 0, 1, 2)
    ring.keep(five, five * 0, lib.arange(5), a([True] * 5))
    assert ring.qpos[:3, 0].tolist() == [22.0, 23.0, 24.0] and ring.skill.tolist() == [2, 3, 4, -1]
    assert int(ring.written) == 9


@pytest.mark.parametrize("lib", [np, torch])
def test_a_start_takes_a_kept_state_of_its_own_skill(lib):
    """Kept skills [1, 0, 1] in slots 0..2: skill 1's states in slot order are slots 0 and 2, so u_slot 0.3 takes
    the first (floor(0.3 * 2) = 0) and 0.7 the second; skill 2 has none; u_own >= weight starts from the clip."""
    ring = _ring(4, lib=lib)
    a = lib.tensor if lib is torch else np.array
    ring.keep(lib.zeros((3, 1)), lib.zeros((3, 1)), a([1, 0, 1]), a([True] * 3))
    skill = a([0, 1, 2, 1, 1])
    u_own = a([0.1, 0.2, 0.3, 0.4, 0.9])
    u_slot = a([0.99, 0.3, 0.5, 0.7, 0.0])
    own, slots = ring.draw(skill, u_own, u_slot, weight=0.5)
    assert own.tolist() == [True, True, False, True, False]
    assert [int(slots[i]) for i in (0, 1, 3)] == [1, 0, 2]
    own, _ = ring.draw(skill, u_own, u_slot, weight=0.0)
    assert not own.any()


def test_a_restart_is_where_the_grace_counter_was_just_set():
    grace = np.array([10, 9, 0, 10])
    active = np.array([True, True, True, False])  # env 3: its reference waits for a ramp
    assert restarted_here(grace, active, 10).tolist() == [True, False, False, False]


@pytest.fixture(scope="module")
def kick():
    return load_skills([SkillConfig("kick", "kick")], 30.0)


def _env(kick, n=2, weight=1.0):
    cfg = OmegaConf.structured(EnvConfig(num_envs=n, switch_prob=0.0, own_start_weight=weight, own_start_capacity=8))
    return CgailEnv(kick, cfg, seed=0, pose_error_threshold=100.0, pose_error_grace_steps=3)


def test_the_env_keeps_the_state_where_the_kick_restarts(kick):
    """Two steps before the kick clip's end: one step reaches its last frame, the next restarts it at frame 0 and
    keeps both envs' physics states as they are after that step."""
    env = _env(kick)
    env.ref_frame[:] = len(kick[0].obs) - 2
    nu = env.sim.layout.nu
    env.step(np.zeros((2, nu)))
    assert env.own_starts.written == 0
    env.step(np.zeros((2, nu)))
    assert env.ref_frame.tolist() == [0, 0] and env.own_starts.written == 2
    assert env.own_starts.skill[:2].tolist() == [0, 0]
    np.testing.assert_array_equal(env.own_starts.qpos[:2], env.sim.qpos)
    np.testing.assert_array_equal(env.own_starts.qvel[:2], env.sim.qvel)


def test_a_reset_starts_from_a_kept_state_at_frame_0_with_grace(kick):
    """With weight 1 every kick start restores a kept state (moved to x = z = 0, no yaw turn here); the reference
    starts at frame 0, unchecked for the grace steps. An evaluation's forced start frame starts from the clip."""
    env = _env(kick)
    env.random_yaw = False
    qpos, qvel = env.rsi_qpos[0, 20].copy(), env.rsi_qvel[0, 20].copy()
    qpos[0], qpos[2] = 3.0, -2.0
    env.own_starts.keep(qpos[None], qvel[None], np.array([0]), np.array([True]))
    env.reset(np.arange(2))
    want = qpos.copy()
    want[0] = want[2] = 0.0
    np.testing.assert_allclose(env.sim.qpos, np.stack([want, want]), atol=1e-12)
    np.testing.assert_allclose(env.sim.qvel, np.stack([qvel, qvel]), atol=1e-12)
    assert env.ref_frame.tolist() == [0, 0] and env.ref_grace.tolist() == [3, 3]
    env.start_frame = 20
    env.reset(np.arange(2))
    assert env.ref_frame.tolist() == [20, 20] and env.ref_grace.tolist() == [0, 0]


@pytest.mark.parametrize("compact", [True, False])
def test_the_torch_env_keeps_and_starts_from_the_same_states(kick, compact):
    """env.backend=torch (the Warp env's code on C MuJoCo's arrays): the same restart kept and the same start,
    with the resets' rows as ids (the CPU's form) and as a mask (a GPU's form)."""
    from charctl.experiments.cgail.env import CgailDeviceEnv
    from charctl.sim.torch_view import TorchBatchedHumanoid

    cfg = OmegaConf.structured(EnvConfig(num_envs=2, switch_prob=0.0, own_start_weight=1.0, own_start_capacity=8))
    env = CgailDeviceEnv(
        kick, cfg, seed=0, sim=TorchBatchedHumanoid(2), pose_error_threshold=100.0, pose_error_grace_steps=3
    )
    env.compact_rows = compact
    env.ref_frame = torch.full_like(env.ref_frame, len(kick[0].obs) - 2)
    for _ in range(2):
        env.step(torch.zeros((2, env.sim.layout.nu)))
    assert env.ref_frame.tolist() == [0, 0] and int(env.own_starts.written) == 2
    torch.testing.assert_close(env.own_starts.qpos[:2], env.sim.qpos)
    env.random_yaw = False
    kept = env.own_starts.qpos[:2].clone()
    env.reset(torch.ones(2, dtype=torch.bool))
    want = kept.clone()
    want[:, 0] = want[:, 2] = 0.0
    assert sorted(map(tuple, env.sim.qpos.tolist())) == sorted(map(tuple, want.tolist()))
    assert env.ref_frame.tolist() == [0, 0] and env.ref_grace.tolist() == [3, 3]


def test_by_success_scales_each_skills_share_by_its_success_rate(kick):
    """env.own_start_by_success: weight 0.8 and a kick failure rate of 0.75 give a share of 0.8 x 0.25 = 0.2, so a
    start with u_own 0.1 takes a kept state and one with 0.3 starts from the clip (weight alone: both would)."""
    env = _env(kick, weight=0.8)
    env.cfg.own_start_by_success = True
    env.own_starts.keep(env.rsi_qpos[0, 20][None], env.rsi_qvel[0, 20][None], np.array([0]), np.array([True]))
    env.fall_rate = np.array([0.75])
    assert env.own_start_shares().tolist() == [0.2]
    draws = iter([np.array([0.1, 0.3]), np.array([0.5, 0.5])])  # u_own, then u_slot
    env.arrays.uniform = lambda rows: next(draws)
    env.reset(np.arange(2))
    assert env.ref_frame[0] == 0 and env.ref_grace.tolist() == [3, 0]


def test_a_floor_bounds_the_success_factor_from_below(kick):
    """env.own_start_floor 0.5 with weight 0.8: a failure rate of 0.75 gives 0.8 x max(0.5, 0.25) = 0.4 (the gate
    alone: 0.2), one of 0.25 gives 0.8 x 0.75 = 0.6 (the floor not reached); on the torch env too."""
    env = _env(kick, weight=0.8)
    env.cfg.own_start_by_success, env.cfg.own_start_floor = True, 0.5
    env.fall_rate = np.array([0.75])
    assert env.own_start_shares().tolist() == pytest.approx([0.4])
    env.fall_rate = np.array([0.25])
    assert env.own_start_shares().tolist() == pytest.approx([0.6])
    env.fall_rate = torch.tensor([0.75, 0.25], dtype=torch.float64)  # the torch env's fall_rate
    assert env.own_start_shares().tolist() == pytest.approx([0.4, 0.6])


def test_the_starts_are_off_in_evaluation_envs_and_need_a_restarting_reference():
    from charctl.config import compose_config
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.config import Config
    from charctl.experiments.cgail.env_rules import env_rules
    from charctl.experiments.cgail.fidelity import _make_env
    from charctl.experiments.cgail.policy import load_trained_run

    from conftest import REPO

    tr = load_trained_run(REPO / "pretrained/cgail-3skill-fidelity")
    tr.cfg.env.own_start_weight = 0.5
    assert tr.make_env(2).own_starts is None and _make_env(tr.agent, 2, 0, 1.0).own_starts is None
    assert tr.make_env(2, rules=env_rules(tr.cfg.reward)).own_starts is not None  # a diagnostic of the training rules
    with pytest.raises(CharctlError, match="set env.own_start_weight > 0 with it"):
        compose_config("cgail", ["scale=smoke", "env.own_start_by_success=true"], Config)
    with pytest.raises(CharctlError, match="set env.own_start_by_success=true with it"):
        floor = ["env.own_start_weight=0.5", "env.phase_obs=true", "env.own_start_floor=0.4"]
        compose_config("cgail", ["scale=smoke", *floor], Config)
    with pytest.raises(CharctlError, match="restarts at frame 0"):
        overrides = ["reward.pose_error_threshold=0", "env.phase_obs=false"]
        compose_config("cgail", ["scale=smoke", "env.own_start_weight=0.5", *overrides], Config)
    cfg = compose_config("cgail", ["scale=smoke", "env.own_start_weight=0.5", "env.phase_obs=true"], Config)
    assert cfg.env.own_start_weight == 0.5


def test_smoke_training_with_own_starts(tmp_path, charctl_main):
    """Each skill's share is logged (own_start_share/<skill>): with the gate, weight x (1 - failure rate), below
    the weight (0.5) while the rate is above 0 (it starts at 0.5 and moves by an average: never exactly 0)."""
    from charctl.eval.tb import read_scalars

    overrides = ["env.own_start_weight=0.5", "env.own_start_by_success=true", "env.phase_obs=true"]
    res = charctl_main("train", "cgail", "scale=smoke", *overrides, f"output_root={tmp_path}")
    assert res.returncode == 0, res.stderr
    assert "done: iterations=4" in res.stdout
    (run,) = (tmp_path / "cgail").iterdir()
    shares = {k: v for k, (_, v) in read_scalars(run / "tb").items() if k.startswith("own_start_share/")}
    assert len(shares) == 2 and all(((v > 0) & (v < 0.5)).all() for v in shares.values()), shares
