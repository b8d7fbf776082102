"""reward.w_track_skills: a tracking weight per skill, replacing reward.w_track for the named skills — the weights
by hand, the total reward by hand per command, the env told to compute r_track, the config's errors, and a tiny
training that takes it from the command line."""

from types import SimpleNamespace

import pytest
import torch
from omegaconf import OmegaConf

from charctl.config import compose_config
from charctl.experiments.cgail.config import Config
from charctl.experiments.cgail.env_rules import env_rules
from charctl.experiments.cgail.reward import total_reward, track_weights


def _reward_cfg(w_track: float, per_skill: dict) -> SimpleNamespace:
    return SimpleNamespace(
        kind="adversarial", w_style=0.8, w_class=0.2, w_goal=0.0, w_track=w_track, w_track_skills=per_skill
    )


def _agent(w_track: float, per_skill: dict) -> SimpleNamespace:
    skills = [SimpleNamespace(name=n) for n in ("walk", "run", "spindance")]
    return SimpleNamespace(cfg=SimpleNamespace(reward=_reward_cfg(w_track, per_skill)), skills=skills, conditional=True)


def test_weights_follow_the_named_skills_and_w_track_elsewhere():
    w = track_weights(_reward_cfg(1.0, {"spindance": 4.0}), ["walk", "run", "spindance"])
    assert w.tolist() == [1.0, 1.0, 4.0]
    w = track_weights(_reward_cfg(0.0, {"run": 0.5}), ["walk", "run"])
    assert w.tolist() == [0.0, 0.5]


def test_total_reward_weights_each_steps_tracking_reward_by_its_command():
    agent = _agent(1.0, {"spindance": 4.0})
    rewards = {"r_style": torch.tensor([[0.5, 0.5, 0.5]]), "r_class": torch.tensor([[1.0, 1.0, 1.0]])}
    r_track = torch.tensor([[0.25, 0.25, 0.25]])
    cmd = torch.tensor([[0, 2, 1]])
    r = total_reward(agent, rewards, torch.zeros(1, 3), r_track, cmd)
    # 0.8 * 0.5 + 0.2 * 1.0 = 0.6, plus w_T * 0.25 with w_T = 1, 4, 1
    assert r[0].tolist() == pytest.approx([0.85, 1.6, 0.85])
    with pytest.raises(ValueError, match="needs the commands"):
        total_reward(agent, rewards, torch.zeros(1, 3), r_track)


def test_without_per_skill_weights_the_total_is_unchanged():
    agent = _agent(1.0, {})
    rewards = {"r_style": torch.tensor([[0.5]]), "r_class": torch.tensor([[1.0]])}
    r = total_reward(agent, rewards, torch.zeros(1, 1), torch.tensor([[0.25]]))
    assert r[0].tolist() == pytest.approx([0.85])


def test_a_per_skill_weight_alone_turns_the_tracking_reward_on():
    reward = compose_config(
        "cgail", ["scale=small", "reward.w_track=0", "reward.w_track_skills={spindance:4.0}"], Config
    )
    assert reward.reward.w_track_skills == {"spindance": 4.0}
    assert env_rules(reward.reward)["reference_reward"] is True


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"reward": {"pose_error_threshold": 0.5, "w_track_skills": {"spin": 4.0}}}, "names unknown skill(s) ['spin']"),
        ({"reward": {"pose_error_threshold": 0.5, "w_track_skills": {"jump": -1.0}}}, "must be >= 0, got jump=-1.0"),
        ({"reward": {"w_track_skills": {"jump": 2.0}}}, "needs reward.pose_error_threshold > 0"),
    ],
)
def test_config_errors(overrides, message):
    cfg = OmegaConf.merge(OmegaConf.structured(Config), overrides)
    assert message in Config.check(cfg)


def test_training_takes_it_from_the_command_line(tmp_path):
    from charctl.experiments.cgail.train import CgailLearner

    cfg = compose_config(
        "cgail",
        [
            "scale=smoke",
            "use_skills=[walk,spindance]",
            "reward.pose_error_threshold=0.5",
            "reward.w_track=0",
            "reward.w_track_skills={spindance:4.0}",
            "env.num_envs=4",
            "train.rollout_steps=8",
            "train.fidelity_every=0",
            f"output_root={tmp_path}",
        ],
        Config,
    )
    stats = CgailLearner(cfg).iterate()
    assert stats["train/episode_length"] > 0
