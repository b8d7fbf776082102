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


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("arr", LIBS)
def test_pose_key_error_frames_last_gives_the_same_numbers(arr, dtype):
    """The frames-last form (the torch env's closest-frame search) equals `pose_key_error` over the
    frame-first clip bit for bit: 50 poses against 3 clips of 47 frames, with a root-height scale."""
    rng = np.random.default_rng(0)
    keys, clips = rng.normal(size=(50, 13)).astype(dtype), rng.normal(size=(3, 47, 13)).astype(dtype)
    cmd = rng.integers(0, 3, size=50)
    each = rules.pose_key_error(arr(keys)[:, None], arr(clips[cmd]), 2.5)
    frames_last = np.ascontiguousarray(clips.transpose(0, 2, 1))[cmd]
    assert np.array_equal(_np(rules.pose_key_error_frames(arr(keys), arr(frames_last), 2.5)), _np(each))


@pytest.mark.parametrize("arr", LIBS)
def test_root_height_threshold_scales_the_root_term_against_the_pose_threshold(arr):
    """Root 0.2 m lower and a hand 0.3 m off: with the pose threshold 0.5 m and a root-height radius of
    0.1 m the root counts 0.2 x 0.5 / 0.1 = 1.0 (> 0.5: ended); off (radius 0) it counts 0.2 (the hand's
    0.3 is the error); a root 0.05 m lower stays under the radius (0.25 < 0.5)."""
    assert rules.root_height_scale(0.5, 0.1) == pytest.approx(5.0)
    assert rules.root_height_scale(0.5, 0.0) == 1.0 and rules.root_height_scale(0.0, 0.1) == 1.0
    obs, ref = np.zeros((2, 133)), np.zeros((2, 133))
    obs[:, 0] = 0.9
    ref[:, 0] = [1.1, 0.95]
    ref[:, 121] = 0.3
    scaled = rules.reference_pose_error(arr(obs), arr(ref), rules.root_height_scale(0.5, 0.1))
    np.testing.assert_allclose(_np(scaled), [1.0, 0.3], atol=1e-12)
    np.testing.assert_allclose(_np(rules.reference_pose_error(arr(obs), arr(ref))), [0.3, 0.3], atol=1e-12)


@pytest.mark.parametrize("arr", LIBS)
def test_yaw_error_adds_up_the_yaw_rate_missed_and_counts_against_the_pose_threshold(arr):
    """Four envs, dt 0.1 s, pose threshold 0.5 m, heading radius 1.5 rad, the reference spinning at 5 rad/s:
    env 0 stands still with 1.2 rad already missed (-1.7 rad, 1.7 / 3 = 0.567 m: above 0.5, ended); env 1 spins
    with it (its 0.2 rad stay, 0.067 m under its hand's 0.1 m); env 2 is in grace steps and env 3 walks (a
    heading goal): neither counts, their heading errors restart at 0."""
    assert rules.yaw_scale(0.5, 1.5) == pytest.approx(1.0 / 3.0)
    assert rules.yaw_scale(0.5, 0.0) == 0.0 and rules.yaw_scale(0.0, 1.5) == 0.0
    obs, ref = np.zeros((4, 133)), np.zeros((4, 133))
    ref[:, rules.OBS_YAW_RATE] = 5.0
    obs[1, rules.OBS_YAW_RATE] = 5.0
    err = np.array([0.1, 0.1, 0.1, 0.1])
    yaw_err = np.array([-1.2, 0.2, -1.2, -1.2])
    active = np.array([True, True, True, True])
    grace = np.array([0, 0, 3, 0])
    goal = np.array([False, False, False, True])
    out, new = rules.add_yaw_error(
        arr(err), arr(yaw_err), arr(obs), arr(ref), arr(active), arr(grace), arr(goal), 0.1, 0.5 / 1.5
    )
    # env 0: -1.2 + (0 - 5) x 0.1 = -1.7 rad -> 1.7 / 3 = 0.5667 m; env 1: 0.2 rad -> 0.0667 < 0.1 keeps 0.1
    np.testing.assert_allclose(_np(new), [-1.7, 0.2, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(_np(out), [1.7 / 3.0, 0.1, 0.1, 0.1], atol=1e-6)


@pytest.mark.parametrize("arr", LIBS)
def test_goal_reference_frame_moves_on_within_its_window(arr):
    """reward.goal_reference_window on a looping 6-frame clip (period 5: frame 5 is frame 0 again), window 2.
    Row 0, advanced to frame 4: frames 4 and 0 (wrapped) are allowed, 0.2 beats 0.3, although frame 1 (0.0)
    is the closest anywhere. Row 1, advanced to 1: frames 1 and 2, 0.4 wins over 0.5 (frames 0, 3, 4 at 0.0 are
    out). Row 2 is as row 1 but in grace steps (not synced): the whole clip, frame 0. Window 0: the whole clip."""
    each = np.array(
        [
            [0.3, 0.0, 0.1, 0.1, 0.2, 0.0],
            [0.0, 0.5, 0.4, 0.0, 0.0, 0.0],
            [0.0, 0.5, 0.4, 0.0, 0.0, 0.0],
        ]
    )
    advanced, loops, n = np.array([4, 1, 1]), np.array([True, True, True]), np.array([6, 6, 6])
    synced = np.array([True, True, False])
    best = rules.goal_reference_frame(arr(each), arr(advanced), arr(loops), arr(n), 2, arr(synced))
    assert _np(best).tolist() == [4, 2, 0]
    anywhere = rules.goal_reference_frame(arr(each), arr(advanced), arr(loops), arr(n), 0, arr(synced))
    assert _np(anywhere).tolist() == [1, 0, 0]
    # a non-looping clip's period is its length: advanced to 5 with window 2 allows frames 5 and 0
    best = rules.goal_reference_frame(
        arr(each[:1]), arr(np.array([5])), arr(np.array([False])), arr(np.array([6])), 2, arr(np.array([True]))
    )
    assert _np(best).tolist() == [5]


def test_state_width():
    assert rules.state_dim(False) == 243 and rules.state_dim(True) == 245


# ---------------------------------------------------------------- per-env bookkeeping


def _switch_example(arr):
    """Five envs, commands B (`cmd`), A (`prev_cmd`), ramp weights w, reference states, the envs commanded
    (`mask`) and their new commands."""
    return dict(
        cmd=arr([1, 2, 0, 3, 1]),
        prev_cmd=arr([0, 1, 0, 2, 0]),
        w=arr([0.75, 0.25, 1.0, 0.5, 0.5]),
        ref_active=arr([True, True, True, True, False]),
        mask=arr([True, True, True, True, False]),
        new_cmd=arr([2, 0, 0, 1, 2]),
    )


@pytest.mark.parametrize("arr", LIBS)
def test_switch_commands_by_hand(arr):
    """Env 0: 1 -> 2 at w 0.75, B (1) dominates, so A = 1; env 1: 2 -> 0 at w 0.25, A (1) dominates, A = 1;
    env 2: commanded to its own skill 0, unchanged; env 3: 3 -> 1 at w 0.5 (a tie goes to B), A = 3; env 4:
    not in the mask, unchanged. The changed envs restart their ramp at w 0 and suspend their reference."""
    cmd, prev_cmd, w, active, changed = rules.switch_commands(**_switch_example(arr), ramp_frames=4)
    assert _np(changed).tolist() == [True, True, False, True, False]
    assert _np(cmd).tolist() == [2, 0, 0, 1, 1]
    assert _np(prev_cmd).tolist() == [1, 1, 0, 3, 0]
    assert _np(w).tolist() == [0.0, 0.0, 1.0, 0.0, 0.5]
    assert _np(active).tolist() == [False, False, True, False, False]


@pytest.mark.parametrize("arr", LIBS)
def test_switch_commands_without_a_ramp_switches_at_once(arr):
    """ramp_frames 0: the changed envs (0, 1, 3) go to w = 1 at once; A is still the dominant old command."""
    cmd, prev_cmd, w, active, changed = rules.switch_commands(**_switch_example(arr), ramp_frames=0)
    assert _np(w).tolist() == [1.0, 1.0, 1.0, 1.0, 0.5]
    assert _np(prev_cmd).tolist() == [1, 1, 0, 3, 0] and _np(cmd).tolist() == [2, 0, 0, 1, 1]
    assert _np(active).tolist() == [False, False, True, False, False]


def test_switch_commands_on_the_commanded_rows_equals_the_masked_form():
    """The CPU env passes the rows it commands (ids 0, 1, 3) with an all-true mask, the device env all rows
    with a mask: the same result on those rows."""
    full = rules.switch_commands(**_switch_example(np.asarray), ramp_frames=4)
    ids = np.array([0, 1, 3])
    rows = {k: v[ids] for k, v in _switch_example(np.asarray).items()}
    rows["mask"] = np.ones(3, dtype=bool)
    for a, b in zip(rules.switch_commands(**rows, ramp_frames=4), full, strict=True):
        assert a.tolist() == b[ids].tolist()


@pytest.mark.parametrize("arr", LIBS)
def test_advance_ramp_by_hand(arr):
    """Ramp over 4 frames: w + 1/4, at most 1 (0.875 -> 1.125 -> 1); no ramp (0 frames): w = 1."""
    w = arr([0.0, 0.5, 0.875, 1.0])
    assert _np(rules.advance_ramp(w, 4)).tolist() == [0.25, 0.75, 1.0, 1.0]
    assert _np(rules.advance_ramp(w, 0)).tolist() == [1.0, 1.0, 1.0, 1.0]


@pytest.mark.parametrize("arr", LIBS)
def test_restart_after_ramp_by_hand(arr):
    """Env 0 waits for its ramp, which has ended (w 1): frame 0, 3 grace steps, reference on; env 1 waits,
    ramp at 0.75: unchanged; envs 2 and 3 run their reference already (env 3 mid-ramp too): unchanged."""
    frame, grace, active = rules.restart_after_ramp(
        arr([7, 7, 7, 7]), arr([0, 1, 0, 2]), arr([False, False, True, True]), arr([1.0, 0.75, 1.0, 0.5]), 3
    )
    assert _np(frame).tolist() == [0, 7, 7, 7]
    assert _np(grace).tolist() == [3, 1, 0, 2]
    assert _np(active).tolist() == [True, False, True, True]


@pytest.mark.parametrize("arr", LIBS)
def test_count_down_grace_by_hand(arr):
    """Grace 0 stays 0, 1 -> 0, 3 -> 2; a clip that has just restarted gets the full grace (5)."""
    out = rules.count_down_grace(arr([0, 1, 3, 0]), arr([False, False, False, True]), 5)
    assert _np(out).tolist() == [0, 0, 2, 5]


@pytest.mark.parametrize("arr", LIBS)
def test_pose_check_by_hand(arr):
    """Threshold 0.5 m. Env 0: checked, 0.6 m -> ended; env 1: checked, 0.5 m is not above -> runs on;
    env 2: reference off (a ramp); env 3: in grace; env 4: fell; env 5: blew up -- none of 2-5 checked."""
    checked, ended = rules.pose_check(
        arr([True, True, False, True, True, True]),
        arr([0, 0, 0, 2, 0, 0]),
        arr([False, False, False, False, True, False]),
        arr([False, False, False, False, False, True]),
        arr([0.6, 0.5, 0.9, 0.9, 0.9, 0.9]),
        0.5,
    )
    assert _np(checked).tolist() == [True, True, False, False, False, False]
    assert _np(ended).tolist() == [True, False, False, False, False, False]


@pytest.mark.parametrize("arr", LIBS)
def test_checked_tracking_reward_by_hand(arr):
    """Env 0 matches its reference: 0.65 + 0.1 + 0.15 + 0.1 = 1; env 1 is 0.1 m higher at the root: the root
    term is exp(-10 * 0.01), r = 0.9 + 0.1 exp(-0.1); env 2 matches but is unchecked: 0."""
    obs, scored = np.zeros((3, 133)), np.zeros((3, 133))
    obs[1, 0] = 0.1
    out = rules.checked_tracking_reward(arr(obs), arr(scored), arr([True, True, False]))
    np.testing.assert_allclose(_np(out), [1.0, 0.9 + 0.1 * math.exp(-0.1), 0.0], atol=1e-12)


@pytest.mark.parametrize("arr", LIBS)
def test_reference_check_by_hand(arr):
    """Five envs, pose threshold 0.5 m, heading radius 1.5 rad (1/3 m per rad), dt 0.1 s, the timed reference
    spinning at 5 rad/s. Env 0 stands still, 1.2 rad already missed: -1.7 rad -> 0.567 m > 0.5, ended; it
    matches the pose it was scored against: r_track 1. Env 1 spins with the reference (0.2 rad stay) and is
    0.1 m higher at the root than its scored pose: 0.3 m runs on, r_track 0.9 + 0.1 exp(-0.1). Env 2 is in
    grace steps: unchecked (0.9 m ends nothing, r_track 0), heading error restarts at 0. Env 3 fell: unchecked,
    but its heading error adds up (-1.7). Env 4 walks (a heading goal): heading not counted (0), scored
    against a closest frame equal to its pose (r_track 1) although its timed reference is 1 m off. Without
    the radius and reward.w_track: the errors as given (nothing ended), yaw_err and r_track handed back."""
    obs = np.zeros((5, 133))
    obs[1, rules.OBS_YAW_RATE] = 5.0
    obs[1, 0] = 0.1
    scored = obs.copy()
    scored[1, 0] = 0.0
    ref = np.zeros((5, 133))
    ref[:, rules.OBS_YAW_RATE] = 5.0
    ref[4, 0] = 1.0
    err = np.array([0.1, 0.3, 0.9, 0.1, 0.2])
    yaw_err = np.array([-1.2, 0.2, -1.2, -1.2, -1.2])
    active = np.ones(5, dtype=bool)
    grace = np.array([0, 0, 3, 0, 0])
    goal = np.array([False, False, False, False, True])
    fell = np.array([False, False, False, True, False])
    unstable = np.zeros(5, dtype=bool)
    given = np.full(5, 0.7)  # r_track so far (the tracking baseline's)
    args = [arr(x) for x in (err, scored, obs, ref, given, yaw_err, active, grace, goal, fell, unstable)]
    r, ended, checked, new_yaw = rules.reference_check(
        *args, threshold=0.5, yaw_error_scale=0.5 / 1.5, dt=0.1, reference_reward=True
    )
    assert _np(checked).tolist() == [True, True, False, False, True]
    assert _np(ended).tolist() == [True, False, False, False, False]
    np.testing.assert_allclose(_np(new_yaw), [-1.7, 0.2, 0.0, -1.7, 0.0], atol=1e-12)
    np.testing.assert_allclose(_np(r), [1.0, 0.9 + 0.1 * math.exp(-0.1), 0.0, 0.0, 1.0], atol=1e-12)
    r, ended, checked, new_yaw = rules.reference_check(
        *args, threshold=0.5, yaw_error_scale=0.0, dt=0.1, reference_reward=False
    )
    assert _np(checked).tolist() == [True, True, False, False, True] and not _np(ended).any()
    assert _np(new_yaw).tolist() == yaw_err.tolist() and _np(r).tolist() == given.tolist()
