"""The cgail env rules (`rules.py`), one implementation for numpy and torch: hand-derived values, each
checked on numpy arrays and on torch tensors (the CPU env and the Warp env / web graph call the same code)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from charctl.experiments.cgail import rules

LIBS = [pytest.param(np.asarray, id="numpy"), pytest.param(torch.as_tensor, id="torch")]


def _np(x) -> np.ndarray:
    return x.numpy() if isinstance(x, torch.Tensor) else np.asarray(x)


@pytest.mark.parametrize("arr", LIBS)
def test_reference_clock_wraps_loops_and_ends_or_restarts_the_others(arr):
    """Clip of 5 frames (last frame index 4 = first of the next loop for a looping clip). Looping: 3 -> 0
    (4 mod 4); non-looping: 3 -> 4 and ends there (4 stays 4), or, with restart, 4 -> 0 and restarted."""
    frame, loops, frames = arr([3, 3, 4, 2]), arr([True, False, False, False]), arr([5, 5, 5, 5])
    new, ended, again = rules.advance_reference(frame, loops, frames, restart=False)
    assert _np(new).tolist() == [0, 4, 4, 3]
    assert _np(ended).tolist() == [False, True, True, False] and not _np(again).any()
    new, ended, again = rules.advance_reference(frame, loops, frames, restart=True)
    assert _np(new).tolist() == [0, 4, 0, 3]
    assert _np(again).tolist() == [False, False, True, False] and not _np(ended).any()


@pytest.mark.parametrize("arr", LIBS)
def test_phase_features_by_hand(arr):
    """Frame 2 of a 5-frame clip: phase 2 pi 2/4 = pi -> (-1, 0); frame 1 of 5: pi/2 -> (0, 1); hidden -> (0, 0)."""
    out = rules.phase_features(arr([2, 1, 1]), arr([5, 5, 5]), arr([True, True, False]))
    np.testing.assert_allclose(_np(out), [[-1.0, 0.0], [0.0, 1.0], [0.0, 0.0]], atol=1e-7)
    np.testing.assert_allclose(_np(rules.phase_features(arr([0]), arr([1]))), [[1.0, 0.0]])  # 1 frame: no division by 0


@pytest.mark.parametrize("arr", LIBS)
def test_goal_features_are_the_goal_relative_to_the_heading(arr):
    """Goal yaw pi/2, heading pi/6: relative pi/3 -> (1/2, sqrt 3/2); no goal -> (0, 0)."""
    goal, heading = arr([math.pi / 2, math.pi / 2]), arr([math.pi / 6, math.pi / 6])
    out = rules.goal_features(goal, heading, arr([True, False]))
    np.testing.assert_allclose(_np(out), [[0.5, math.sqrt(3) / 2], [0.0, 0.0]], atol=1e-7)


@pytest.mark.parametrize("arr", LIBS)
def test_goal_reward_by_hand(arr):
    """Goal yaw 0 (+x): COM velocity (1.5, 0, 0) against v* 1.5 -> 1; (0.5, 0, 0) -> exp(-2 * 1) with
    sharpness 2; goal yaw pi/2 points to -z: velocity (0, 0, -1.5) -> 1; a skill without a goal -> 1."""
    goal = arr([0.0, 0.0, math.pi / 2, 0.0])
    vel = arr([[1.5, 0, 0], [0.5, 0, 0], [0, 0, -1.5], [0, 0, 0]])
    out = rules.goal_reward(goal, vel, arr([1.5, 1.5, 1.5, 1.5]), arr([True, True, True, False]), 2.0)
    np.testing.assert_allclose(_np(out), [1.0, math.exp(-2.0), 1.0, 1.0], atol=1e-7)


@pytest.mark.parametrize("arr", LIBS)
def test_pose_key_error_broadcasts_over_clip_frames(arr):
    """One pose against a 3-frame clip: frame 0 equal (0), frame 1 with the left hand 0.3 m off (0.3),
    frame 2 with the root 0.2 m lower (0.2): the (1, 3) errors and the closest frame 0."""
    obs = np.zeros((1, 133))
    obs[0, 0] = 0.9
    clip = np.repeat(obs, 3, axis=0)
    clip[1, 121] += 0.3
    clip[2, 0] -= 0.2
    each = rules.pose_key_error(rules.pose_keys(arr(obs))[:, None], rules.pose_keys(arr(clip))[None])
    np.testing.assert_allclose(_np(each), [[0.0, 0.3, 0.2]], atol=1e-12)
    np.testing.assert_allclose(_np(rules.reference_pose_error(arr(obs), arr(clip[1:2]))), [0.3], atol=1e-12)


def test_state_width():
    assert rules.state_dim(False) == 243 and rules.state_dim(True) == 245
