"""env.backend=torch: the torch env (`CgailDeviceEnv`) on the CPU over C MuJoCo's arrays
(`charctl.sim.torch_view.TorchBatchedHumanoid`).

The adapter's raw arrays share memory with MuJoCo's (no copies) and its interface gives the numpy
simulator's numbers; the torch env over it gives the numpy env's (`CgailEnv`) state, observation,
rewards and episode ends after a reset and one step from the same states, with the tolerances of the
Warp env's check (`tests/test_gpu_path.py`; here both sides run C MuJoCo in float64, so the actual
differences are far below them); a smoke-scale `charctl train cgail env.backend=torch` completes
(slow, `make test-slow`).
"""

from __future__ import annotations

import os

import numpy as np
import pytest
import torch

from conftest import FIDELITY_ENV_RULES, REPO, assert_step_matches_cpu_env, cli_env, run_charctl


def _np(x: torch.Tensor) -> np.ndarray:
    return x.detach().cpu().numpy()


def _rsi_states(n: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """`n` RSI states of the walk clip, some dropped onto the ground."""
    from charctl.motion.library import load_clip
    from charctl.sim.humanoid import clip_to_qpos_qvel

    q, v = clip_to_qpos_qvel(load_clip("walk").resample(30.0))
    idx = np.linspace(0, len(q) - 2, n).astype(int)
    qpos, qvel = q[idx].copy(), v[idx].copy()
    qpos[::3, 1] = 0.12
    return qpos, qvel


def test_adapter_views_mujoco_arrays_and_matches_the_numpy_simulator():
    """Raw arrays are views (a write on either side shows on the other); the derived quantities, the mask
    and integer forms of set_state and a step equal BatchedHumanoid's on the same states and targets."""
    from charctl.experiments.cgail import features as F
    from charctl.experiments.cgail.warp_kinematics import sim_kinematics
    from charctl.sim.batch import BatchedHumanoid
    from charctl.sim.torch_view import TorchBatchedHumanoid

    qpos, qvel = _rsi_states()
    n = len(qpos)
    ref, sim = BatchedHumanoid(n), TorchBatchedHumanoid(n)
    for name in ("qpos", "qvel", "ctrl", "xfrc_applied", "xpos", "xquat", "cvel", "subtree_com", "geom_xpos"):
        assert np.shares_memory(getattr(sim, name).numpy(), getattr(sim.base, name)), name
    assert np.shares_memory(sim.geom_xmat.numpy(), sim.base.geom_xmat)
    ref.set_state(np.arange(n), qpos, qvel)
    mask = torch.zeros(n, dtype=torch.bool)
    mask[::2] = True
    sim.set_state(mask, torch.from_numpy(qpos), torch.from_numpy(qvel))  # masked rows from full-size inputs
    sim.set_state(torch.arange(1, n, 2), qpos[1::2], qvel[1::2])  # integer ids with their rows
    sim.set_state(torch.zeros(n, dtype=torch.bool), qpos * np.nan, qvel)  # an all-false mask writes nothing
    targets = np.random.default_rng(0).normal(scale=0.2, size=(n, sim.layout.nu))
    bad_ref, bad = ref.step(targets), sim.step(torch.from_numpy(targets))
    assert bad.dtype == torch.bool and np.array_equal(_np(bad), bad_ref)
    np.testing.assert_array_equal(_np(sim.qpos), ref.qpos)
    k_np, k_t = F.sim_kinematics(ref), sim_kinematics(sim)
    for field in ("body_pos", "body_rot", "lin_vel", "ang_vel", "com", "com_vel"):
        np.testing.assert_allclose(_np(getattr(k_t, field)), getattr(k_np, field), atol=1e-12, err_msg=field)
    np.testing.assert_array_equal(_np(sim.non_foot_ground_contact()), ref.non_foot_ground_contact())
    assert sim.dtype == torch.float64 and sim.total_mass == pytest.approx(float(ref.model.body_subtreemass[1]))


def test_backend_torch_is_accepted_on_the_cpu_only():
    from charctl.config import compose_config
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.config import Config
    from charctl.sim.warp_batch import resolve_backend

    assert compose_config("cgail", ["scale=smoke", "env.backend=torch"], Config).env.backend == "torch"
    assert resolve_backend("torch", "cpu") == "torch"
    with pytest.raises(CharctlError, match="env.backend=torch"):
        resolve_backend("torch", "cuda")


@pytest.mark.parametrize(
    ("fidelity", "window"), [(False, 0), (True, 0), (True, 3)], ids=["default", "phase-pose-track", "goal-window"]
)
def test_torch_env_on_cpu_gives_the_numpy_env_observations(fidelity, window):
    """Same skill, same RSI frame, no random yaw, goal straight ahead: the torch env over the adapter gives
    the numpy env's state, obs, rewards and episode ends after reset and after one step with the same
    actions; with the fidelity recipe's env rules too (env.phase_obs, the pose-error check, r_track there).
    Tolerances of test_gpu_path's Warp check."""
    from omegaconf import OmegaConf

    from charctl.config import compose_config
    from charctl.experiments.cgail.config import Config
    from charctl.experiments.cgail.env import CgailDeviceEnv, CgailEnv
    from charctl.experiments.cgail.skills import load_skills, select_skills
    from charctl.sim.torch_view import TorchBatchedHumanoid

    overrides = ["scale=smoke", "env.num_envs=4", "env.goal_max_angle_deg=0", "env.switch_prob=0"]
    cfg = compose_config("cgail", overrides + (["env.phase_obs=true"] if fidelity else []), Config)
    skills = load_skills(select_skills(cfg), cfg.env.control_hz)
    env_cfg = OmegaConf.to_object(cfg.env)
    forced = np.array([0, 1, 0, 1])
    rules = dict(pose_error_threshold=0.10, pose_error_grace_steps=0, reference_reward=True) if fidelity else {}
    if window:  # reward.goal_reference_window: the walk's reference moves on from its matched frame
        rules["goal_reference_window"] = window
    c_env = CgailEnv(skills, env_cfg, seed=0, **rules)
    t_env = CgailDeviceEnv(skills, env_cfg, seed=0, device="cpu", sim=TorchBatchedHumanoid(4), **rules)
    c_env.forced_command, t_env.forced_command = forced, torch.as_tensor(forced)
    for env in (c_env, t_env):
        env.start_frame, env.random_yaw = 5, False
    c_env.reset(np.arange(4))
    t_env.reset(torch.ones(4, dtype=torch.bool))
    assert t_env.state.dtype == torch.float32 and t_env.obs.dtype == torch.float32
    np.testing.assert_allclose(_np(t_env.state), c_env.state, atol=2e-4)
    np.testing.assert_allclose(_np(t_env.obs), c_env.obs, atol=2e-4)
    actions = np.random.default_rng(0).normal(scale=0.1, size=(4, 28)).astype(np.float32).astype(np.float64)
    c_res, t_res = c_env.step(actions), t_env.step(torch.as_tensor(actions, dtype=torch.float32))
    assert_step_matches_cpu_env(c_env, c_res, t_env, t_res, fidelity)
    np.testing.assert_array_equal(_np(t_env.ref_frame), c_env.ref_frame)
    np.testing.assert_allclose(_np(t_res.state), c_res.state, atol=2e-3)
    np.testing.assert_array_equal(_np(t_res.truncated), c_res.truncated)
    np.testing.assert_array_equal(_np(t_res.unstable), c_res.unstable)
    # the per-skill failure rates (logged as fall_rate/<skill>) follow the ended episodes on both envs, whatever
    # env.skill_fall_weight (0 here: they do not weight the commands)
    assert cfg.env.skill_fall_weight == 0
    if fidelity:
        assert c_res.pose_ended.any() and not np.allclose(c_env.fall_rate, 0.5)
    np.testing.assert_allclose(_np(t_env.fall_rate), c_env.fall_rate, rtol=0, atol=1e-12)


@pytest.mark.parametrize("window", [0, 3], ids=["closest-frame", "goal-window"])
def test_row_form_on_the_cpu_gives_the_mask_forms_episodes(window):
    """On the CPU the torch env resets, and searches the closest clip frame, on the rows concerned only
    (`compact_rows`); on a GPU it does both in mask form. From the same seed, actions and extra resets the two
    forms give the same episodes (resets, commands, reference frames, ends, simulator states bit for bit) and
    the same states, observations and rewards up to float64 rounding: a transcendental function may round
    its last bit differently on a few rows (scalar kernel) than on all of them (vectorised kernel)."""
    from omegaconf import OmegaConf

    from charctl.config import compose_config
    from charctl.experiments.cgail.config import Config
    from charctl.experiments.cgail.env import CgailDeviceEnv
    from charctl.experiments.cgail.skills import load_skills, select_skills
    from charctl.sim.torch_view import TorchBatchedHumanoid

    n = 16
    overrides = ["scale=smoke", f"env.num_envs={n}", "env.phase_obs=true", "env.skill_fall_weight=0.5"]
    cfg = compose_config("cgail", [*overrides, "env.switch_prob=0.2"], Config)
    skills = load_skills(select_skills(cfg), cfg.env.control_hz)
    env_cfg = OmegaConf.to_object(cfg.env)
    rules = dict(pose_error_threshold=0.15, pose_error_grace_steps=2, reference_reward=True, yaw_error_threshold=0.5)
    rules["goal_reference_window"] = window
    envs = []
    for compact in (True, False):
        env = CgailDeviceEnv(skills, env_cfg, seed=3, device="cpu", sim=TorchBatchedHumanoid(n), **rules)
        assert env.compact_rows  # the CPU's form; the mask form is the GPU's, forced here
        env.compact_rows = compact
        env.reset(torch.ones(n, dtype=torch.bool))
        envs.append(env)
    rows, masks = envs
    g = torch.Generator().manual_seed(0)
    exact = ("terminated", "truncated", "unstable", "pose_ended")
    ends = 0
    for _ in range(40):
        actions = 0.3 * torch.randn(n, 28, generator=g)
        extra = torch.rand(n, generator=g) < 0.1  # as the low-style termination's resets
        results = [env.step(actions) for env in envs]
        for env in envs:
            env.reset(extra)
        for name in exact:
            assert torch.equal(getattr(results[0], name), getattr(results[1], name)), name
        for name in ("state", "obs", "pair_next", "final_state", "r_goal", "r_track", "pose_reference"):
            torch.testing.assert_close(getattr(results[0], name), getattr(results[1], name), rtol=0, atol=1e-12)
        for name in ("cmd", "prev_cmd", "steps", "ref_frame", "ref_active", "ref_grace"):
            assert torch.equal(getattr(rows, name), getattr(masks, name)), name
        for name in ("w", "goal_angle", "yaw_err", "fall_rate", "state", "obs"):
            torch.testing.assert_close(getattr(rows, name), getattr(masks, name), rtol=0, atol=1e-12)
        assert torch.equal(rows.sim.qpos, masks.sim.qpos) and torch.equal(rows.sim.qvel, masks.sim.qvel)
        ends += int((results[0].terminated | results[0].truncated).sum())
    assert ends > 0 and rows.fall_count == masks.fall_count


@pytest.mark.slow
def test_smoke_training_with_the_torch_backend(tmp_path):
    """`charctl train cgail scale=smoke env.backend=torch device=cpu` with the fidelity recipe's env rules and
    the overlapped loop completes, and its checkpoint loads with the CPU evaluation code."""
    from charctl.experiments.cgail.policy import load_trained_run

    env = cli_env(PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH", "")])))
    res = run_charctl(
        "train",
        "cgail",
        "scale=smoke",
        "env.backend=torch",
        "train.overlap_update=true",
        *FIDELITY_ENV_RULES,
        "device=cpu",
        f"output_root={tmp_path}",
        env=env,
        timeout=900,
    )
    assert res.returncode == 0, res.stdout + res.stderr
    assert "done: iterations=4" in res.stdout
    (run_dir,) = (tmp_path / "cgail").iterdir()
    run = load_trained_run(run_dir)
    assert run.agent.samples == 512 and run.agent.model.obs_dim == 245  # 241 features + goal + phase


def test_a_shipped_policy_rolls_out_the_same_on_both_envs():
    """The shipped 3-skill policy, one env per skill (held command, RSI at frame 0, no random yaw, goals straight
    ahead: no random number enters), 90 control steps with its mean actions on the numpy env and on the torch env
    over C MuJoCo: the same body positions (measured here: walk and run bit for bit; the kick, whose state carries
    the clip phase, 6.8e-6 m at 3 s: float64 cos/sin rounded differently by numpy and torch, seen through the float32
    policy input; the bounds leave room for another CPU's rounding, a real difference is millimetres or more).
    The deterministic evaluations (`--fidelity`, the pins) therefore agree on the two envs; what differs is the
    random draws (docs/cgail.md, "What deleting the numpy env would take")."""
    from omegaconf import OmegaConf

    from charctl.experiments.cgail.drive import mean_action
    from charctl.experiments.cgail.env import CgailDeviceEnv, CgailEnv
    from charctl.experiments.cgail.rollouts import load_eval_run
    from charctl.experiments.cgail.train import _torch_cpu_sim

    from conftest import REPO

    agent = load_eval_run(REPO / "pretrained/cgail-3skill-fidelity", device="cpu").agent
    k = len(agent.skills)
    cfg = OmegaConf.merge(agent.cfg.env, {"num_envs": k, "switch_prob": 0.0, "goal_max_angle_deg": 0.0})
    c_env = CgailEnv(agent.skills, cfg, seed=0, conditional=True)
    t_env = CgailDeviceEnv(agent.skills, cfg, seed=0, conditional=True, device="cpu", sim=_torch_cpu_sim(cfg))
    c_env.forced_command, t_env.forced_command = np.arange(k), torch.arange(k)
    for env in (c_env, t_env):
        env.start_frame, env.random_yaw = 0, False
    c_env.reset(np.arange(k))
    t_env.reset(torch.ones(k, dtype=torch.bool))
    for _ in range(90):
        c_env.step(mean_action(agent, c_env))
        with torch.no_grad():
            state, blend = t_env.state, t_env.command_blend().to(torch.float32)
            t_env.step(agent.model.mean_action(state, blend).float())
    diff = np.abs(c_env.sim.body_pos_rows() - t_env.sim.base.body_pos_rows()).max(axis=(1, 2))
    names = [s.name for s in agent.skills]
    assert diff[names.index("walk")] < 1e-6 and diff[names.index("run")] < 1e-6
    assert diff[names.index("right_kick")] < 1e-4
