"""cgail: reward formulas, transition blend, discriminator pieces, features, smoke training + resume."""

import numpy as np
import pytest
import torch

from charctl.experiments.cgail.discriminator import (
    Discriminator,
    blended_class_reward,
    class_loss,
    class_reward,
    gradient_penalty,
    style_loss,
    style_reward,
)

torch.set_num_threads(1)


def test_style_reward_formula():
    d = torch.tensor([1.0, -1.0, 0.0, 3.0, -3.0])
    # 1 - (1 - d)^2 / 4, clipped to [0, 1]
    assert style_reward(d).tolist() == pytest.approx([1.0, 0.0, 0.75, 0.0, 0.0])


def test_class_reward_formula_and_blend():
    p = torch.tensor([[0.7, 0.2, 0.1]])
    ca = torch.tensor([[1.0, 0.0, 0.0]])
    # ||C - c||_1 = 0.3 + 0.2 + 0.1 = 0.6 -> r = 0.4 ; vs class 1: 0.7+0.8+0.1 = 1.6 -> r = 0
    assert class_reward(p, ca).item() == pytest.approx(0.4)
    assert class_reward(p, torch.tensor([[0.0, 1.0, 0.0]])).item() == pytest.approx(0.0)
    # eq 4.11 with w = 0.25: 0.75 * 0.4 + 0.25 * 0
    r = blended_class_reward(p, torch.tensor([0]), torch.tensor([1]), torch.tensor([0.25]), 3)
    assert r.item() == pytest.approx(0.3)


def test_style_and_class_losses():
    assert style_loss(torch.tensor([1.0, 1.0]), torch.tensor([-1.0])).item() == pytest.approx(0.0)
    assert style_loss(torch.tensor([0.0]), torch.tensor([0.0])).item() == pytest.approx(2.0)
    logits = torch.tensor([[2.0, 0.0]])
    tgt = torch.tensor([[1.0, 0.0]])
    p = torch.softmax(logits, -1)
    assert class_loss(logits, tgt, "ce").item() == pytest.approx(-torch.log(p[0, 0]).item())
    assert class_loss(logits, tgt, "ls").item() == pytest.approx(((tgt - p) ** 2).sum().item())


def test_gradient_penalty_matches_finite_differences():
    torch.manual_seed(0)
    disc = Discriminator(6, 2, [16, 16]).double()
    disc.eval()
    x = torch.randn(3, 6, dtype=torch.float64)
    gp = gradient_penalty(disc, x, w_gp=0.5).item()
    eps = 1e-6
    sq = []
    for i in range(3):
        g = []
        for j in range(6):
            e = torch.zeros(6, dtype=torch.float64)
            e[j] = eps
            with torch.no_grad():
                hi = disc(x[i : i + 1] + e, normalized=True)[0]
                lo = disc(x[i : i + 1] - e, normalized=True)[0]
            g.append(((hi - lo) / (2 * eps)).item())
        sq.append(np.sum(np.square(g)))
    assert gp == pytest.approx(0.25 * np.mean(sq), rel=1e-4)


def test_spectral_norm_on_every_discriminator_layer():
    disc = Discriminator(10, 3, [32, 16, 8])
    linears = [m for m in disc.modules() if isinstance(m, torch.nn.Linear)]
    assert len(linears) == 5  # 3 hidden + style head + class head
    assert all(hasattr(m, "parametrizations") and "weight" in m.parametrizations for m in linears)
    amp = Discriminator(10, 3, [32], conditional=False)
    assert amp.class_head is None


def test_class_head_trains_at_class_lr():
    from types import SimpleNamespace

    from charctl.experiments.cgail.agent import discriminator_param_groups

    disc = Discriminator(4, 2, [8])
    groups = discriminator_param_groups(disc, SimpleNamespace(lr=1e-5, class_lr=1e-3))
    by_lr = {g["lr"]: {id(p) for p in g["params"]} for g in groups}
    assert by_lr[1e-3] == {id(p) for p in disc.class_head.parameters()}
    assert by_lr[1e-5] == {id(p) for n, p in disc.named_parameters() if not n.startswith("class_head.")}


def test_transition_ramp_blend():
    from omegaconf import OmegaConf

    from charctl.experiments.cgail.config import EnvConfig, SkillConfig
    from charctl.experiments.cgail.env import CgailEnv
    from charctl.experiments.cgail.skills import load_skills

    cfg = OmegaConf.structured(EnvConfig(num_envs=2, ramp_frames=4, switch_prob=0.0))
    skills = load_skills([SkillConfig("walk", "walk"), SkillConfig("kick", "kick")], 30.0)
    env = CgailEnv(skills, cfg, seed=0)
    env.forced_command = np.array([0, 0])
    env.reset(np.arange(2))
    env.set_command(np.array([0]), 1, ramp=True)
    env.set_command(np.array([1]), 1, ramp=False)
    blends = []
    for _ in range(5):
        blends.append(env.command_blend().copy())
        env._advance_ramp()
    # env 0 ramps 0 -> 1 over 4 frames; env 1 switches at once
    assert [b[0, 1] for b in blends] == pytest.approx([0.0, 0.25, 0.5, 0.75, 1.0])
    assert [b[0].sum() for b in blends] == pytest.approx([1.0] * 5)
    assert all(b[1, 1] == 1.0 for b in blends)


def test_features_agree_between_clip_and_simulator():
    from charctl.experiments.cgail.features import clip_kinematics, disc_obs, policy_state, sim_kinematics
    from charctl.motion.library import load_clip
    from charctl.sim.batch import BatchedHumanoid
    from charctl.sim.humanoid import clip_to_qpos_qvel

    clip = load_clip("run")
    kc = clip_kinematics(clip)
    qpos, qvel = clip_to_qpos_qvel(clip)
    sim = BatchedHumanoid(3)
    sim.set_state(np.arange(3), qpos[5:8], qvel[5:8])
    ks = sim_kinematics(sim)
    s_clip, s_sim = policy_state(kc)[5:8], policy_state(ks)
    o_clip, o_sim = disc_obs(kc)[5:8], disc_obs(ks)
    assert s_sim.shape == (3, 241) and o_sim.shape == (3, 133)
    # positions and rotations agree exactly; velocities up to finite-difference error
    np.testing.assert_allclose(s_sim[:, :133], s_clip[:, :133], atol=1e-9)
    assert np.abs(o_sim - o_clip).mean() < 0.05
    # heading invariance: turning the character about +y leaves the features unchanged
    from charctl.motion import rotations as R

    turn = R.heading_quat(np.array(1.1))
    q2 = qpos[5:8].copy()
    q2[:, 3:7] = R.xyzw_to_wxyz(R.multiply(np.broadcast_to(turn, (3, 4)), R.wxyz_to_xyzw(q2[:, 3:7])))
    q2[:, [0, 2]] = R.rotate(np.broadcast_to(turn, (3, 4)), q2[:, :3])[:, [0, 2]]
    v2 = qvel[5:8].copy()
    v2[:, :3] = R.rotate(np.broadcast_to(turn, (3, 4)), v2[:, :3])
    sim.set_state(np.arange(3), q2, v2)
    np.testing.assert_allclose(disc_obs(sim_kinematics(sim)), o_sim, atol=1e-9)


def test_smoke_training_and_resume(smoke_run_copy):
    from charctl.checkpoints import load_checkpoint
    from charctl.commands.train import train_command

    run_dir = smoke_run_copy("cgail")  # `charctl train cgail scale=smoke`, once per session (test_smoke.py)
    state = load_checkpoint(run_dir / "checkpoints" / "last.pt", "cgail")
    assert state["iteration"] == 4 and state["samples"] == 512
    assert (run_dir / "config.yaml").is_file() and (run_dir / "metrics.json").is_file()
    assert list((run_dir / "tb").glob("events.out.tfevents.*"))
    train_command("cgail", ["train.total_samples=1024"], resume=run_dir)
    state2 = load_checkpoint(run_dir / "checkpoints" / "last.pt", "cgail")
    assert state2["iteration"] == 8 and state2["samples"] == 1024
    assert state2["replay"]["size"] > state["replay"]["size"]


def test_amp_baseline_smoke(tmp_path):
    from charctl.checkpoints import load_checkpoint
    from charctl.commands.train import train_command

    (run_dir,) = train_command("cgail", ["scale=smoke", "cgail.conditional=false", f"output_root={tmp_path}"])
    state = load_checkpoint(run_dir / "checkpoints" / "last.pt", "cgail")
    assert not any(k.startswith("class_head") for k in state["disc"])
    assert state["ppo"]["model"]["actor.0.weight"].shape[1] == 243  # no command input


def test_wrong_checkpoint_is_one_line_error(smoke_run_copy):
    from charctl.commands.train import train_command
    from charctl.errors import CharctlError

    run_dir = smoke_run_copy("cgail")
    with pytest.raises(CharctlError, match="hidden"):
        train_command("cgail", ["ppo.hidden=[16]", "train.total_samples=2048"], resume=run_dir)


def test_reset_rows_get_the_same_features_as_the_whole_batch():
    """Resets compute kinematics and features for the reset rows only: they must equal the rows of the
    whole-batch computation (state with goal and phase, disc obs), and the fused state+obs must equal
    the two separate functions."""
    from omegaconf import OmegaConf

    from charctl.experiments.cgail.config import EnvConfig, SkillConfig
    from charctl.experiments.cgail.env import CgailEnv
    from charctl.experiments.cgail.features import disc_obs, policy_state, sim_kinematics, state_and_obs
    from charctl.experiments.cgail.skills import load_skills

    cfg = OmegaConf.structured(EnvConfig(num_envs=6, switch_prob=0.0))
    skills = load_skills([SkillConfig("walk", "walk"), SkillConfig("kick", "kick")], 30.0)
    env = CgailEnv(skills, cfg, seed=3, tracking=True)
    rng = np.random.default_rng(0)
    for _ in range(3):
        env.step(0.1 * rng.standard_normal((6, env.sim.layout.nu)))
    ids = np.array([1, 4])
    env.reset(ids)
    whole = sim_kinematics(env.sim)
    state, obs = env._features(whole)
    np.testing.assert_allclose(env.state[ids], state[ids], atol=1e-12)
    np.testing.assert_allclose(env.obs[ids], obs[ids], atol=1e-12)
    s, o = state_and_obs(whole)
    np.testing.assert_array_equal(s, policy_state(whole))
    np.testing.assert_array_equal(o, disc_obs(whole))


def test_fall_rate_average_and_skill_probabilities_by_hand():
    """Halflife 2 episodes: a skill with 2 ended episodes, 1 fall, keeps 0.5 of its old rate 0.5 and takes
    0.5 of 1/2 -> 0.5; one with 4 episodes, all falls, keeps 0.25 of 0.2 -> 0.05 + 0.75 = 0.8; a skill with
    no ended episode keeps its rate. Probabilities: weight 0.5 over K=3 -> 1/6 each plus 0.5 * share of
    (rate + 0.001)."""
    from charctl.experiments.cgail.rules import skill_probabilities, update_fall_rates

    rates = np.array([0.5, 0.2, 0.3])
    skill = np.array([0, 0, 1, 1, 1, 1, 2])
    fell = np.array([True, False, True, True, True, True, True])
    ended = np.array([True, True, True, True, True, True, False])  # skill 2's env still runs: no episode
    new = update_fall_rates(rates, skill, ended, fell, halflife=2.0)
    np.testing.assert_allclose(new, [0.5, 0.8, 0.3])
    as_torch = update_fall_rates(*(torch.from_numpy(a) for a in (rates, skill, ended, fell)), halflife=2.0)
    np.testing.assert_allclose(as_torch.numpy(), new, atol=1e-15)  # the one implementation, on torch tensors
    p = skill_probabilities(np.array([0.0, 0.3, 0.699]), 0.5)
    np.testing.assert_allclose(p, np.array([1, 1, 1]) / 6 + 0.5 * np.array([0.001, 0.301, 0.7]) / 1.002)
    assert p.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(skill_probabilities(np.array([0.9, 0.1]), 0.0), [0.5, 0.5])


def test_fall_weighted_commands_favour_the_falling_skill():
    """With skill_fall_weight 1 and skill 1 the only one falling, resets draw skill 1 about
    (0.9 + 0.001) / (0.9 + 0.001 + 0.001) = 99.8 % of the time; with weight 0 about half."""
    from omegaconf import OmegaConf

    from charctl.experiments.cgail.config import EnvConfig, SkillConfig
    from charctl.experiments.cgail.env import CgailEnv
    from charctl.experiments.cgail.skills import load_skills

    skills = load_skills([SkillConfig("walk", "humanoid3d_walk.txt"), SkillConfig("jump", "humanoid3d_jump.txt")], 30.0)
    env = CgailEnv(skills, OmegaConf.structured(EnvConfig(num_envs=8, skill_fall_weight=1.0)), seed=3)
    env.fall_rate = np.array([0.0, 0.9])
    draws = env._sample_skills(4000)
    assert 0.99 < draws.mean() <= 1.0
    env.cfg.skill_fall_weight = 0.0
    assert abs(env._sample_skills(4000).mean() - 0.5) < 0.05


def test_fall_weight_config_errors():
    from charctl.config import compose_config
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.config import Config

    with pytest.raises(CharctlError, match="skill_fall_weight must lie in"):
        compose_config("cgail", ["scale=smoke", "env.skill_fall_weight=1.5"], Config)
    with pytest.raises(CharctlError, match="skill_fall_halflife"):
        compose_config("cgail", ["scale=smoke", "env.skill_fall_halflife=0"], Config)
    with pytest.raises(CharctlError, match="keep_checkpoint_every"):
        compose_config("cgail", ["scale=smoke", "train.keep_checkpoint_every=-1"], Config)


def test_kept_checkpoints_are_evaluated_by_name(smoke_run_copy):
    """Resuming the smoke run (512 samples, 128 per iteration) to 1024 with train.keep_checkpoint_every=256
    passes 640, 768, 896, 1024: the multiples of 256 crossed are 768 and 1024, so exactly those two are kept.
    `load_trained_run(RUN, name)` loads the named one, and a path or a missing name is a one-line error."""
    from charctl.checkpoints import load_checkpoint
    from charctl.commands.train import train_command
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.policy import load_trained_run

    run_dir = smoke_run_copy("cgail")
    train_command("cgail", ["train.total_samples=1024", "train.keep_checkpoint_every=256"], resume=run_dir)
    kept = sorted(p.name for p in (run_dir / "checkpoints").glob("samples_*.pt"))
    assert kept == ["samples_000000768.pt", "samples_000001024.pt"]
    assert load_checkpoint(run_dir / "checkpoints" / kept[0], "cgail")["samples"] == 768
    tr = load_trained_run(run_dir, kept[0])
    assert tr.agent.samples == 768
    with pytest.raises(CharctlError, match="file name inside"):
        load_trained_run(run_dir, "../last.pt")
    with pytest.raises(CharctlError, match="checkpoint not found"):
        load_trained_run(run_dir, "samples_000000001.pt")


def _overlapped_learner(tmp_path, seed: int = 0):
    from charctl.config import compose_config
    from charctl.experiments.cgail.config import Config
    from charctl.experiments.cgail.train import CgailLearner

    cfg = compose_config("cgail", ["scale=smoke", "train.overlap_update=true", f"seed={seed}"], Config)
    return CgailLearner(cfg)


def test_overlapped_loop_acts_one_update_behind_and_checkpoints_every_sample(tmp_path):
    """train.overlap_update: iteration k's rollout acts with the parameters before the update of rollout
    k-1 (that update runs beside it); state_dict() first finishes the pending update; the same seed gives
    the same parameters (the worker thread draws only from the learner's own generators)."""
    learner = _overlapped_learner(tmp_path)
    weight = learner.agent.model.actor[0].weight
    p0 = weight.detach().clone()
    first = learner.iterate()  # nothing to overlap yet: rollout only
    assert torch.equal(weight, p0) and learner.pending is not None and "losses/policy" not in first
    second = learner.iterate()  # update of rollout 1 beside rollout 2, which acted with p0
    assert torch.equal(learner.acting.model.actor[0].weight, p0) and not torch.equal(weight, p0)
    assert second["losses/behaviour_weight"] == pytest.approx(1.0)  # rollout 1 acted with p0 = the proximal policy
    p2 = weight.detach().clone()
    third = learner.iterate()  # rollout 2 acted with p0, the update starts from p2: weights below 1
    assert third["losses/behaviour_weight"] < 1.0
    state = learner.state_dict()
    assert learner.pending is None and not torch.equal(weight, p2)
    twin = _overlapped_learner(tmp_path)
    for _ in range(3):
        twin.iterate()
    twin_state = twin.state_dict()
    for k, v in state["ppo"]["model"].items():
        assert torch.equal(v, twin_state["ppo"]["model"][k]), k


def test_overlapped_update_error_reaches_the_main_thread(tmp_path, monkeypatch):
    """An exception in the worker thread's update is raised by iterate(), after the rollout finished."""
    learner = _overlapped_learner(tmp_path)
    learner.iterate()

    def broken(*args, **kwargs):
        raise RuntimeError("update failed")

    monkeypatch.setattr(learner.agent.ppo, "update", broken)
    with pytest.raises(RuntimeError, match="update failed"):
        learner.iterate()
