"""The GPU path (README "GPU"), checked on the CPU.

Without MuJoCo Warp: the torch features, rewards and episode ends equal the numpy ones on the same
inputs; the device-side demonstration sampler and replay buffer behave; env.backend is validated.

With MuJoCo Warp on Warp's CPU device (its kernels compile once, ~26 s on an idle 2-core machine,
and are cached under ~/.cache/warp; afterwards these tests take ~6 s): MuJoCo Warp against C MuJoCo
for the same humanoid from RSI frames of walk, run and kick under the same PD targets, body
positions within POS_TOL metres after 1, 10 and 30 control steps; blow-ups reset only the affected
worlds; the device env gives the CPU env's observations. Slow (`make test-slow`, ~15 s):
`charctl train cgail scale=smoke env.backend=warp` completes and its checkpoint loads with the CPU
evaluation code. CHARCTL_WARP_TEST_DEVICE=cuda runs the Warp tests on a GPU (`make gpu-check`).
"""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest
import torch

from conftest import FIDELITY_ENV_RULES, assert_step_matches_cpu_env, run_charctl

# Body-position tolerance (m) of MuJoCo Warp (float32) vs C MuJoCo (float64) after k control steps
# (10 physics substeps each). Measured on Warp's CPU device: 3.5e-7, 9.1e-6, 4.3e-5 m (README "GPU").
POS_TOL = {1: 1e-5, 10: 1e-4, 30: 1e-3}
VEL_TOL = {1: 3e-4, 10: 1e-3, 30: 1e-2}  # m/s, body-origin linear velocities (measured 1.1e-5, 4.2e-5, 3.3e-4)
CLIPS = ("walk", "run", "kick")

needs_warp = pytest.mark.skipif(sys.version_info < (3, 11), reason="MuJoCo Warp needs Python >= 3.11")
# Warp's device for the slow tests: Warp's CPU device here; `make gpu-check` sets cuda
WARP_DEVICE = os.environ.get("CHARCTL_WARP_TEST_DEVICE", "cpu")


def _np(x: torch.Tensor) -> np.ndarray:
    return x.detach().cpu().numpy()


def _t(x: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(x))


def _clip_kinematics(name: str):
    from charctl.experiments.cgail import features as F
    from charctl.motion.library import load_clip

    k = F.clip_kinematics(load_clip(name).resample(30.0))
    kt = F.Kinematics(*(_t(getattr(k, f)) for f in ("body_pos", "body_rot", "lin_vel", "ang_vel", "com", "com_vel")))
    return k, kt


# ---------------------------------------------------------------------------- torch == numpy (fast)
def test_torch_rotations_equal_numpy():
    from charctl.motion import rotations as R
    from charctl.motion import rotations_torch as RT

    rng = np.random.default_rng(0)
    a = R.normalize(rng.normal(size=(64, 4)))
    b = R.normalize(rng.normal(size=(64, 4)))
    v = rng.normal(size=(64, 3))
    theta = rng.uniform(-np.pi, np.pi, size=64)
    pairs = [
        (R.multiply(a, b), RT.multiply(_t(a), _t(b))),
        (R.conjugate(a), RT.conjugate(_t(a))),
        (R.rotate(a, v), RT.rotate(_t(a), _t(v))),
        (R.to_matrix(a), RT.to_matrix(_t(a))),
        (R.heading_quat(theta), RT.heading_quat(_t(theta))),
        (R.yaw_about_y(a), RT.yaw_about_y(_t(a))),
        (R.wxyz_to_xyzw(a), RT.wxyz_to_xyzw(_t(a))),
        (R.xyzw_to_wxyz(a), RT.xyzw_to_wxyz(_t(a))),
    ]
    for want, got in pairs:
        np.testing.assert_allclose(got.numpy(), want, atol=1e-12)


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_gathered_and_written_out_quaternion_forms_agree_bit_for_bit(dtype):
    """`rotations_torch.multiply` and `to_matrix` gather their terms for small inputs and write them out for large
    ones; on the same quaternions (zero and negative-zero components included) the two forms give the same bits,
    signs of zero too."""
    from charctl.motion import rotations_torch as RT

    g = torch.Generator().manual_seed(0)
    a, b = (torch.nn.functional.normalize(torch.randn(8, 1000, 4, generator=g, dtype=dtype), dim=-1) for _ in range(2))
    a[:, ::3, 0], b[:, ::5, 2], a[:, ::7, 1] = 0.0, -0.0, -0.0
    a[:, ::11] = torch.tensor([0.0, 0.6, 0.0, 0.8], dtype=dtype)  # a heading: exact zeros and ones in its matrix
    assert a.numel() > RT._GATHER_MAX >= a[0].numel()  # all at once: written out; one row at a time: gathered
    for whole, parts in (
        (RT.multiply(a, b), [RT.multiply(x, y) for x, y in zip(a, b)]),
        (RT.to_matrix(a), [RT.to_matrix(x) for x in a]),
    ):
        parts = torch.stack(parts)
        assert torch.equal(whole, parts) and torch.equal(whole.signbit(), parts.signbit())


@pytest.mark.parametrize("clip_name", ["walk", "kick"])
def test_torch_policy_state_and_disc_obs_equal_numpy(clip_name):
    """The one implementation on torch tensors: same kinematics in, same 241-d state and 133-d observation
    out as on numpy arrays: float64 to 1e-12, float32 to 2e-5."""
    from charctl.experiments.cgail import features as F
    from charctl.experiments.cgail import features as FT

    k, kt = _clip_kinematics(clip_name)
    s_np, o_np = F.policy_state(k), F.disc_obs(k)
    assert s_np.shape[1] == FT.STATE_DIM and o_np.shape[1] == FT.DISC_OBS_DIM
    np.testing.assert_allclose(FT.policy_state(kt).numpy(), s_np, atol=1e-12)
    np.testing.assert_allclose(FT.disc_obs(kt).numpy(), o_np, atol=1e-12)
    k32 = FT.Kinematics(*(x.float() for x in vars(kt).values() if x is not None))
    np.testing.assert_allclose(FT.policy_state(k32).numpy(), s_np, atol=2e-5)
    np.testing.assert_allclose(FT.disc_obs(k32).numpy(), o_np, atol=2e-5)


def test_torch_rewards_and_episode_ends_equal_numpy():
    from charctl.experiments.cgail import rules as FT
    from charctl.experiments.cgail.features import disc_obs
    from charctl.experiments.cgail.rules import tracking_reward

    rng = np.random.default_rng(1)
    _, kt = _clip_kinematics("run")
    ref = disc_obs(kt).numpy()
    obs = ref + rng.normal(scale=0.05, size=ref.shape)
    np.testing.assert_allclose(FT.tracking_reward(_t(obs), _t(ref)).numpy(), tracking_reward(obs, ref), atol=1e-12)
    # heading-goal reward: CgailEnv._goal_reward's formula (d = (cos g, -sin g) in x-z)
    n = 50
    goal, vel = rng.uniform(-np.pi, np.pi, n), rng.normal(size=(n, 3))
    speed, has_goal, sharp = rng.uniform(0, 3, n), rng.random(n) < 0.5, 2.0
    d = np.stack([np.cos(goal), -np.sin(goal)], axis=1)
    want = np.where(has_goal, np.exp(-sharp * (speed - np.sum(d * vel[:, [0, 2]], axis=1)) ** 2), 1.0)
    got = FT.goal_reward(_t(goal), _t(vel), _t(speed), _t(has_goal), sharp).numpy()
    np.testing.assert_allclose(got, want, atol=1e-12)
    # episode ends: every combination, against CgailEnv.step's numpy expressions
    fell, unstable, ended, pose = (rng.random(256) < 0.3 for _ in range(4))
    steps, max_steps = rng.integers(0, 12, 256), 10
    term, trunc = FT.episode_end(_t(fell), _t(unstable), _t(pose), _t(steps), max_steps, _t(ended))
    want_term = fell | unstable | pose
    np.testing.assert_array_equal(term.numpy(), want_term)
    np.testing.assert_array_equal(trunc.numpy(), ((steps >= max_steps) | ended) & ~want_term)


class _TorchViewOfCSim:
    """The C backend's arrays seen as torch tensors (the warp backend's interface for sim_kinematics)."""

    def __init__(self, sim):
        self.sim = sim
        self.total_mass = float(sim.model.body_subtreemass[1])
        self.body_pos = _t(sim.body_pos)
        self.body_quat_xyzw = _t(sim.body_quat_xyzw)

    def body_velocities(self):
        lin, ang = self.sim.body_velocities()
        return _t(lin), _t(ang)

    def com(self):
        return _t(self.sim.com())


def test_torch_sim_kinematics_and_ground_contact_equal_numpy():
    """From the same simulator arrays (RSI states of three clips, some fallen), the torch COM velocity and
    lowest geom points equal the numpy ones."""
    from charctl.experiments.cgail import features as F
    from charctl.experiments.cgail import warp_kinematics as FT
    from charctl.motion.library import load_clip
    from charctl.sim.batch import BatchedHumanoid, _lowest_y
    from charctl.sim.humanoid import clip_to_qpos_qvel
    from charctl.sim.warp_batch import lowest_y

    qpos, qvel = [], []
    for name in CLIPS:
        q, v = clip_to_qpos_qvel(load_clip(name).resample(30.0))
        idx = np.linspace(0, len(q) - 1, 4).astype(int)
        qpos.append(q[idx])
        qvel.append(v[idx])
    qpos, qvel = np.concatenate(qpos), np.concatenate(qvel)
    qpos[::3, 1] = 0.12  # drop some characters onto the ground
    sim = BatchedHumanoid(len(qpos))
    sim.set_state(np.arange(len(qpos)), qpos, qvel)
    k_np, k_t = F.sim_kinematics(sim), FT.sim_kinematics(_TorchViewOfCSim(sim))
    for field in ("body_pos", "body_rot", "lin_vel", "ang_vel", "com", "com_vel"):
        np.testing.assert_allclose(getattr(k_t, field).numpy(), getattr(k_np, field), atol=1e-12, err_msg=field)
    ids = sim._ground_geoms
    code = np.select([sim.model.geom_type[ids] == t for t in (2, 3)], [0, 1], default=2)  # sphere, capsule, box
    low_t = lowest_y(
        _t(sim.geom_xpos[:, ids]),
        _t(sim.geom_xmat[:, ids].reshape(len(qpos), len(ids), 3, 3)),
        _t(code),
        _t(sim.model.geom_size[ids]),
    )
    low_np = _lowest_y(sim.model, sim.geom_xpos, sim.geom_xmat, ids)
    np.testing.assert_allclose(low_t.numpy(), low_np, atol=1e-12)
    fell = sim.non_foot_ground_contact()
    assert fell.any() and not fell.all()
    np.testing.assert_array_equal((low_t[:, ~_t(sim._foot_geoms)] < 0.005).any(dim=1).numpy(), fell)


def test_device_demo_sampler_and_replay_buffer():
    """`DemoPairs.sample_torch` draws real pairs of the labelled skill, both skills about equally; the
    replay buffer's state dict is on the CPU whatever its device (checkpoints load anywhere)."""
    from charctl.experiments.cgail.config import SkillConfig
    from charctl.experiments.cgail.discriminator import ReplayBuffer
    from charctl.experiments.cgail.skills import DemoPairs, load_skills

    skills = load_skills([SkillConfig("walk", "walk"), SkillConfig("kick", "kick")], 30.0)
    demos = DemoPairs(skills)
    demos.to_device("cpu")
    pairs, labels = demos.sample_torch(4000, torch.Generator().manual_seed(0))
    assert pairs.shape == (4000, 266) and labels.dtype == torch.long
    assert 0.45 < float(labels.float().mean()) < 0.55
    for k in (0, 1):
        own = {row.tobytes() for row in demos.pairs[k]}
        assert all(row.tobytes() in own for row in pairs[labels == k][:200].numpy())
    replay = ReplayBuffer(10, 266, 2)
    replay.add(pairs[:4], torch.zeros(4, 2))
    state = replay.state_dict()
    assert state["pairs"].device.type == "cpu" and state["size"] == 4
    assert sorted(state) == ["cond", "pairs", "pos", "size"]


def test_backend_setting_is_validated():
    from charctl.config import compose_config
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.config import Config
    from charctl.sim.warp_batch import resolve_backend

    assert compose_config("cgail", ["scale=smoke"], Config).env.backend == "cpu"
    with pytest.raises(CharctlError, match="env.backend"):
        compose_config("cgail", ["scale=smoke", "env.backend=gpu"], Config)
    assert resolve_backend("cpu", "cuda") == "cpu"
    assert resolve_backend("auto", "cpu") == "cpu"  # auto picks warp only on a CUDA device


# ---------------------------------------------------------------------------- MuJoCo Warp (slow)
def _rsi_batch(frames_per_clip: int = 4, horizon: int = 30):
    """RSI states of walk, run and kick (frames spread over each clip) and, per env, the clip's next
    `horizon` poses as PD targets (the same open-loop targets for both simulators)."""
    from charctl.motion.library import load_clip
    from charctl.sim.humanoid import clip_to_qpos_qvel

    qpos, qvel, targets = [], [], []
    for name in CLIPS:
        q, v = clip_to_qpos_qvel(load_clip(name).resample(30.0))
        for f in np.linspace(0, len(q) - 2, frames_per_clip).astype(int):
            qpos.append(q[f])
            qvel.append(v[f])
            targets.append(q[np.minimum(np.arange(f + 1, f + 1 + horizon), len(q) - 1), 7:])
    return np.array(qpos), np.array(qvel), np.array(targets)


@pytest.fixture(scope="module")
def warp_sim_factory():
    from charctl.sim.warp_batch import WarpBatchedHumanoid

    return lambda n, **kw: WarpBatchedHumanoid(n, device=WARP_DEVICE, **kw)


@needs_warp
def test_warp_matches_c_mujoco_from_rsi_frames(warp_sim_factory):
    from charctl.sim.batch import BatchedHumanoid

    qpos, qvel, targets = _rsi_batch()
    n = len(qpos)
    c_sim, w_sim = BatchedHumanoid(n), warp_sim_factory(n)
    c_sim.set_state(np.arange(n), qpos, qvel)
    w_sim.set_state(torch.arange(n), qpos, qvel)
    assert np.abs(_np(w_sim.body_pos) - c_sim.body_pos).max() < 1e-6  # same FK of the same state
    errors = {}
    for step in range(1, max(POS_TOL) + 1):
        c_bad = c_sim.step(targets[:, step - 1])
        w_bad = w_sim.step(torch.as_tensor(targets[:, step - 1]))
        assert not c_bad.any() and not bool(w_bad.any())
        if step in POS_TOL:
            errors[step] = float(np.abs(_np(w_sim.body_pos) - c_sim.body_pos).max())
            lin_c, _ = c_sim.body_velocities()
            lin_w, _ = w_sim.body_velocities()
            assert np.abs(_np(lin_w) - lin_c).max() < VEL_TOL[step]
            low_err = np.abs(_np(w_sim.lowest_point_heights()) - c_sim.lowest_point_heights()).max()
            assert low_err < POS_TOL[step]  # the fall test (non-foot geom height) agrees as well
    print("warp vs C MuJoCo, max body position error (m) after k control steps:", errors)
    for step, err in errors.items():
        assert err < POS_TOL[step], (step, err)


@needs_warp
def test_warp_blow_up_resets_only_the_affected_worlds(warp_sim_factory):
    qpos, qvel, targets = _rsi_batch(frames_per_clip=1, horizon=1)
    sim = warp_sim_factory(3)
    sim.set_state(torch.tensor([True, True, True]), qpos, qvel)
    before = sim.body_pos.clone()
    sim.set_state(torch.tensor([1]), qpos[1:2], 1e4 * np.ones_like(qvel[1:2]))  # integer ids: only env 1
    assert torch.equal(sim.body_pos[[0, 2]], before[[0, 2]])
    bad = sim.step(torch.as_tensor(targets[:, 0]))
    assert bad.tolist() == [False, True, False] and sim.unstable_count == 1
    np.testing.assert_allclose(_np(sim.qpos[1]), sim.model.qpos0, atol=1e-6)  # rest pose
    assert float(sim.qvel[1].abs().max()) == 0.0
    assert bool(torch.isfinite(sim.qpos).all()) and float(sim.body_pos[[0, 2], 0, 1].min()) > 0.5


@needs_warp
@pytest.mark.parametrize("fidelity", [False, True], ids=["default", "phase-pose-track"])
def test_device_env_gives_the_cpu_env_observations(warp_sim_factory, fidelity):
    """Same skill, same RSI frame, no random yaw, goal straight ahead: the warp env's state, obs and
    rewards equal the C env's after reset and after one step with the same actions (float32 + parity);
    with the fidelity recipe's env rules too (env.phase_obs, the pose-error check, r_track there)."""
    from omegaconf import OmegaConf

    from charctl.config import compose_config
    from charctl.experiments.cgail.config import Config
    from charctl.experiments.cgail.env import CgailDeviceEnv, CgailEnv
    from charctl.experiments.cgail.skills import load_skills, select_skills

    overrides = ["scale=smoke", "env.num_envs=4", "env.goal_max_angle_deg=0", "env.switch_prob=0"]
    cfg = compose_config("cgail", overrides + (["env.phase_obs=true"] if fidelity else []), Config)
    skills = load_skills(select_skills(cfg), cfg.env.control_hz)
    env_cfg = OmegaConf.to_object(cfg.env)
    forced = np.array([0, 1, 0, 1])
    # a 10 cm pose threshold without grace: the kick envs (error ~0.13 m) end on the first step, walk (~0.09) goes on
    rules = dict(pose_error_threshold=0.10, pose_error_grace_steps=0, reference_reward=True) if fidelity else {}
    envs = []
    for make in (
        lambda: CgailEnv(skills, env_cfg, seed=0, **rules),
        lambda: CgailDeviceEnv(skills, env_cfg, seed=0, sim=warp_sim_factory(4), **rules),
    ):
        env = make()
        env.forced_command = forced if isinstance(env, CgailEnv) else torch.as_tensor(forced)
        env.start_frame, env.random_yaw = 5, False
        env.reset(np.arange(4) if isinstance(env, CgailEnv) else torch.ones(4, dtype=torch.bool))
        envs.append(env)
    c_env, w_env = envs
    np.testing.assert_allclose(_np(w_env.state), c_env.state, atol=2e-4)
    np.testing.assert_allclose(_np(w_env.obs), c_env.obs, atol=2e-4)
    actions = np.random.default_rng(0).normal(scale=0.1, size=(4, 28))
    c_res, w_res = c_env.step(actions), w_env.step(torch.as_tensor(actions, dtype=torch.float32))
    assert_step_matches_cpu_env(c_env, c_res, w_env, w_res, fidelity)


@pytest.mark.slow
@needs_warp
def test_smoke_training_with_the_warp_backend_on_cpu(tmp_path):
    """`charctl train cgail scale=smoke env.backend=warp device=cpu` with the fidelity recipe's env rules
    (the clip phase in the state, pose-error and low-style terminations, r_track, fall-weighted commands)
    completes; its checkpoint has the CPU path's keys (plus the device env's generator state) and loads
    with the evaluation code."""
    from charctl.checkpoints import load_checkpoint
    from charctl.experiments.cgail.policy import load_trained_run

    res = run_charctl(
        "train",
        "cgail",
        "scale=smoke",
        "env.backend=warp",
        *FIDELITY_ENV_RULES,
        f"device={WARP_DEVICE}",
        f"output_root={tmp_path}",
        timeout=1800,
    )
    assert res.returncode == 0, res.stdout + res.stderr
    assert "done: iterations=4" in res.stdout
    (run_dir,) = (tmp_path / "cgail").iterdir()
    state = load_checkpoint(run_dir / "checkpoints" / "last.pt", "cgail")
    assert {"ppo", "disc", "disc_opt", "replay", "iteration", "samples", "torch_rng", "gen_rng"} <= set(state)
    assert "env_torch_rng" in state and state["replay"]["pairs"].device.type == "cpu"
    run = load_trained_run(run_dir)
    assert run.agent.samples == 512 and run.agent.model.obs_dim == 245  # 241 features + goal + phase
