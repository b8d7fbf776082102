"""env.clip_return_after_coverage: a skill's way back (env.clip_return_seconds) is switched on once its training
fidelity coverage reaches the gate; the switch rebuilds the reference tables and demonstrations, and checkpoints
carry it to a resumed run and to every evaluation."""

from __future__ import annotations

import numpy as np
import pytest

from charctl.config import compose_config
from charctl.errors import CharctlError
from charctl.experiments.cgail.agent import agent_state, build_agent, load_policy_state
from charctl.experiments.cgail.config import Config, EnvConfig, SkillConfig
from charctl.experiments.cgail.skills import load_skills, returning_after, switch_prob_for

GATED = [
    "scale=smoke",
    "env.clip_return_seconds=0.5",
    "env.clip_return_after_coverage=0.5",
    "env.phase_obs=true",
    "env.switch_prob_after_returns=0.03",
]


def test_a_skill_is_switched_on_at_the_gate_and_stays_on():
    skills = load_skills([SkillConfig("walk", "walk", heading_goal=True), SkillConfig("right_kick", "kick")], 30.0)
    assert returning_after({"walk": 1.0, "right_kick": 0.49}, skills, 0.5, ()) == ()  # walk loops: never
    assert returning_after({"walk": 1.0, "right_kick": 0.5}, skills, 0.5, ()) == ("right_kick",)
    assert returning_after({"right_kick": 0.1}, skills, 0.5, ("right_kick",)) == ("right_kick",)


def test_the_switch_rate_rises_once_every_way_back_is_on():
    """env.switch_prob_after_returns replaces env.switch_prob only when each non-looping skill returns; 0 leaves it."""
    skills = load_skills(
        [
            SkillConfig("walk", "walk", heading_goal=True),
            SkillConfig("right_kick", "kick"),
            SkillConfig("right_punch", "punch"),
        ],
        30.0,
    )
    env = EnvConfig(switch_prob=0.01, switch_prob_after_returns=0.03)
    assert switch_prob_for(env, skills, ()) == 0.01
    assert switch_prob_for(env, skills, ("right_kick",)) == 0.01  # the punch has none yet
    assert switch_prob_for(env, skills, ("right_kick", "right_punch")) == 0.03
    assert switch_prob_for(EnvConfig(switch_prob=0.01), skills, ("right_kick", "right_punch")) == 0.01
    assert switch_prob_for(env, skills[:1], ()) == 0.01  # only looping skills: nothing to wait for, nothing raised


def test_the_raised_switch_rate_needs_the_gate():
    with pytest.raises(CharctlError, match="set env.clip_return_after_coverage > 0 with it"):
        compose_config("cgail", ["scale=smoke", "env.switch_prob_after_returns=0.03"], Config)


def test_the_gate_needs_a_return_and_fidelity_checks():
    with pytest.raises(CharctlError, match="set env.clip_return_seconds > 0 and train.fidelity_every > 0"):
        compose_config("cgail", ["scale=smoke", "env.clip_return_after_coverage=0.5"], Config)
    with pytest.raises(CharctlError, match="set env.clip_return_seconds > 0 and train.fidelity_every > 0"):
        compose_config("cgail", [*GATED, "train.fidelity_every=0"], Config)


@pytest.fixture(scope="module")
def learner():
    from charctl.experiments.cgail.train import CgailLearner

    return CgailLearner(compose_config("cgail", GATED, Config))


def test_the_switch_lengthens_the_kicks_reference_and_demonstrations(learner):
    """The kick's 47 clip frames become 62 (0.5 s at 30 Hz appended) in the env's reference and RSI lengths and in
    the demonstration pairs (61 pairs from 62 frames, 46 before); the walk's stay as they were."""
    agent, env = learner.agent, learner.env
    assert agent.returning == () and env.clip_frames.tolist() == [len(agent.skills[0].obs), 47]
    walk_pairs = len(agent.demos.pairs[0])
    assert len(agent.demos.pairs[1]) == 46
    assert env.switch_prob == 0.01
    below = learner._switch_on_returns({"fidelity/walk/coverage": 1.0, "fidelity/right_kick/coverage": 0.4})
    assert below == {"returning/right_kick": 0.0, "returning/switch_prob": 0.01} and agent.returning == ()
    on = learner._switch_on_returns({"fidelity/walk/coverage": 1.0, "fidelity/right_kick/coverage": 0.6})
    assert on == {"returning/right_kick": 1.0, "returning/switch_prob": 0.03} and agent.returning == ("right_kick",)
    assert env.switch_prob == 0.03
    assert env.clip_frames.tolist() == [len(agent.skills[0].obs), 62] and env.rsi_frames.tolist()[1] == 62
    assert env.ref_obs.shape[1] == max(62, len(agent.skills[0].obs))
    assert [len(p) for p in agent.demos.pairs] == [walk_pairs, 61]
    assert agent.skills[1].clip_frames == 47  # evaluations still compare with the clip alone
    learner.iterate()  # the rollouts go on over the longer reference


def test_checkpoints_carry_the_switch_to_a_resume_and_to_inference(learner):
    from charctl.experiments.cgail.train import CgailLearner

    state = agent_state(learner.agent, learner.env)
    assert state["returning"] == ["right_kick"]
    resumed = CgailLearner(learner.cfg)
    assert resumed.agent.returning == ()
    resumed.load_state_dict(state)
    assert resumed.agent.returning == ("right_kick",) and resumed.env.clip_frames.tolist()[1] == 62
    assert resumed.env.switch_prob == 0.03
    inference = build_agent(learner.cfg, training=False)
    load_policy_state(inference, state)
    assert inference.returning == ("right_kick",) and len(inference.skills[1].obs) == 62
    np.testing.assert_allclose(inference.skills[1].obs, learner.agent.skills[1].obs)
