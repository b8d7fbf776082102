"""Early termination on a large pose error against the commanded clip (reward.pose_error_threshold):
the error by hand, the reference's timing (RSI, restart of a non-looping clip, start after a command
switch's ramp), the closest-frame rule of locomotion clips, and the learner's counters."""

import importlib.util

import numpy as np
import pytest
from omegaconf import OmegaConf

from charctl.experiments.cgail.config import EnvConfig, SkillConfig
from charctl.experiments.cgail.env import CgailEnv
from charctl.experiments.cgail.rules import add_yaw_error, reference_pose_error
from charctl.experiments.cgail.skills import load_skills

needs_warp = pytest.mark.skipif(importlib.util.find_spec("mujoco_warp") is None, reason="needs MuJoCo Warp")


@pytest.fixture(scope="module")
def skills():
    return load_skills([SkillConfig("walk", "walk", heading_goal=True), SkillConfig("kick", "kick")], 30.0)


def _env(skills, n=2, threshold=0.5, grace=3, ramp=4):
    cfg = OmegaConf.structured(EnvConfig(num_envs=n, ramp_frames=ramp, switch_prob=0.0))
    return CgailEnv(skills, cfg, seed=0, pose_error_threshold=threshold, pose_error_grace_steps=grace)


def test_pose_error_is_the_largest_end_effector_or_root_height_distance():
    obs, ref = np.zeros((3, 133)), np.zeros((3, 133))
    ref[0, 121 + 3 : 121 + 6] = [0.3, 0.4, 0.0]  # second end effector 0.5 m away (3-4-5)
    ref[1, 0] = -0.7  # root 0.7 m lower; a 0.2 m hand offset is smaller
    ref[1, 121:124] = [0.0, 0.2, 0.0]
    obs[2, 1:121] = 5.0  # velocities and joint rotations do not count
    assert reference_pose_error(obs, ref) == pytest.approx([0.5, 0.7, 0.0])


def test_reference_runs_on_from_the_rsi_frame_and_a_non_looping_clip_restarts_with_grace(skills):
    env = _env(skills, grace=3)
    env.forced_command = np.array([1, 1])
    env.start_frame = 5
    env.reset(np.arange(2))
    assert env.ref_frame.tolist() == [5, 5] and env.ref_active.all() and (env.ref_grace == 0).all()
    last = len(skills[1].obs) - 1
    env.ref_frame[:] = last - 1
    env._advance_phase(restart=True)
    assert env.ref_frame.tolist() == [last, last] and (env.ref_grace == 0).all()
    env._advance_phase(restart=True)  # past the last frame: back to the clip's start, unchecked for 3 steps
    assert env.ref_frame.tolist() == [0, 0] and env.ref_grace.tolist() == [3, 3]
    env._advance_phase(restart=True)
    assert env.ref_frame.tolist() == [1, 1] and env.ref_grace.tolist() == [2, 2]


def test_a_step_returns_the_reference_its_pose_check_compared(skills):
    """The kick (no heading goal) is scored against its timed frame: RSI at frame 5, one control step on, frame 6
    of the clip's disc observations (the clip is resampled at the 30-Hz control rate). Without a check: None."""
    env = _env(skills)
    env.forced_command = np.array([1, 1])
    env.start_frame, env.random_yaw = 5, False
    env.reset(np.arange(2))
    res = env.step(np.zeros((2, 28)))
    np.testing.assert_array_equal(res.pose_reference, skills[1].obs[[6, 6]])
    assert _env(skills, threshold=0.0).step(np.zeros((2, 28))).pose_reference is None


def test_a_switch_suspends_the_check_until_the_ramp_ends_then_starts_the_new_clip_at_frame_zero(skills):
    env = _env(skills, grace=2, ramp=4)
    env.forced_command = np.array([0, 0])
    env.reset(np.arange(2))
    env.set_command(np.array([0]), 1, ramp=True)
    assert env.ref_active.tolist() == [False, True]
    for _ in range(3):  # w = 0.25, 0.5, 0.75
        env._advance_ramp()
        env._restart_reference_after_ramp()
        assert env.ref_active.tolist() == [False, True]
    env._advance_ramp()  # w = 1: the kick's reference starts at its first frame, unchecked for 2 steps
    env._restart_reference_after_ramp()
    assert env.ref_active.tolist() == [True, True] and env.ref_frame[0] == 0 and env.ref_grace[0] == 2


def test_locomotion_clips_are_scored_against_their_closest_frame_and_others_against_the_timed_one(skills):
    env = _env(skills)
    env.cmd[:] = [0, 1]
    obs = np.stack([skills[0].obs[17], skills[1].obs[20]])
    env.ref_frame[:] = [3, 3]  # walk: frame 17 is still a walk pose (0 error); kick: frame 3 is not frame 20
    err, scored = env._pose_error(obs, env._reference_obs())
    assert err[0] == pytest.approx(0.0, abs=1e-12) and np.array_equal(scored[0], skills[0].obs[17])
    assert np.array_equal(scored[1], skills[1].obs[3])
    assert err[1] == pytest.approx(reference_pose_error(obs[1:], skills[1].obs[3:4])[0]) and err[1] > 0.5


def test_a_goal_reference_window_moves_the_walk_reference_on_past_a_held_pose(skills):
    """reward.goal_reference_window: a walk pose held still (a shuffle that never leaves its frame) is scored 0
    against the closest frame anywhere, but with a 3-frame window the reference moves on one frame or more per
    step, so the held pose's error grows with the gait cycle it leaves out (past 0.15 m within 19 steps, half a
    cycle of the 38-frame loop), and the reference frames are 18, 19, ... as the clip's own timing."""
    held = skills[0].obs[17][None]
    errors = {}
    for window in (0, 3):
        cfg = OmegaConf.structured(EnvConfig(num_envs=1, switch_prob=0.0))
        env = CgailEnv(skills, cfg, seed=0, pose_error_threshold=0.5, goal_reference_window=window)
        env.cmd[:], env.ref_frame[:], env.ref_grace[:] = 0, 17, 0
        errs, frames = [], []
        for _ in range(19):
            ref, _ = env._advance_phase(restart=True)
            err, _ = env._pose_error(held, ref)
            errs.append(float(err[0]))
            frames.append(int(env.ref_frame[0]))
        errors[window] = errs
        if window:
            assert frames == list(range(18, 37))  # the closest allowed frame is always the nearest one ahead
    assert max(errors[0]) == pytest.approx(0.0, abs=1e-12)
    assert errors[3][0] < 0.1 and max(errors[3]) > 0.15


def test_an_in_place_looping_clip_keeps_its_timing():
    """The jump loops but has no heading goal: a pose held from its crouch is scored against the frame the
    clip has moved on to (the closest-frame rule would let a standing policy pass it)."""
    skills = load_skills([SkillConfig("walk", "walk", heading_goal=True), SkillConfig("jump", "jump")], 30.0)
    assert skills[1].loop and not skills[1].heading_goal
    env = _env(skills)
    env.cmd[:] = [1, 1]
    crouch = skills[1].obs[0]
    env.ref_frame[:] = [0, 25]  # at frame 0 the pose is the reference; 25 frames (0.83 s) later the jump is airborne
    err, scored = env._pose_error(np.stack([crouch, crouch]), env._reference_obs())
    assert err[0] == pytest.approx(0.0, abs=1e-12) and np.array_equal(scored[1], skills[1].obs[25])
    assert err[1] == pytest.approx(reference_pose_error(crouch[None], skills[1].obs[25:26])[0]) and err[1] > 0.3


def test_a_root_height_radius_ends_a_jump_done_on_the_ground():
    """reward.root_height_threshold: the jump's highest frame with the root put 0.2 m lower (hands and feet
    unchanged relative to the root) is within the 0.5 m pose threshold, but beyond a 0.15 m root radius."""
    skills = load_skills([SkillConfig("jump", "jump")], 30.0)
    top = int(np.argmax(skills[0].obs[:, 0]))
    grounded = skills[0].obs[top].copy()
    grounded[0] -= 0.2
    for radius, ended in ((0.0, False), (0.15, True)):
        cfg = OmegaConf.structured(EnvConfig(num_envs=1, switch_prob=0.0))
        env = CgailEnv(skills, cfg, seed=0, pose_error_threshold=0.5, root_height_threshold=radius)
        env.ref_frame[:] = top
        err, _ = env._pose_error(grounded[None], env._reference_obs())
        assert err[0] == pytest.approx(0.2 * (0.5 / radius if radius else 1.0))
        assert bool(err[0] > env.pose_threshold) is ended


def test_a_heading_radius_ends_a_spin_done_without_turning():
    """reward.yaw_error_threshold: the spindance clip turns 2 pi per loop; its first pose held still (hands and
    feet as the clip's, no turn) is ended once the missed yaw passes 1.5 rad, never with the radius off. The
    simulated yaw rate is replaced by the held pose's 0 through `step`'s observation, so the count is exact:
    the clip's own yaw rates summed frame by frame."""
    skills = load_skills([SkillConfig("spindance", "dance_a")], 30.0)
    w = skills[0].obs[:, 5]
    missed = np.cumsum(w[1:]) / 30.0  # rad missed after each step from frame 0 (the reference runs on)
    first = int(np.argmax(np.abs(missed) > 1.5))
    assert 5 < first < 30  # within a second: the clip turns at 4.7 rad/s on average
    for radius, ends_at in ((0.0, None), (1.5, first)):
        cfg = OmegaConf.structured(EnvConfig(num_envs=1, switch_prob=0.0))
        env = CgailEnv(skills, cfg, seed=0, pose_error_threshold=0.5, yaw_error_threshold=radius)
        env.ref_frame[:] = 0
        still = skills[0].obs[:1].copy()
        still[:, 5] = 0.0
        ended = None
        for t in range(40):
            ref, _ = env._advance_phase(restart=True)
            err, _ = env._pose_error(skills[0].obs[env.ref_frame], ref)  # hands and feet on the reference
            if env.yaw_scale > 0:
                err, env.yaw_err = add_yaw_error(
                    err,
                    env.yaw_err,
                    still,
                    ref,
                    env.ref_active,
                    env.ref_grace,
                    env.has_goal[env.cmd],
                    1 / 30.0,
                    env.yaw_scale,
                )
            if err[0] > env.pose_threshold:
                ended = t
                break
        assert ended == ends_at


def test_step_applies_the_heading_radius():
    """The env's step wires the heading check in: with a 10 m pose threshold nothing else can end the spin,
    and a 0.1 mrad heading radius ends it at the first simulated step (the yaw rates never match that
    closely); with the radius off it does not end."""
    skills = load_skills([SkillConfig("spindance", "dance_a")], 30.0)
    for radius, ended in ((0.0, False), (1e-4, True)):
        cfg = OmegaConf.structured(EnvConfig(num_envs=2, switch_prob=0.0))
        env = CgailEnv(
            skills, cfg, seed=0, pose_error_threshold=10.0, pose_error_grace_steps=0, yaw_error_threshold=radius
        )
        res = env.step(np.zeros((2, 28)))
        assert bool(res.pose_ended.all()) is ended and bool(res.terminated.all()) is ended
        assert (env.yaw_err == 0).all()  # restarted at 0: ended envs were reset, the others never counted


def test_episodes_that_leave_the_reference_end_without_counting_a_fall(skills):
    """A threshold of 1 mm ends every checked kick episode after its first simulated step; 10 m never does."""
    strict = _env(skills, threshold=1e-3, grace=0)
    strict.forced_command = np.array([1, 1])
    strict.reset(np.arange(2))
    res = strict.step(np.zeros((2, 28)))
    assert res.pose_ended.all() and res.terminated.all() and strict.fall_count == 0
    # ...but as a failure of the skill for fall-weighted commands: half-life 200 episodes, 2 failed episodes
    a = 0.5 ** (2 / 200.0)
    assert strict.fall_rate.tolist() == pytest.approx([0.5, a * 0.5 + (1 - a) * 1.0])
    loose = _env(skills, threshold=10.0, grace=0)
    loose.forced_command = np.array([1, 1])
    loose.reset(np.arange(2))
    assert not loose.step(np.zeros((2, 28))).pose_ended.any()


@pytest.mark.parametrize("backend", ["cpu", pytest.param("warp", marks=needs_warp)])
def test_learner_counts_pose_terminations_apart_from_falls(backend):
    """Both backends (the Warp env on the CPU here) end every step by the pose check at a 1 mm threshold."""
    from charctl.experiments.cgail.config import Config
    from charctl.experiments.cgail.train import CgailLearner

    cfg = OmegaConf.merge(
        OmegaConf.structured(Config),
        {
            "use_skills": ["walk", "right_kick"],
            "device": "cpu",
            "env": {"num_envs": 4, "episode_seconds": 5.0, "backend": backend},
            "ppo": {"hidden": [16], "minibatch_size": 32, "epochs": 1},
            "disc": {"hidden": [16], "batch_size": 32, "steps_per_iter": 1, "replay_size": 256},
            "reward": {"pose_error_threshold": 1e-3, "pose_error_grace_steps": 0},
            "train": {"rollout_steps": 8, "torch_threads": 1, "fidelity_every": 0},
        },
    )
    stats = CgailLearner(cfg).iterate()
    # 1 mm: every step of every episode ends it (RSI states are exact, the first physics step is not)
    assert stats["train/pose_terminations"] == 4 * 8 and stats["train/falls"] == 0
    assert stats["train/episode_length"] == 1.0


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"reward": {"pose_error_threshold": -0.1}}, "must be >= 0"),
        ({"reward": {"pose_error_grace_steps": -1}}, "must be >= 0"),
        ({"reward": {"low_style_threshold": 0.05, "kind": "tracking"}}, "needs reward.kind=adversarial"),
    ],
)
def test_config_errors(overrides, message):
    from charctl.experiments.cgail.config import Config

    cfg = OmegaConf.merge(OmegaConf.structured(Config), overrides)
    assert message in Config.check(cfg)


def test_reference_reward_is_the_tracking_reward_where_the_reference_is_checked(skills):
    """reward.w_track: r_track against the pose-error reference, 0 for an env whose check is off (grace)."""
    from charctl.experiments.cgail.rules import tracking_reward

    cfg = OmegaConf.structured(EnvConfig(num_envs=2, ramp_frames=4, switch_prob=0.0))
    env = CgailEnv(skills, cfg, seed=0, pose_error_threshold=10.0, pose_error_grace_steps=5, reference_reward=True)
    env.forced_command = np.array([1, 1])
    env.start_frame = 3
    env.reset(np.arange(2))
    env.ref_grace[1] = 3  # env 1 unchecked this step
    res = env.step(np.zeros((2, 28)))
    want = tracking_reward(res.pair_next[:1], skills[1].obs[4:5])[0]  # RSI frame 3 -> reference frame 4
    assert res.r_track[0] == pytest.approx(want) and 0.0 < want <= 1.0
    assert res.r_track[1] == 0.0


def test_w_track_needs_the_pose_error_reference():
    from charctl.experiments.cgail.config import Config

    cfg = OmegaConf.merge(OmegaConf.structured(Config), {"reward": {"w_track": 0.5}})
    assert "reward.w_track" in Config.check(cfg)
    cfg = OmegaConf.merge(cfg, {"reward": {"pose_error_threshold": 0.5}})
    assert Config.check(cfg) is None


def test_phase_obs_puts_the_timed_reference_phase_in_the_state(skills):
    """env.phase_obs: (cos, sin) of the kick's reference frame appended to the state, advancing one frame per
    control step from the RSI frame even without a pose-error check; (0, 0) for walk (heading goal) and while
    a switch's ramp runs; the state grows by 2 and nothing else in it changes."""
    cfg = OmegaConf.structured(EnvConfig(num_envs=2, ramp_frames=4, switch_prob=0.0, phase_obs=True))
    env = CgailEnv(skills, cfg, seed=0)
    plain = _env(skills, threshold=0.0)
    assert env.state_dim == plain.state_dim + 2
    for e in (env, plain):
        e.forced_command = np.array([0, 1])
        e.start_frame = 5
        e.reset(np.arange(2))
    frames = len(skills[1].obs) - 1
    angle = 2 * np.pi * 5 / frames
    assert env.state[:, -2:] == pytest.approx(np.array([[0.0, 0.0], [np.cos(angle), np.sin(angle)]]))
    assert np.array_equal(env.state[:, :-2], plain.state)  # same physics, same seed
    env.step(np.zeros((2, 28)))
    angle = 2 * np.pi * 6 / frames
    assert env.state[1, -2:] == pytest.approx([np.cos(angle), np.sin(angle)])
    env.set_command(np.array([1]), 0)  # kick -> walk: a heading goal, so no phase
    env.set_command(np.array([0]), 1)  # walk -> kick: no phase until the ramp ends, then frame 0
    env.step(np.zeros((2, 28)))
    assert env.state[:, -2:] == pytest.approx(np.zeros((2, 2)))
    for _ in range(3):  # the ramp ends in the 4th step: the reference starts at frame 0 after that step's state
        env.step(np.zeros((2, 28)))
    assert env.ref_frame[0] == 0 and env.state[0, -2:] == pytest.approx([0.0, 0.0])
    env.step(np.zeros((2, 28)))
    angle = 2 * np.pi * 1 / frames
    assert env.ref_frame[0] == 1 and env.state[0, -2:] == pytest.approx([np.cos(angle), np.sin(angle)])


def test_the_tracking_baseline_can_end_its_episodes_on_the_pose_check(skills):
    """reward.kind=tracking with a pose threshold: the kick's clip runs on from the RSI frame as in tracking (no
    restart), r_track stays the tracking reward, and an env farther than the threshold ends (1 mm: every checked
    env); without the threshold the same step ends nothing."""
    from charctl.experiments.cgail.rules import tracking_reward

    cfg = OmegaConf.structured(EnvConfig(num_envs=2, switch_prob=0.0))
    strict = CgailEnv(skills, cfg, seed=0, tracking=True, pose_error_threshold=1e-3, pose_error_grace_steps=0)
    plain = CgailEnv(skills, cfg, seed=0, tracking=True)
    for env in (strict, plain):
        env.forced_command = np.array([1, 1])
        env.start_frame, env.random_yaw = 3, False
        env.reset(np.arange(2))
    a, b = strict.step(np.zeros((2, 28))), plain.step(np.zeros((2, 28)))
    assert a.pose_ended.all() and a.terminated.all() and not b.terminated.any()
    np.testing.assert_allclose(a.r_track, tracking_reward(a.pair_next, skills[1].obs[[4, 4]]))
    np.testing.assert_allclose(a.r_track, b.r_track)
