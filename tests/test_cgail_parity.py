"""cgail parity checks that can fail: clip replayed through the simulator vs the clip path's
discriminator observations, a discriminator that separates data from a shifted copy (and not
from itself), and the tracking reward against hand-derived values."""

from __future__ import annotations

import numpy as np
import pytest
import torch

OBS_BLOCKS = {
    "root_height": slice(0, 1),
    "root_velocity": slice(1, 4),
    "root_angular_velocity": slice(4, 7),
    "joint_rotations": slice(7, 79),
    "body_velocities": slice(79, 121),
    "end_effectors": slice(121, 133),
}


@pytest.mark.parametrize("clip_name", ["walk", "run", "kick"])
def test_clip_replayed_through_simulator_gives_clip_observations(clip_name):
    """Every frame of a clip set as the simulator state gives the clip path's disc observation.

    Positions, rotations and the root velocities agree to 1e-9 (same FK, same qvel); body linear
    velocities come from MuJoCo's Jacobians of the finite-difference joint rates on one side and
    from finite differences of body positions on the other: they agree to 10 % relative RMS."""
    from charctl.experiments.cgail.features import clip_kinematics, disc_obs, sim_kinematics
    from charctl.motion.library import load_clip
    from charctl.sim.batch import BatchedHumanoid
    from charctl.sim.humanoid import clip_to_qpos_qvel

    clip = load_clip(clip_name).resample(30.0)
    qpos, qvel = clip_to_qpos_qvel(clip)
    frames = len(qpos)
    sim = BatchedHumanoid(frames)
    sim.set_state(np.arange(frames), qpos, qvel)
    o_sim, o_clip = disc_obs(sim_kinematics(sim)), disc_obs(clip_kinematics(clip))
    inner = slice(1, frames - 1)  # one-sided differences at the ends
    for name, cols in OBS_BLOCKS.items():
        err = o_sim[inner, cols] - o_clip[inner, cols]
        if name == "body_velocities":
            rel = np.sqrt((err**2).mean()) / np.sqrt((o_clip[inner, cols] ** 2).mean())
            assert rel < 0.10, (name, rel)
        else:
            assert np.abs(err).max() < 1e-9, (name, np.abs(err).max())


def _train_disc(data: torch.Tensor, other: torch.Tensor, steps: int = 300, seed: int = 0):
    from charctl.experiments.cgail.discriminator import Discriminator, gradient_penalty, style_loss

    torch.manual_seed(seed)
    disc = Discriminator(data.shape[1], 1, [64, 64], conditional=False)
    disc.norm.update(data)
    opt = torch.optim.Adam(disc.parameters(), lr=1e-3)
    gen = torch.Generator().manual_seed(seed)
    for _ in range(steps):
        a = data[torch.randint(0, len(data), (128,), generator=gen)]
        b = other[torch.randint(0, len(other), (128,), generator=gen)]
        d_a, _ = disc(a)
        d_b, _ = disc(b)
        loss = style_loss(d_a, d_b) + gradient_penalty(disc, disc.norm(a), 0.5)
        opt.zero_grad()
        loss.backward()
        opt.step()
    return disc


def _accuracy(disc, data: torch.Tensor, other: torch.Tensor) -> float:
    with torch.no_grad():
        return 0.5 * float((disc(data)[0] > 0).float().mean() + (disc(other)[0] < 0).float().mean())


def test_discriminator_separates_data_from_a_shifted_copy_and_not_from_itself():
    """Walk pairs vs pairs lifted 5 cm (root height + end effectors): separable (accuracy > 0.9 on
    held-out frames). Walk pairs vs walk pairs (two random halves): not (accuracy within 0.5 +- 0.15)."""
    from charctl.experiments.cgail.features import clip_kinematics, disc_obs
    from charctl.motion.library import load_clip

    # (o(t), o(t + 1/30 s)) at every 1/120 s of the clip: four times the pairs its 30-Hz frames give
    fine = disc_obs(clip_kinematics(load_clip("walk").resample(120.0)))
    pairs = torch.from_numpy(np.concatenate([fine[:-4], fine[4:]], axis=1).astype(np.float32))
    perm = torch.randperm(len(pairs), generator=torch.Generator().manual_seed(1))
    train_idx, test_idx = perm[: len(perm) // 2], perm[len(perm) // 2 :]
    shifted = pairs.clone()
    shifted[:, [0, 133]] += 0.05  # root height of o_t and o_t+1
    sep = _train_disc(pairs[train_idx], shifted[train_idx])
    assert _accuracy(sep, pairs[test_idx], shifted[test_idx]) > 0.9
    half_a, half_b = train_idx[: len(train_idx) // 2], train_idx[len(train_idx) // 2 :]
    same = _train_disc(pairs[half_a], pairs[half_b])
    assert abs(_accuracy(same, pairs[test_idx], pairs[test_idx]) - 0.5) < 0.15


def test_tracking_reward_hand_values():
    from charctl.experiments.cgail.rules import tracking_reward

    rng = np.random.default_rng(0)
    ref = rng.normal(size=(2, 133))
    assert tracking_reward(ref, ref) == pytest.approx([1.0, 1.0])
    obs = ref.copy()
    obs[0, 7] += 0.5  # one rotation-matrix entry off by 0.5: pose term exp(-0.25)
    obs[1, 121] += 0.1  # one end-effector coordinate off by 10 cm: ee term exp(-0.4)
    expected = [0.65 * np.exp(-0.25) + 0.35, 0.15 * np.exp(-0.4) + 0.85]
    assert tracking_reward(obs, ref) == pytest.approx(expected)


def test_tracking_env_phase_and_clip_end():
    """The reference frame advances one clip frame per control step; a non-looping clip truncates
    the episode at its last frame; the phase features are in the state."""
    from omegaconf import OmegaConf

    from charctl.experiments.cgail.config import EnvConfig, SkillConfig
    from charctl.experiments.cgail.env import CgailEnv
    from charctl.experiments.cgail.features import STATE_DIM
    from charctl.experiments.cgail.rules import GOAL_DIM, PHASE_DIM
    from charctl.experiments.cgail.skills import load_skills

    cfg = OmegaConf.structured(EnvConfig(num_envs=1, switch_prob=0.0, episode_seconds=100.0))
    skills = load_skills([SkillConfig("kick", "kick")], 30.0)
    env = CgailEnv(skills, cfg, seed=0, tracking=True)
    env.start_frame = len(skills[0].obs) - 4
    env.reset(np.arange(1))
    assert env.state.shape == (1, STATE_DIM + GOAL_DIM + PHASE_DIM)
    start = int(env.ref_frame[0])
    res = env.step(np.zeros((1, 28)))
    assert int(env.ref_frame[0]) == start + 1 and not res.truncated[0]
    res = env.step(np.zeros((1, 28)))
    res = env.step(np.zeros((1, 28)))
    assert res.truncated[0] or res.terminated[0]


def test_class_reward_forms_hand_values():
    """l1 (eq 4.8) = max(0, 2 P(c) - 1) for a one-hot command; prob = P(c); both blended by eq 4.11."""
    from charctl.experiments.cgail.discriminator import blended_class_reward

    probs = torch.tensor([[0.2, 0.7, 0.1], [0.2, 0.7, 0.1]])
    a, b, w = torch.tensor([1, 0]), torch.tensor([1, 1]), torch.tensor([1.0, 0.5])
    assert blended_class_reward(probs, a, b, w, 3, "l1").tolist() == pytest.approx([0.4, 0.5 * 0.0 + 0.5 * 0.4])
    assert blended_class_reward(probs, a, b, w, 3, "prob").tolist() == pytest.approx([0.7, 0.5 * 0.2 + 0.5 * 0.7])
    # logratio = log(3 P(c)), clipped below at -1: log 2.1 = 0.7419; log 0.6 = -0.5108; log 0.3 -> -1
    assert blended_class_reward(probs, a, b, w, 3, "logratio").tolist() == pytest.approx(
        [0.741937, 0.5 * -0.510826 + 0.5 * 0.741937], abs=1e-5
    )
    low = blended_class_reward(probs, torch.tensor([2, 2]), torch.tensor([2, 2]), w, 3, "logratio")
    assert low.tolist() == pytest.approx([-1.0, -1.0])
    with pytest.raises(ValueError):
        blended_class_reward(probs, a, b, w, 3, "other")
