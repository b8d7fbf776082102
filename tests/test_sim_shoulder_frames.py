"""The shoulders' hinge-chain frames (`shoulder_frame`, charctl.sim.humanoid.SHOULDER_FRAMES): MuJoCo's kinematics
of the rotated model reproduce the clips, the parent-axes model is unchanged, and the rotated chains keep dance_a's
right shoulder away from the singular pose (figures of scripts/choose_shoulder_frames.py, docs/cgail.md)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from omegaconf import OmegaConf

from charctl.motion import rotations as R
from charctl.motion.library import load_clip
from charctl.sim.humanoid import (
    build_mjcf,
    chain_frames,
    clip_to_qpos_qvel,
    layout,
    load_model,
    local_rot_to_qpos,
    qpos_to_local_rot,
)


@pytest.mark.parametrize("name", ["dance_a", "kick:mirror", "backflip"])
def test_mujoco_fk_of_the_rotated_model_matches_the_clip(name):
    clip = load_clip(name)
    m = load_model(shoulder_frame="rotated")
    d = mujoco.MjData(m)
    qpos, _ = clip_to_qpos_qvel(clip, "rotated")
    ids = [m.body(n).id for n in clip.skeleton.names]
    for t in range(0, clip.num_frames, 3):
        d.qpos[:] = qpos[t]
        mujoco.mj_kinematics(m, d)
        np.testing.assert_allclose(d.xpos[ids], clip.body_pos[t], atol=1e-9)
    root, rot = qpos_to_local_rot(qpos, "rotated")
    assert R.angle_between(rot, clip.local_rot).max() < 1e-6


def test_the_parent_axes_model_is_the_plain_euler_chain():
    """Parent axes: a shoulder turned 0.3 rad about x is (0.3, 0, 0) in its XYZ chain, and its hinges lie on x, y, z."""
    clip = load_clip("walk")
    rot = clip.local_rot[:1].copy()
    rot[0, clip.skeleton.index("right_shoulder")] = R.from_axis_angle(np.array([1.0, 0.0, 0.0]), 0.3)
    s = layout().qpos_slices["right_shoulder"]
    qpos = local_rot_to_qpos(clip.root_pos[:1], rot)
    np.testing.assert_allclose(qpos[0, s], [0.3, 0.0, 0.0], atol=1e-12)
    xml = build_mjcf()
    for axis, text in (("x", "1 0 0"), ("y", "0 1 0"), ("z", "0 0 1")):
        assert f'<joint name="right_shoulder_{axis}" type="hinge" axis="{text}"/>' in xml
    rotated = load_model(shoulder_frame="rotated")
    j = rotated.joint("right_shoulder_x").id
    np.testing.assert_allclose(rotated.jnt_axis[j], chain_frames("rotated")["right_shoulder"].apply([1.0, 0, 0]))


def test_the_rotated_chain_keeps_dance_a_away_from_the_singular_pose():
    """Parent axes: dance_a's right shoulder hinges reach 25 rad/s and wind a whole turn per loop (the middle angle
    -1.40 rad at frame 39); rotated: the fastest hinge of either shoulder is under 12.5 rad/s, no winding."""
    clip = load_clip("dance_a").resample(30.0)
    s = layout().qpos_slices["right_shoulder"]
    v = layout().qvel_slices["right_shoulder"]
    for frame, rate_range, winds in (("parent", (24.0, 26.0), True), ("rotated", (5.0, 12.5), False)):
        qpos, qvel = clip_to_qpos_qvel(clip, frame)
        assert rate_range[0] < np.abs(qvel[:, v]).max() < rate_range[1]
        turn = np.unwrap(qpos[:, s], axis=0)
        assert (np.abs(turn[-1] - turn[0]).max() > 6.0) == winds  # a loop's net turn of the first and third hinges
    assert np.abs(clip_to_qpos_qvel(clip, "rotated")[1][:, 6:]).max() < 12.5


def test_an_unknown_frame_is_refused():
    with pytest.raises(ValueError, match="unknown shoulder_frame 'tilted'"):
        chain_frames("tilted")
    from charctl.config import compose_config
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.config import Config

    with pytest.raises(CharctlError, match="shoulder_frame"):
        compose_config("cgail", ["scale=smoke", "env.shoulder_frame=tilted"], Config)


def test_the_env_starts_at_the_clip_pose_with_the_rotated_model():
    from charctl.experiments.cgail.config import EnvConfig, SkillConfig
    from charctl.experiments.cgail.env import CgailEnv
    from charctl.experiments.cgail.skills import load_skills
    from charctl.motion.fk import forward_kinematics

    skills = load_skills([SkillConfig("spindance", "dance_a")], 30.0, "rotated")
    cfg = OmegaConf.structured(EnvConfig(num_envs=1, switch_prob=0.0, shoulder_frame="rotated"))
    env = CgailEnv(skills, cfg, seed=0)
    env.start_frame, env.random_yaw = 40, False
    env.reset(np.arange(1))
    clip = load_clip("dance_a").resample(30.0)
    pos, _ = forward_kinematics(clip.skeleton, clip.root_pos[40], clip.local_rot[40])
    rel = env.sim.body_pos[0] - env.sim.body_pos[0, :1]
    np.testing.assert_allclose(rel, pos - pos[:1], atol=1e-6)


@pytest.mark.parametrize("backend", ["cpu", "torch"])
def test_smoke_training_and_fidelity_with_rotated_shoulders(backend, tmp_path, charctl_main):
    res = charctl_main(
        "train", "cgail", "scale=smoke", "env.shoulder_frame=rotated",
        f"env.backend={backend}", "device=cpu", f"output_root={tmp_path}",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "done: iterations=4" in res.stdout
    (run,) = (tmp_path / "cgail").iterdir()
    if backend == "cpu":  # the filmstrip renders the run's own model
        res = charctl_main("eval", str(run), "--fidelity", "-k", "1", "--out", str(tmp_path / "ev"))
        assert res.returncode == 0, res.stderr
        assert (tmp_path / "ev" / "fidelity_walk.png").is_file()
