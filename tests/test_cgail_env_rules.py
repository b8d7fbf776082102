"""`env_rules`: the env's training rules read from a composed reward config, each key by hand, and the
training env built from it enforcing them."""

import pytest

from charctl.config import compose_config
from charctl.experiments.cgail.config import Config
from charctl.experiments.cgail.env_rules import env_rules


def _reward(*overrides: str):
    return compose_config("cgail", ["scale=small", *overrides], Config).reward


def test_each_rule_is_read_from_its_key():
    rules = env_rules(
        _reward(
            "reward.pose_error_threshold=0.4",
            "reward.pose_error_grace_steps=7",
            "reward.root_height_threshold=0.15",
            "reward.yaw_error_threshold=1.5",
            "reward.goal_reference_window=3",
            "reward.w_track=0.5",
        )
    )
    assert rules == dict(
        tracking=False,
        pose_error_threshold=0.4,
        pose_error_grace_steps=7,
        root_height_threshold=0.15,
        yaw_error_threshold=1.5,
        goal_reference_window=3,
        reference_reward=True,
    )


def test_tracking_and_no_tracking_reward():
    assert env_rules(_reward("use_skills=[walk]", "reward.kind=tracking"))["tracking"] is True
    assert env_rules(_reward("reward.w_track=0"))["reference_reward"] is False


def test_an_override_replaces_one_rule_and_a_misspelt_one_is_refused():
    rules = env_rules(_reward("reward.goal_reference_window=3"), goal_reference_window=0)
    assert rules["goal_reference_window"] == 0 and rules["pose_error_threshold"] == 0.5
    with pytest.raises(TypeError, match="not a rule: goal_window"):
        env_rules(_reward(), goal_window=0)


def test_the_training_env_enforces_them():
    from charctl.experiments.cgail.env import CgailEnv
    from charctl.experiments.cgail.skills import load_skills, select_skills

    cfg = compose_config(
        "cgail", ["scale=small", "use_skills=[walk]", "reward.yaw_error_threshold=1.5", "env.num_envs=2"], Config
    )
    env = CgailEnv(load_skills(select_skills(cfg), cfg.env.control_hz), cfg.env, seed=0, **env_rules(cfg.reward))
    assert env.pose_threshold == 0.5 and env.pose_grace == int(cfg.reward.pose_error_grace_steps)
    assert env.yaw_scale == pytest.approx(0.5 / 1.5) and env.root_scale == 1.0  # root_scale 1: no root radius
    assert env.timed_reference
