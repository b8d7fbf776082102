"""The humanoid's left/right mirror (charctl.experiments.cgail.symmetry) against an independent one, the clip
mirror of charctl.motion (`kick:mirror`), and the PPO mirror loss (charctl.rl.symmetry) by hand values."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from charctl.errors import CharctlError
from charctl.experiments.cgail.features import STATE_DIM, clip_kinematics, policy_state
from charctl.experiments.cgail.rules import GOAL_DIM, goal_features, state_dim
from charctl.experiments.cgail.symmetry import (
    action_mirror,
    build_mirror,
    command_mirror,
    mirror_problem,
    state_mirror,
    twin,
)
from charctl.motion.library import load_clip
from charctl.rl.config import PPOConfig
from charctl.rl.ppo import PPO, ActorCritic
from charctl.rl.storage import RolloutStorage
from charctl.rl.symmetry import Mirror, mirror_loss
from charctl.sim.humanoid import clip_to_qpos_qvel

PAPER_CLIPS = ["walk", "run", "jump", "dance_b", "dance_a", "spinkick", "punch:mirror", "punch", "kick", "kick:mirror"]


@pytest.fixture(scope="module")
def kick_pair():
    return load_clip("kick").resample(30.0), load_clip("kick:mirror").resample(30.0)


def test_twin_names():
    assert twin("right_hip") == "left_hip" and twin("left_wrist") == "right_wrist" and twin("chest") == "chest"


def test_state_mirror_maps_the_kick_onto_the_mirrored_clip(kick_pair):
    kick, mirrored = kick_pair
    perm, sign = state_mirror(phase=False)
    assert perm.shape == (state_dim(False),) and sorted(perm) == list(range(state_dim(False)))
    x, xm = policy_state(clip_kinematics(kick)), policy_state(clip_kinematics(mirrored))
    assert np.abs(xm).max() > 1.0  # the states are not trivially zero
    np.testing.assert_allclose(x[:, perm[:STATE_DIM]] * sign[:STATE_DIM], xm, atol=1e-9)
    assert np.abs(x - xm).max() > 0.5  # and the kick is not its own mirror


def test_state_mirror_of_the_goal_and_phase():
    perm, sign = state_mirror(phase=True)
    goal = slice(STATE_DIM, STATE_DIM + GOAL_DIM)
    g = goal_features(np.array([0.7]), np.array([0.2]), np.array([True]))  # relative yaw 0.5 rad
    gm = goal_features(np.array([-0.7]), np.array([-0.2]), np.array([True]))  # the mirrored yaws
    state = np.zeros((1, state_dim(True)))
    state[:, goal] = g
    state[:, -2:] = [0.3, 0.9]
    mirrored = state[:, perm] * sign
    np.testing.assert_allclose(mirrored[:, goal], gm, atol=1e-12)
    np.testing.assert_allclose(mirrored[:, -2:], [[0.3, 0.9]])


def test_action_mirror_maps_the_kick_hinges_onto_the_mirrored_clip(kick_pair):
    kick, mirrored = kick_pair
    perm, sign = action_mirror()
    q, _ = clip_to_qpos_qvel(kick)
    qm, _ = clip_to_qpos_qvel(mirrored)
    np.testing.assert_allclose(q[:, 7:][:, perm] * sign, qm[:, 7:], atol=1e-9)
    # by hand: the chest chain (ZYX, actions 0-2) keeps z and flips y and x; actions swap with their twins
    np.testing.assert_array_equal(perm[:3], [0, 1, 2])
    np.testing.assert_array_equal(sign[:3], [1, -1, -1])
    assert set(perm[3:]) == set(range(3, 28)) and not np.array_equal(perm[3:], np.arange(3, 28))


def test_command_mirror_pairs_only_mirrored_clips():
    perm, paired = command_mirror(PAPER_CLIPS)
    np.testing.assert_array_equal(perm, [0, 1, 2, 3, 4, 5, 7, 6, 9, 8])
    np.testing.assert_array_equal(paired, [False] * 6 + [True] * 4)
    perm3, paired3 = command_mirror(["walk", "run", "kick"])
    np.testing.assert_array_equal(perm3, [0, 1, 2])
    assert not paired3.any()


def test_mirror_problems_are_one_line_messages():
    assert mirror_problem(PAPER_CLIPS, True, "parent") is None
    assert "two skills whose clips mirror" in mirror_problem(["walk", "run", "kick"], True, "parent")
    assert "conditional" in mirror_problem(PAPER_CLIPS, False, "parent")
    assert "shoulder_frame" in mirror_problem(PAPER_CLIPS, True, "rotated")
    with pytest.raises(CharctlError, match="mirror each other"):
        build_mirror(["walk", "kick"], True, "parent", phase=True)


def _toy_mirror() -> Mirror:
    """obs (3): swap 0 and 1, flip 2; commands (3): 0 <-> 1 paired, 2 alone; actions (2): swap, second flipped."""
    return Mirror(
        np.array([1, 0, 2]),
        np.array([1.0, 1.0, -1.0]),
        np.array([1, 0, 2]),
        np.array([True, True, False]),
        np.array([1, 0]),
        np.array([1.0, -1.0]),
    ).to("cpu")


def test_mirror_applies_to_states_commands_and_actions_by_hand():
    m = _toy_mirror()
    np.testing.assert_allclose(m.obs(torch.tensor([[1.0, 2.0, 3.0]])), [[2.0, 1.0, -3.0]])
    np.testing.assert_allclose(m.cond(torch.tensor([[0.25, 0.75, 0.0]])), [[0.75, 0.25, 0.0]])
    np.testing.assert_allclose(m.actions(torch.tensor([[0.5, -2.0]])), [[-2.0, -0.5]])
    cond = torch.tensor([[1.0, 0.0, 0.0], [0.3, 0.7, 0.0], [0.5, 0.0, 0.5], [0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(m.applies(cond), [True, True, False, False])


def test_mirror_loss_by_hand():
    m = _toy_mirror()
    mean = torch.tensor([[0.5, -2.0], [1.0, 1.0]])  # mirrored: [-2, -0.5], [1, -1]
    mirrored_mean = torch.tensor([[-2.0, -0.5], [0.0, 1.0]])  # first symmetric; second off by (-1, 2)
    assert float(mirror_loss(mirrored_mean, mean, m)) == pytest.approx((0 + 0 + 1 + 4) / 4)
    assert float(mirror_loss(mirrored_mean[:0], mean[:0], m)) == 0.0


def _storage(model: ActorCritic, n_steps: int, n_envs: int, command: torch.Tensor) -> RolloutStorage:
    """A rollout of `model` on random states, all under `command`, with random advantages and returns."""
    g = torch.Generator().manual_seed(0)
    st = RolloutStorage(n_steps, n_envs, 3, 2, cond_dim=3)
    st.obs.copy_(torch.randn(st.obs.shape, generator=g))
    st.cond.copy_(command.expand(n_steps, n_envs, 3))
    actions, log_probs, values = model.act(st.obs, st.cond)
    st.actions.copy_(actions)
    st.log_probs.copy_(log_probs)
    st.values.copy_(values)
    st.advantages.copy_(torch.randn(st.advantages.shape, generator=g))
    st.returns.copy_(torch.randn(st.returns.shape, generator=g))
    return st


def _asymmetry(model: ActorCritic, m: Mirror, obs: torch.Tensor, cond: torch.Tensor) -> float:
    with torch.no_grad():
        return float(mirror_loss(model.mean_action(m.obs(obs), m.cond(cond)), model.mean_action(obs, cond), m))


def test_ppo_mirror_loss_makes_the_policy_symmetric_on_paired_commands_only():
    torch.manual_seed(0)
    obs = torch.randn(64, 3)
    paired, alone = torch.tensor([1.0, 0.0, 0.0]).expand(64, 3), torch.tensor([0.0, 0.0, 1.0]).expand(64, 3)
    m = _toy_mirror()
    result = {}
    for weight in (0.0, 10.0):
        torch.manual_seed(1)
        cfg = PPOConfig(hidden=[16], epochs=100, minibatch_size=32, lr=3e-3, mirror_loss=weight)
        model = ActorCritic(3, 2, cfg, cond_dim=3)
        with torch.no_grad():  # an output layer of the usual gain, so the policy starts clearly asymmetric
            model.actor[-1].weight.normal_(0.0, 0.5)
        ppo = PPO(model, cfg, generator=torch.Generator().manual_seed(0), mirror=m if weight else None)
        before = (_asymmetry(model, m, obs, paired), _asymmetry(model, m, obs, alone))
        stats = ppo.update(_storage(model, 8, 8, torch.tensor([1.0, 0.0, 0.0])))
        result[weight] = (before, (_asymmetry(model, m, obs, paired), _asymmetry(model, m, obs, alone)), stats)
    (before, after, stats) = result[10.0]
    assert "losses/mirror" in stats and "losses/mirror" not in result[0.0][2]
    assert after[0] < 0.02 * before[0]  # the paired command's outputs became mirror images (1.39 -> 0.010)
    assert result[0.0][1][0] > 0.5 * result[0.0][0][0]  # which plain PPO does not do (1.39 -> 1.35)
    # the unpaired command (skill 2, no sample of it in the batch) was not asked to be symmetric
    assert after[1] > 10 * after[0]  # (0.42)


def test_ppo_refuses_a_mirror_loss_without_a_mirror():
    cfg = PPOConfig(hidden=[8], mirror_loss=1.0)
    with pytest.raises(ValueError, match="mirror"):
        PPO(ActorCritic(3, 2, cfg, cond_dim=3), cfg)
