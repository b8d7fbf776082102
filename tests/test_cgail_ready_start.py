"""The ready start (env.ready_radius): a timed reference that restarts at frame 0 holds there until the character is
within the radius of the clip's first frame, or for env.ready_wait_steps; the rules by hand values, then the env
holding the kick's next pass, starting it at once when the radius is wide, and on the torch env the same frames."""

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from charctl.experiments.cgail.config import EnvConfig, SkillConfig
from charctl.experiments.cgail.env import CgailEnv
from charctl.experiments.cgail.rules import hold_reference, ready_update, ready_waits, start_waiting
from charctl.experiments.cgail.skills import load_skills


@pytest.mark.parametrize("lib", [np, torch])
def test_a_waiting_reference_keeps_its_frame_and_does_not_restart(lib):
    a = lib.tensor if lib is torch else np.array
    frame, advanced = a([0, 5, 0]), a([1, 6, 0])
    restarted, wait = a([False, False, True]), a([3, 0, 2])
    held, again = hold_reference(frame, advanced, restarted, wait)
    assert held.tolist() == [0, 6, 0] and again.tolist() == [False, False, False]


@pytest.mark.parametrize("lib", [np, torch])
def test_a_restart_waits_only_for_skills_whose_restarts_wait(lib):
    a = lib.tensor if lib is torch else np.array
    wait = start_waiting(a([0, 7, 4]), a([True, True, False]), a([True, False, True]), 30)
    assert wait.tolist() == [30, 0, 4]  # the kick waits, the walk's restart clears it, env 2 keeps its count


def test_which_skills_wait_heading_goals_never_and_with_the_return_only_once_it_is_on():
    goal, returning = [True, False, False], [False, True, False]  # walk; kick with its way back on; jump without
    assert ready_waits(goal, returning, with_return=False) == [False, True, True]
    assert ready_waits(goal, returning, with_return=True) == [False, True, False]


@pytest.mark.parametrize("lib", [np, torch])
def test_the_reference_starts_within_the_radius_or_on_its_last_waiting_step(lib):
    """radius 0.3 m, grace 10: env 0 is close (starts), 1 is far (counts down), 2 far on its last step (starts),
    3 runs already (unchanged), 4 waits for a command ramp (inactive, unchanged)."""
    a = lib.tensor if lib is torch else np.array
    wait, grace = a([5, 5, 1, 0, 5]), a([10, 10, 10, 3, 10])
    active = a([True, True, True, True, False])
    err = a([0.1, 0.5, 0.9, 0.1, 0.1])
    left, grace, started = ready_update(wait, grace, active, err, 0.3, 10)
    assert left.tolist() == [0, 4, 0, 0, 5] and grace.tolist() == [10, 10, 10, 3, 10]
    assert started.tolist() == [True, False, True, False, False]


@pytest.fixture(scope="module")
def kick():
    return load_skills([SkillConfig("kick", "kick")], 30.0)


def _frames(env, steps: int, zeros) -> list[list[int]]:
    out = []
    for _ in range(steps):
        env.step(zeros)
        out.append([int(f) for f in env.ref_frame.tolist()])
    return out


def _cfg(radius: float, wait: int = 4):
    return OmegaConf.structured(EnvConfig(num_envs=2, switch_prob=0.0, ready_radius=radius, ready_wait_steps=wait))


def test_the_kicks_next_pass_waits_for_the_character_then_runs_with_its_grace(kick):
    """From two frames before the clip's end: the next pass restarts at frame 0. A radius no pose meets (1e-9 m)
    holds it for the 4 waiting steps (the restart's step counted), then the clip runs 1, 2, ... with the pose
    check's 3 grace steps counted from the start; a radius every pose meets (100 m) starts it at once."""
    last = len(kick[0].obs) - 1
    for radius, want in ((1e-9, [last, 0, 0, 0, 0, 1, 2]), (100.0, [last, 0, 1, 2, 3, 4, 5])):
        env = CgailEnv(kick, _cfg(radius), seed=0, pose_error_threshold=100.0, pose_error_grace_steps=3)
        env.ref_frame[:] = last - 1
        zeros = np.zeros((2, env.sim.layout.nu))
        graces = []
        frames = []
        for _ in range(7):
            env.step(zeros)
            frames.append(int(env.ref_frame[0]))
            graces.append(int(env.ref_grace[0]))
        assert frames == want, radius
        if radius < 1:  # held at 3 while waiting, then 3, 2, 1 once it runs (the start step sets it)
            assert graces == [0, 3, 3, 3, 3, 2, 1]
            assert env.ref_wait.tolist() == [0, 0]


def test_without_a_radius_the_pass_restarts_on_time(kick):
    env = CgailEnv(kick, _cfg(0.0), seed=0, pose_error_threshold=100.0, pose_error_grace_steps=3)
    last = len(kick[0].obs) - 1
    env.ref_frame[:] = last - 1
    zeros = np.zeros((2, env.sim.layout.nu))
    assert [f[0] for f in _frames(env, 4, zeros)] == [last, 0, 1, 2]


def test_the_torch_env_holds_the_same_frames(kick):
    from charctl.experiments.cgail.env import CgailDeviceEnv
    from charctl.sim.torch_view import TorchBatchedHumanoid

    env = CgailDeviceEnv(
        kick, _cfg(1e-9), seed=0, sim=TorchBatchedHumanoid(2), pose_error_threshold=100.0, pose_error_grace_steps=3
    )
    last = len(kick[0].obs) - 1
    env.ref_frame = torch.full_like(env.ref_frame, last - 1)
    frames = _frames(env, 7, torch.zeros((2, env.sim.layout.nu)))
    assert [f[0] for f in frames] == [last, 0, 0, 0, 0, 1, 2] and [f[1] for f in frames] == [last, 0, 0, 0, 0, 1, 2]


def test_a_ready_start_needs_a_restarting_adversarial_reference():
    from charctl.config import compose_config
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.config import Config

    with pytest.raises(CharctlError, match="env.ready_radius holds a timed reference"):
        untimed = ["reward.pose_error_threshold=0", "env.phase_obs=false"]
        compose_config("cgail", ["scale=smoke", "env.ready_radius=0.3", *untimed], Config)
    cfg = compose_config("cgail", ["scale=smoke", "env.ready_radius=0.3", "env.phase_obs=true"], Config)
    assert cfg.env.ready_radius == 0.3 and cfg.env.ready_wait_steps == 30


def test_the_env_counts_the_starts_that_timed_out(kick):
    """The held pass of the first test starts on its last waiting step (no pose within 1e-9 m): one start per env,
    both timed out; read once, the counts are 0 again."""
    env = CgailEnv(kick, _cfg(1e-9), seed=0, pose_error_threshold=100.0, pose_error_grace_steps=3)
    env.ref_frame[:] = len(kick[0].obs) - 2
    _frames(env, 7, np.zeros((2, env.sim.layout.nu)))
    assert env.take_ready_counts() == (2, 2) and env.take_ready_counts() == (0, 0)


def test_smoke_training_with_a_ready_start(tmp_path, charctl_main):
    """End to end at smoke scale; the start counts are logged (train/ready_starts, train/ready_timeout_share)."""
    from charctl.eval.tb import read_scalars

    overrides = ["env.ready_radius=0.3", "env.phase_obs=true", f"output_root={tmp_path}"]
    res = charctl_main("train", "cgail", "scale=smoke", *overrides)
    assert res.returncode == 0, res.stderr
    (run,) = (tmp_path / "cgail").iterdir()
    scalars = read_scalars(run / "tb")
    share = scalars["train/ready_timeout_share"][1]
    assert ((share >= 0) & (share <= 1)).all() and "train/ready_starts" in scalars


def test_without_the_wait_after_a_pass_only_a_ramp_into_the_kick_waits():
    """env.ready_after_pass=false: the kick's next pass restarts on time; a walk -> kick switch (ramp of 2 frames)
    holds the kick's frame 0 for the 4 waiting steps after the ramp's end, then runs."""
    skills = load_skills([SkillConfig("walk", "walk", heading_goal=True), SkillConfig("kick", "kick")], 30.0)
    cfg = OmegaConf.structured(
        EnvConfig(
            num_envs=2, switch_prob=0.0, ready_radius=1e-9, ready_wait_steps=4, ready_after_pass=False, ramp_frames=2
        )
    )
    env = CgailEnv(skills, cfg, seed=0, pose_error_threshold=100.0, pose_error_grace_steps=3)
    zeros = np.zeros((2, env.sim.layout.nu))
    last = len(skills[1].obs) - 1
    env.cmd[:], env.prev_cmd[:], env.ref_frame[:] = 1, 1, last - 1  # both envs in the kick, a step before its end
    assert [f[0] for f in _frames(env, 4, zeros)] == [last, 0, 1, 2]  # the next pass: on time
    env.set_command(np.arange(2), 0)  # to the walk (2-frame ramp) and back to the kick
    _frames(env, 3, zeros)
    env.set_command(np.arange(2), 1)
    frames = [f[0] for f in _frames(env, 10, zeros)]
    first = frames.index(0)
    # the ramp's end sets frame 0 after its step's check, so the 4 waiting steps follow that frame: five at frame 0
    assert frames[first : first + 7] == [0, 0, 0, 0, 0, 1, 2], frames


def test_with_the_return_gate_the_kick_waits_only_once_its_way_back_is_on():
    """env.ready_with_return: the kick without its way back restarts its next pass on time (as without the radius);
    swapped for the kick with the way back (`use_skills`, as the training's coverage gate does), it waits."""
    cfg = OmegaConf.structured(
        EnvConfig(num_envs=2, switch_prob=0.0, ready_radius=1e-9, ready_wait_steps=4, ready_with_return=True)
    )
    plain = load_skills([SkillConfig("kick", "kick")], 30.0, return_seconds=0.5, returning=())
    env = CgailEnv(plain, cfg, seed=0, pose_error_threshold=100.0, pose_error_grace_steps=3)
    zeros = np.zeros((2, env.sim.layout.nu))
    last = len(plain[0].obs) - 1
    env.ref_frame[:] = last - 1
    assert not plain[0].has_return and env.ready_skills.tolist() == [False]
    assert [f[0] for f in _frames(env, 4, zeros)] == [last, 0, 1, 2]  # on time
    back = load_skills([SkillConfig("kick", "kick")], 30.0, return_seconds=0.5, returning=("kick",))
    env.use_skills(back)
    last = len(back[0].obs) - 1
    assert back[0].has_return and env.ready_skills.tolist() == [True]
    env.ref_frame[:] = last - 1
    assert [f[0] for f in _frames(env, 7, zeros)] == [last, 0, 0, 0, 0, 1, 2]  # held for the 4 waiting steps


def test_the_return_gate_needs_the_radius_and_the_coverage_gate():
    from charctl.config import compose_config
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.config import Config

    base = ["scale=smoke", "env.phase_obs=true", "env.ready_with_return=true"]
    with pytest.raises(CharctlError, match="env.ready_with_return starts the ready start with each skill's way back"):
        compose_config("cgail", [*base, "env.ready_radius=0.3"], Config)
    gated = ["env.ready_radius=0.3", "env.clip_return_seconds=0.5", "env.clip_return_after_coverage=0.5"]
    cfg = compose_config("cgail", [*base, *gated, "train.fidelity_every=1000000"], Config)
    assert cfg.env.ready_with_return
