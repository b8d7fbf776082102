"""Per-skill style head (disc.style_head=per_skill), CALM's wrong-skill fakes and the class head on
demonstrations only (cgail.class_on_policy=false): hand-checked scores, losses and config errors."""

import pytest
import torch

from charctl.experiments.cgail.discriminator import (
    Discriminator,
    gradient_penalty,
    wrong_skill_labels,
)

torch.set_num_threads(1)


def _disc(K: int = 3) -> Discriminator:
    torch.manual_seed(0)
    d = Discriminator(6, K, [8], style_head="per_skill").double()
    d.eval()
    return d


def test_per_skill_score_is_the_commanded_logit_and_blends_linearly():
    disc = _disc()
    x = torch.randn(4, 6, dtype=torch.float64)
    with torch.no_grad():
        logits = disc.style_head(disc.trunk(x))  # (4, 3): one style logit per skill
        eye = torch.eye(3, dtype=torch.float64)
        for k in range(3):
            d, _ = disc(x, normalized=True, cond=eye[k].expand(4, 3))
            assert torch.allclose(d, logits[:, k])
        blend = torch.tensor([0.25, 0.75, 0.0], dtype=torch.float64).expand(4, 3)
        d, _ = disc(x, normalized=True, cond=blend)
        assert torch.allclose(d, 0.25 * logits[:, 0] + 0.75 * logits[:, 1])


def test_per_skill_head_needs_the_command_and_shared_head_ignores_it():
    disc = _disc()
    with pytest.raises(ValueError, match="command blend"):
        disc(torch.zeros(2, 6, dtype=torch.float64), normalized=True)
    shared = Discriminator(6, 3, [8]).double().eval()
    x = torch.randn(2, 6, dtype=torch.float64)
    with torch.no_grad():
        a, _ = shared(x, normalized=True)
        b, _ = shared(x, normalized=True, cond=torch.eye(3, dtype=torch.float64)[:2])
    assert torch.equal(a, b) and a.shape == (2,)
    with pytest.raises(ValueError, match="style head"):
        Discriminator(6, 3, [8], style_head="per_clip")


def test_gradient_penalty_of_the_labelled_logit_matches_finite_differences():
    disc = _disc()
    x = torch.randn(2, 6, dtype=torch.float64)
    cond = torch.eye(3, dtype=torch.float64)[[2, 0]]
    gp = gradient_penalty(disc, x, w_gp=2.0, cond=cond).item()
    eps, sq = 1e-6, []
    for i in range(2):
        g = []
        for j in range(6):
            e = torch.zeros(6, dtype=torch.float64)
            e[j] = eps
            with torch.no_grad():
                hi = disc(x[i : i + 1] + e, normalized=True, cond=cond[i : i + 1])[0]
                lo = disc(x[i : i + 1] - e, normalized=True, cond=cond[i : i + 1])[0]
            g.append(((hi - lo) / (2 * eps)).item())
        sq.append(sum(v * v for v in g))
    assert gp == pytest.approx(1.0 * sum(sq) / 2, rel=1e-4)  # (w_gp / 2) * mean ||grad||^2


def test_wrong_skill_labels_never_return_the_own_label_and_cover_the_others():
    labels = torch.tensor([0, 1, 2] * 2000)
    wrong = wrong_skill_labels(labels, 3, torch.Generator().manual_seed(0))
    assert not (wrong == labels).any()
    for k in range(3):
        others = wrong[labels == k]
        counts = torch.bincount(others, minlength=3).float() / len(others)
        assert counts[k] == 0 and all(abs(counts[j] - 0.5) < 0.05 for j in range(3) if j != k)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"disc": {"style_head": "per_clip"}}, "disc.style_head"),
        ({"disc": {"style_head": "per_skill"}, "cgail": {"conditional": False}}, "needs cgail.conditional"),
        ({"disc": {"wrong_skill_fakes": 0.25}}, "needs disc.style_head=per_skill"),
        ({"disc": {"style_head": "per_skill", "wrong_skill_fakes": 1.0}}, "must lie in"),
    ],
)
def test_config_errors(overrides, message):
    from omegaconf import OmegaConf

    from charctl.experiments.cgail.config import Config

    cfg = OmegaConf.merge(OmegaConf.structured(Config), overrides)
    assert message in Config.check(cfg)


def test_update_trains_the_class_head_on_demonstrations_only_when_asked():
    """With cgail.class_on_policy=false the class loss is the demonstration term alone: a policy batch
    whose command labels are all wrong leaves it unchanged (the same seed, both settings)."""
    from omegaconf import OmegaConf

    from charctl.experiments.cgail.config import Config
    from charctl.experiments.cgail.train import CgailLearner

    def losses(class_on_policy: bool) -> float:
        cfg = OmegaConf.merge(
            OmegaConf.structured(Config),
            {
                "use_skills": ["walk", "right_kick"],
                "env": {"num_envs": 4, "episode_seconds": 1.0},
                "ppo": {"hidden": [16], "minibatch_size": 32, "epochs": 1},
                "disc": {
                    "hidden": [16],
                    "batch_size": 32,
                    "steps_per_iter": 1,
                    "replay_size": 256,
                    "style_head": "per_skill",
                    "wrong_skill_fakes": 0.25,
                },
                "cgail": {"class_on_policy": class_on_policy},
                "train": {"rollout_steps": 8, "torch_threads": 1},
            },
        )
        stats = CgailLearner(cfg).iterate()
        return stats["losses/disc_class"], stats["train/disc_acc_wrong_skill"]

    (with_policy, acc_w1), (demo_only, acc_w2) = losses(True), losses(False)
    assert demo_only < with_policy  # the policy term (>= 0, here ~log 2) is gone
    assert 0.0 <= acc_w1 <= 1.0 and 0.0 <= acc_w2 <= 1.0


def test_learner_logs_fidelity_scalars_when_the_samples_cross_a_multiple():
    """train.fidelity_every: the cheap fidelity evaluation's scalars appear in exactly the iterations
    whose samples cross a multiple (4 envs x 8 steps = 32 samples per iteration, every 64)."""
    from omegaconf import OmegaConf

    from charctl.experiments.cgail.config import Config
    from charctl.experiments.cgail.train import CgailLearner

    cfg = OmegaConf.merge(
        OmegaConf.structured(Config),
        {
            "use_skills": ["walk", "right_kick"],
            "env": {"num_envs": 4, "episode_seconds": 1.0},
            "ppo": {"hidden": [16], "minibatch_size": 32, "epochs": 1},
            "disc": {"hidden": [16], "batch_size": 32, "steps_per_iter": 1, "replay_size": 256},
            "train": {"rollout_steps": 8, "torch_threads": 1, "fidelity_every": 64},
        },
    )
    learner = CgailLearner(cfg)
    logged = []
    for _ in range(4):
        stats = learner.iterate()
        learner.samples += learner.samples_per_iteration
        logged.append("fidelity/min_coverage" in stats)
    assert logged == [False, True, False, True]
    assert 0.0 <= stats["fidelity/min_coverage"] <= 1.0
    assert stats["fidelity/right_kick/foot_peak"] > 0.0


@pytest.mark.parametrize(
    "options",
    [
        {"survival": 1.0, "switch": ("walk", "nosuch")},
        {"dtw": True, "switch": ("nosuch", "walk")},
        {"survival": 1.0, "episodes": 0},
    ],
)
def test_eval_with_a_bad_mode_argument_writes_nothing(tmp_path, options):
    """Every mode's arguments are checked before the first mode writes its table (an unknown --switch
    skill used to fail after --survival had written report.md)."""
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.evaluate import evaluate

    out = tmp_path / "eval"
    with pytest.raises(CharctlError, match="unknown skill|-k must be"):
        evaluate(["pretrained/cgail-3skill-fidelity"], {**options, "out": str(out)}, [])
    assert not out.exists()


def test_low_style_termination_counts_consecutive_low_steps_and_restarts_on_done():
    """r_S < threshold for `steps` steps in a row ends the episode; a done episode or a good step
    restarts the count (threshold 0.999 makes every step low for an untrained discriminator)."""
    from charctl.experiments.cgail.termination import LowStyleTermination

    disc = Discriminator(6, 2, [8], style_head="per_skill")
    term = LowStyleTermination(disc, num_envs=3, threshold=0.999, steps=3)
    pairs, cond = torch.randn(3, 6), torch.eye(2)[[0, 1, 0]]
    no = torch.zeros(3, dtype=torch.bool)
    assert not term.update(pairs, cond, no).any()
    assert not term.update(pairs, cond, torch.tensor([True, False, False])).any()  # env 0 restarts
    assert term.update(pairs, cond, no).tolist() == [False, True, True]  # envs 1, 2: third low step
    assert term.low.tolist() == [1, 0, 0]  # env 0: counted again from its restart
    never = LowStyleTermination(disc, num_envs=3, threshold=1e-9, steps=1)
    d, _ = never.disc(pairs, cond=cond)
    ended = never.update(pairs, cond, no)
    assert ended.tolist() == (style_reward_of(d) < 1e-9).tolist()


def style_reward_of(d):
    from charctl.experiments.cgail.discriminator import style_reward

    return style_reward(d)


def test_learner_with_low_style_termination_ends_episodes_and_logs_them():
    from omegaconf import OmegaConf

    from charctl.experiments.cgail.config import Config
    from charctl.experiments.cgail.train import CgailLearner

    cfg = OmegaConf.merge(
        OmegaConf.structured(Config),
        {
            "use_skills": ["walk", "right_kick"],
            "env": {"num_envs": 4, "episode_seconds": 5.0},
            "ppo": {"hidden": [16], "minibatch_size": 32, "epochs": 1},
            "disc": {"hidden": [16], "batch_size": 32, "steps_per_iter": 1, "replay_size": 256},
            "reward": {"low_style_threshold": 0.999, "low_style_steps": 2},
            "train": {"rollout_steps": 8, "torch_threads": 1, "fidelity_every": 0},
        },
    )
    stats = CgailLearner(cfg).iterate()
    # every step is "low" at threshold 0.999: episodes end every 2 steps unless they fell first
    assert stats["train/style_terminations"] >= 4 * 8 // 2 - 4 - stats["train/falls"]
    assert stats["train/episode_length"] <= 2.0


def test_multi_skill_tracking_baseline_has_command_and_phase_in_its_inputs():
    """reward.kind=tracking over several skills (the fidelity anchor): the policy gets the command (cond) and
    the state the clip phase; the reward is the tracking reward against the commanded clip; switching
    commands mid-episode is refused by the config check."""
    from omegaconf import OmegaConf

    from charctl.experiments.cgail.config import Config
    from charctl.experiments.cgail.features import STATE_DIM
    from charctl.experiments.cgail.rules import PHASE_DIM
    from charctl.experiments.cgail.train import CgailLearner

    cfg = OmegaConf.merge(
        OmegaConf.structured(Config),
        {
            "use_skills": ["walk", "right_kick"],
            "reward": {"kind": "tracking"},
            "env": {"num_envs": 4, "episode_seconds": 1.0, "switch_prob": 0.0},
            "ppo": {"hidden": [16], "minibatch_size": 32, "epochs": 1},
            "disc": {"hidden": [16], "batch_size": 32, "steps_per_iter": 1, "replay_size": 256},
            "train": {"rollout_steps": 8, "torch_threads": 1, "fidelity_every": 0},
        },
    )
    assert Config.check(cfg) is None
    learner = CgailLearner(cfg)
    assert learner.env.state_dim == STATE_DIM + 2 + PHASE_DIM
    assert learner.agent.model.cond_dim == 2
    stats = learner.iterate()
    assert 0.0 < stats["train/r_track"] <= 1.0
    switching = OmegaConf.merge(cfg, {"env": {"switch_prob": 0.01}})
    assert "needs env.switch_prob=0" in Config.check(switching)


def test_performed_after_switch_counts_a_replayed_kick_and_not_a_stance():
    """The switch study's "kick performed" check: the kick clip's own bodies reach 1.0 x its foot peak
    (performed), a character frozen in the clip's first pose does not, and a fall before the peak
    does not count."""
    from types import SimpleNamespace

    import numpy as np

    from charctl.experiments.cgail.config import SkillConfig
    from charctl.experiments.cgail.fidelity import clip_reference
    from charctl.experiments.cgail.metrics import performed_after_switch
    from charctl.experiments.cgail.skills import load_skills

    kick = load_skills([SkillConfig("right_kick", "kick")], 30.0)[0]
    ref = clip_reference(kick)
    tr = SimpleNamespace(
        agent=SimpleNamespace(skills=[kick]), cfg=SimpleNamespace(env=SimpleNamespace(control_hz=30.0))
    )
    F = len(ref.body_pos)
    pos = np.stack([ref.body_pos, np.repeat(ref.body_pos[:1], F, 0), ref.body_pos], axis=1)  # (F, 3, 15, 3)
    rot = np.stack([ref.body_rot, np.repeat(ref.body_rot[:1], F, 0), ref.body_rot], axis=1)
    alive = np.ones((F + 5, 3), dtype=bool)
    alive[5 + 3 :, 2] = False  # trial 2 falls 3 frames after the switch at frame 5
    out = performed_after_switch(tr, 0, pos, rot, alive, t_switch=5)
    assert out["foot_peak"][0] == pytest.approx(out["clip_foot_peak"])
    assert out["clip_foot_peak"] == pytest.approx(1.28, abs=0.01)
    assert out["foot_peak"][1] < 0.2
    assert out["performed"] == 1


def test_resume_with_overrides_records_them_in_the_run_config(smoke_run_copy):
    """A resume's overrides reach config.yaml (and resumes.txt) once the checkpoint has loaded; a resume whose
    overrides the checkpoint rejects leaves config.yaml as it was."""
    from omegaconf import OmegaConf

    from charctl.commands.train import train_command
    from charctl.errors import CharctlError

    run_dir = smoke_run_copy("cgail")
    before = (run_dir / "config.yaml").read_text()
    with pytest.raises(CharctlError, match="hidden"):
        train_command("cgail", ["ppo.hidden=[16]", "train.total_samples=2048"], resume=run_dir)
    assert (run_dir / "config.yaml").read_text() == before and not (run_dir / "resumes.txt").exists()
    overrides = ["train.total_samples=1024", "reward.low_style_threshold=0.05", "reward.pose_error_threshold=0.5"]
    overrides.append("reward.w_track_skills={walk:2.0}")
    train_command("cgail", overrides, resume=run_dir)  # Hydra's dict syntax, as on a fresh train
    cfg = OmegaConf.load(run_dir / "config.yaml")
    assert cfg.train.total_samples == 1024 and cfg.reward.low_style_threshold == 0.05
    assert OmegaConf.to_container(cfg.reward.w_track_skills) == {"walk": 2.0}
    assert "reward.low_style_threshold=0.05" in (run_dir / "resumes.txt").read_text()


def test_frozen_copy_scores_as_the_eval_mode_discriminator_and_leaves_it_working():
    """`frozen_copy`: plain Linears with the spectral-normalised weights computed once give the eval-mode
    outputs (float32 rounding), hold no parametrization, and the original (trained a step) still works."""
    from torch.nn.utils import parametrize

    from charctl.experiments.cgail.discriminator import Discriminator, frozen_copy

    torch.manual_seed(0)
    disc = Discriminator(12, 3, [16, 16], style_head="per_skill")
    disc(torch.randn(64, 12), cond=torch.eye(3)[torch.randint(0, 3, (64,))])  # a training-mode pass: u, v move
    pairs, cond = torch.randn(32, 12), torch.softmax(torch.randn(32, 3), -1)
    frozen = frozen_copy(disc)
    assert not any(parametrize.is_parametrized(m) for m in frozen.modules())
    assert not any(p.requires_grad for p in frozen.parameters())
    with torch.no_grad():
        want = disc.eval()(pairs, cond=cond)
        got = frozen(pairs, cond=cond)
    torch.testing.assert_close(got[0], want[0], rtol=0, atol=1e-6)
    torch.testing.assert_close(got[1], want[1], rtol=0, atol=1e-6)
    disc.train()
    d, _ = disc(pairs, cond=cond)  # the original keeps its parametrizations and its gradients
    d.sum().backward()
    assert disc.trunk[0].parametrizations.weight.original.grad is not None
