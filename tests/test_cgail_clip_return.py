"""env.clip_return_seconds: the right kick's reference gets a way back to its first pose; evaluations keep the clip."""

from __future__ import annotations

import numpy as np
import pytest

from charctl.experiments.cgail.config import SkillConfig
from charctl.experiments.cgail.fidelity import clip_reference
from charctl.experiments.cgail.rules import reference_pose_error
from charctl.experiments.cgail.skills import load_skills

SKILLS = [SkillConfig("walk", "walk", heading_goal=True), SkillConfig("right_kick", "kick")]


@pytest.fixture(scope="module")
def plain_and_returned():
    return load_skills(SKILLS, 30.0), load_skills(SKILLS, 30.0, return_seconds=0.5)


def test_the_kick_gets_fifteen_frames_and_the_walk_none(plain_and_returned):
    plain, returned = plain_and_returned
    assert [len(s.obs) for s in plain] == [s.clip_frames for s in plain] == [s.clip_frames for s in returned]
    assert len(returned[0].obs) == len(plain[0].obs)  # a looping clip is left as it is
    assert len(returned[1].obs) == len(plain[1].obs) + 15 == 62  # 0.5 s at 30 Hz after the kick's 47 frames


def test_the_return_closes_the_gap_the_restart_jumped(plain_and_returned):
    """The pose check's distance (largest hand / foot / root-height distance, heading frame) from the reference's
    last frame to frame 0, where it restarts: 0.35 m (the left foot) for the clip, under 1 cm with the return,
    and no step of the return farther than the clip's own largest step."""
    plain, returned = plain_and_returned
    kick, back = plain[1].obs, returned[1].obs
    assert reference_pose_error(kick[-1:], kick[:1])[0] == pytest.approx(0.3505, abs=1e-3)
    assert reference_pose_error(back[-1:], back[:1])[0] < 0.01
    steps = reference_pose_error(back[47:], back[46:-1])
    assert steps.max() < reference_pose_error(kick[1:], kick[:-1]).max()


def test_evaluations_compare_with_the_clip_alone(plain_and_returned):
    plain, returned = plain_and_returned
    own = returned[1].clip_only()
    assert len(own.obs) == len(own.qpos) == len(own.local_rot) == 47
    for key in ("qpos", "qvel", "obs", "local_rot"):  # the clip's own velocities too, at its last frame as well
        np.testing.assert_allclose(getattr(own, key), getattr(plain[1], key), atol=1e-9, err_msg=key)
    assert not np.allclose(returned[1].obs[46], plain[1].obs[46])  # the reference's last clip frame runs on
    assert returned[0].own_obs is None and plain[1].own_obs is None  # no return: nothing kept twice
    a, b = clip_reference(plain[1]), clip_reference(returned[1])
    np.testing.assert_allclose(b.body_pos, a.body_pos, atol=1e-9)
    assert b.signature() == pytest.approx(a.signature(), abs=1e-9)
