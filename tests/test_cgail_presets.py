"""The small preset carries the fidelity recipe; the paper's reward stays reachable with `~key` deletions
(mk/cgail.mk's CGAIL_PAPER_RECIPE); the AMP and tracking baselines drop the recipe keys that do not apply to
them when a config is composed, but not a key the command line sets, and not in a recorded run's config."""

import pytest
from omegaconf import OmegaConf

from charctl.config import compose_config, validate
from charctl.errors import CharctlError
from charctl.experiments.cgail.config import Config

from conftest import REPO, cgail_paper_recipe


def _compose(*overrides: str):
    return compose_config("cgail", list(overrides), Config)


def test_the_small_preset_is_run_h_recipe():
    # run H's command line (docs/cgail.md, "Run H"), key by key
    cfg = _compose("scale=small")
    assert cfg.disc.style_head == "per_skill" and cfg.disc.wrong_skill_fakes == 0.25
    assert cfg.cgail.class_on_policy is False
    assert (cfg.reward.w_style, cfg.reward.w_class, cfg.reward.class_form) == (0.8, 0.2, "prob")
    assert (cfg.reward.low_style_threshold, cfg.reward.low_style_steps) == (0.05, 10)
    assert (cfg.reward.pose_error_threshold, cfg.reward.w_track) == (0.5, 1.0)
    assert cfg.env.skill_fall_weight == 0.5 and cfg.env.phase_obs is True
    assert (cfg.ppo.desired_kl, cfg.ppo.lr_max) == (0.02, 1e-4)


def test_the_paper_recipe_deletions_return_every_recipe_key_to_the_schema():
    deletions = cgail_paper_recipe()
    assert len(deletions) == 13 and all(d.startswith("~") for d in deletions)
    paper, recipe, schema = _compose("scale=small", *deletions), _compose("scale=small"), OmegaConf.structured(Config)
    for key in (d[1:] for d in deletions):
        assert OmegaConf.select(paper, key) == OmegaConf.select(schema, key), key
        assert OmegaConf.select(recipe, key) != OmegaConf.select(schema, key), f"{key}: the preset does not set it"
    # nothing else moves: the small scale's networks and rates stay
    assert paper.ppo.hidden == recipe.ppo.hidden == [256, 256] and paper.env.physics_hz == 150.0


def test_the_baselines_drop_the_keys_that_do_not_apply():
    amp = _compose("scale=small", "use_skills=[walk]", "cgail.conditional=false")
    assert amp.disc.style_head == "shared" and amp.disc.wrong_skill_fakes == 0.0
    assert amp.reward.pose_error_threshold == 0.5  # the terminations still apply to AMP
    tracking = _compose("scale=small", "use_skills=[walk]", "reward.kind=tracking")
    assert (tracking.reward.low_style_threshold, tracking.reward.pose_error_threshold, tracking.reward.w_track) == (
        0.0,
        0.0,
        0.0,
    )
    assert tracking.disc.style_head == "per_skill"  # conditional: the (unused) discriminator keeps the preset's head


def test_a_key_the_command_line_sets_is_not_dropped_but_refused():
    with pytest.raises(CharctlError, match="style_head=per_skill needs cgail.conditional=true"):
        _compose("scale=small", "cgail.conditional=false", "disc.style_head=per_skill")
    with pytest.raises(CharctlError, match="root_height_threshold must be >= 0, and > 0 only with"):
        _compose("scale=small", "~reward.pose_error_threshold", "~reward.w_track", "reward.root_height_threshold=0.15")
    with pytest.raises(CharctlError, match="yaw_error_threshold must be >= 0, and > 0 only with"):
        _compose("scale=small", "~reward.pose_error_threshold", "~reward.w_track", "reward.yaw_error_threshold=1.5")
    # the tracking baseline drops the preset's pose check; set on the command line it is kept (docs/cgail.md,
    # "Spindance": tracking episodes ended far from the clip)
    kept = _compose("scale=small", "use_skills=[walk]", "reward.kind=tracking", "reward.pose_error_threshold=0.3")
    assert kept.reward.pose_error_threshold == 0.3 and kept.reward.w_track == 0.0


def test_a_recorded_config_is_taken_as_it_is():
    cfg = OmegaConf.to_container(_compose("scale=small"))
    cfg["cgail"]["conditional"] = False
    with pytest.raises(CharctlError, match="style_head=per_skill needs cgail.conditional=true"):
        validate(OmegaConf.create(cfg), Config, "cgail")


def test_a_bare_tilde_is_a_bad_override():
    with pytest.raises(CharctlError, match="overrides look like key=value"):
        _compose("~")


@pytest.mark.parametrize(
    ("overrides", "label"),
    [
        ((), "cGAIL"),
        (("cgail.class_loss=ls",), "cGAIL-LS"),
        (("cgail.conditional=false",), "AMP"),
        (("reward.kind=tracking", "use_skills=[walk]"), "tracking"),
        (("reward.kind=tracking", "use_skills=[walk]", "cgail.conditional=false"), "tracking"),
    ],
)
def test_method_label_names_the_method_from_the_config_and_from_a_stored_one(overrides, label, tmp_path):
    from charctl.experiments.cgail.config import method_label

    cfg = _compose("scale=small", *overrides)
    assert method_label(cfg) == label
    OmegaConf.save(cfg, tmp_path / "config.yaml")  # as a run folder stores it
    assert method_label(OmegaConf.load(tmp_path / "config.yaml")) == label


def test_method_label_reads_a_key_an_older_run_lacks_as_the_schema_default():
    from charctl.experiments.cgail.config import method_label

    # pretrained/amp-walk's stored config has no reward.kind; a bare cGAIL config names no class loss
    assert method_label(OmegaConf.create({"reward": {}, "cgail": {"conditional": False}})) == "AMP"
    assert method_label(OmegaConf.create({"cgail": {"conditional": True}})) == "cGAIL"
    assert method_label(OmegaConf.load(REPO / "pretrained/amp-walk/config.yaml")) == "AMP"
