"""Humanoid MJCF, clip<->qpos mapping and the batched simulator."""

import mujoco
import numpy as np
import pytest

from charctl.motion import rotations as R
from charctl.motion.library import load_clip
from charctl.sim.batch import BatchedHumanoid, SimSettings
from charctl.sim.humanoid import clip_to_qpos_qvel, layout, load_model, qpos_to_local_rot


def test_model_mass_and_bodies():
    m = load_model()
    assert m.nbody == 16  # world + 15
    assert m.body_subtreemass[1] == pytest.approx(45.0)
    assert m.nu == layout().nu == 28


@pytest.mark.parametrize("name", ["walk", "backflip", "kick:mirror"])
def test_mujoco_fk_and_com_match_charctl(name):
    """MuJoCo's body positions and subtree COM equal charctl's FK/COM for every frame."""
    clip = load_clip(name)
    m = load_model()
    d = mujoco.MjData(m)
    qpos, _ = clip_to_qpos_qvel(clip)
    ids = [m.body(n).id for n in clip.skeleton.names]
    com = clip.com()
    for t in range(0, clip.num_frames, 3):
        d.qpos[:] = qpos[t]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        np.testing.assert_allclose(d.xpos[ids], clip.body_pos[t], atol=1e-9)
        np.testing.assert_allclose(d.subtree_com[1], com[t], atol=1e-9)


def _noisy_tracking_blowups(physics_hz: float, armature: float, seconds: float = 6.0) -> tuple[int, float]:
    """PD-track the walk clip from RSI with 0.1 rad target noise (64 envs, 2-s episodes).

    Returns (blow-ups, mean |q - q_ref| in rad)."""
    from charctl.sim.tracking import track_clip_with_noise

    sim = BatchedHumanoid(64, SimSettings(physics_hz=physics_hz, armature=armature, nthread=1))
    r = track_clip_with_noise(sim, noise=0.1, max_steps=int(seconds * 30), episode_steps=60, seed=0)
    return r.blowups, r.mean_error


def test_armature_keeps_150hz_stable():
    """The small preset's 150 Hz physics needs 0.05 kg m^2 armature: with the default 0.01 the same
    noisy tracking blows up; with 0.05 it does not and tracks as closely as 300 Hz (within 10 %)."""
    m = load_model(150.0, armature=0.05)
    assert m.opt.timestep == pytest.approx(1 / 150)
    assert np.allclose(m.dof_armature[6:], 0.05)  # every hinge dof (after the free root joint)
    bad_default, _ = _noisy_tracking_blowups(150.0, 0.01)
    bad, err = _noisy_tracking_blowups(150.0, 0.05)
    _, err_300 = _noisy_tracking_blowups(300.0, 0.01)
    assert bad_default > 0
    assert bad == 0
    assert err < 1.1 * err_300


def test_clip_qpos_round_trip():
    clip = load_clip("dance_a")
    qpos, _ = clip_to_qpos_qvel(clip)
    root, rot = qpos_to_local_rot(qpos)
    np.testing.assert_allclose(root, clip.root_pos, atol=1e-12)
    assert R.angle_between(rot, clip.local_rot).max() < 1e-6


def test_qvel_matches_finite_differences_of_simulated_kinematics():
    """Setting the clip's qvel gives MuJoCo body velocities close to the clip's finite differences."""
    clip = load_clip("walk")
    qpos, qvel = clip_to_qpos_qvel(clip)
    sim = BatchedHumanoid(1, SimSettings(nthread=1))
    sim.set_state(np.array([0]), qpos[10:11], qvel[10:11])
    lin, _ = sim.body_velocities()
    err = np.abs(lin[0] - clip.body_linear_velocity()[10]).mean()
    assert err < 0.05  # m/s; central differences at 30 fps


def _rollout(sim, qpos0, qvel0, targets):
    sim.set_state(np.arange(sim.num_envs), qpos0, qvel0)
    out = []
    for u in targets:
        sim.step(u)
        out.append(sim.qpos.copy())
    return np.array(out)


def test_batch_of_one_equals_batch_of_64():
    clip = load_clip("walk")
    qpos, qvel = clip_to_qpos_qvel(clip)
    targets = qpos[1:11, 7:]
    one = _rollout(BatchedHumanoid(1), qpos[:1], qvel[:1], targets[:, None])
    many = _rollout(
        BatchedHumanoid(64), np.repeat(qpos[:1], 64, 0), np.repeat(qvel[:1], 64, 0), np.repeat(targets[:, None], 64, 1)
    )
    np.testing.assert_array_equal(many[:, 17], one[:, 0])
    np.testing.assert_array_equal(many[:, 0], many[:, 63])


def test_injected_nan_resets_only_its_env():
    clip = load_clip("walk")
    qpos, qvel = clip_to_qpos_qvel(clip)
    n = 8
    resets = []
    sim = BatchedHumanoid(n, reset_fn=lambda ids: resets.append(ids.copy()))
    sim.set_state(np.arange(n), np.repeat(qpos[:1], n, 0), np.repeat(qvel[:1], n, 0))
    sim.step(np.repeat(qpos[1:2, 7:], n, 0))
    before = sim.qpos.copy()
    sim.qpos[5, 8] = np.nan
    bad = sim.step(np.repeat(qpos[2:3, 7:], n, 0))
    assert bad.tolist() == [i == 5 for i in range(n)]
    assert sim.unstable_count == 1
    assert len(resets) == 1 and resets[0].tolist() == [5]
    assert np.isfinite(sim.qpos).all()
    # the others kept simulating normally (moved on from their previous state)
    assert not np.allclose(sim.qpos[0], before[0])


def test_pd_holds_the_character_up_briefly():
    """PD tracking from a walk frame does not blow up and keeps the root above the knees for 0.5 s."""
    clip = load_clip("walk").resample(30)
    qpos, qvel = clip_to_qpos_qvel(clip)
    sim = BatchedHumanoid(4)
    sim.set_state(np.arange(4), np.repeat(qpos[:1], 4, 0), np.repeat(qvel[:1], 4, 0))
    for t in range(1, 16):
        sim.step(np.repeat(qpos[t : t + 1, 7:], 4, 0))
    assert sim.unstable_count == 0
    assert (sim.qpos[:, 1] > 0.6).all()


def test_fall_detection_geometry():
    sim = BatchedHumanoid(2)
    clip = load_clip("walk")
    qpos, qvel = clip_to_qpos_qvel(clip)
    q = np.repeat(qpos[:1], 2, 0)
    q[1, 1] = 0.05  # root dropped to the floor
    sim.set_state(np.arange(2), q, np.repeat(qvel[:1], 2, 0))
    assert sim.non_foot_ground_contact().tolist() == [False, True]
