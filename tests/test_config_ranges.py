"""Single-field range rules declared on the experiments' fields (`ranged(...)`, charctl.config_fields) instead of
code in each schema's `check`: a value outside one is refused at composition with one line naming the key and its
range, the schema's `check` alone reports it too, the bounds are the ones the code enforced before (the edge value
is still accepted), `charctl config EXP --explain KEY` prints them, and the cross-field rules stay in `check`."""

import pytest
import yaml
from omegaconf import OmegaConf

from charctl.config import BaseConfig, compose_config, scale_choices, validate
from charctl.config_fields import schema_choices
from charctl.config_help import explain, knobs
from charctl.errors import CharctlError
from charctl.experiments import load

from conftest import assert_config_value_refused, assert_one_line

# (experiment, key, a value outside the declared range, the range's wording, a value at (or near) its edge that is
# still accepted)
RANGES = [
    ("cgail", "reward.low_style_threshold", "1.0", ">= 0 and < 1, got 1", "0.0"),
    ("cgail", "reward.low_style_steps", "0", ">= 1, got 0", "1"),
    ("cgail", "reward.pose_error_threshold", "-0.1", ">= 0, got -0.1", "0.0"),
    ("cgail", "reward.pose_error_grace_steps", "-1", ">= 0, got -1", "0"),
    ("cgail", "reward.root_height_threshold", "-0.1", ">= 0, got -0.1", "0.0"),
    ("cgail", "reward.yaw_error_threshold", "-1.5", ">= 0, got -1.5", "0.0"),
    ("cgail", "env.skill_fall_halflife", "0", "> 0, got 0", "0.5"),
    ("cgail", "train.fidelity_every", "-1", ">= 0, got -1", "0"),
    ("cgail", "train.keep_checkpoint_every", "-1", ">= 0, got -1", "0"),
    ("hopper-ga", "beta", "1.0", ">= 0 and < 1, got 1", "0.0"),
    ("hopper-ga", "hopper.g", "0.0", "< 0, got 0", "-1.0"),
    ("hopper-ga", "hopper.thigh_fraction", "0.6", ">= 0.2 and <= 0.5, got 0.6", "0.2"),
    ("hopper-ga", "hopper.knee_max_flexion_deg", "180", "> 0 and < 180, got 180", "179.0"),
    ("hopper-ga", "ga.population", "3", ">= 4, got 3", "4"),
    ("hopper-ga", "ga.elite", "0", ">= 1, got 0", "1"),
    ("hopper-ga", "limp.speed_factor", "0", "> 0, got 0", "0.5"),
    ("hopper-ga", "limp.cycles", "1", ">= 2, got 1", "2"),
    ("motion-matching", "features.position_weight", "-0.1", ">= 0, got -0.1", "0.0"),
    ("motion-matching", "features.velocity_weight", "-0.1", ">= 0, got -0.1", "0.0"),
    ("motion-matching", "features.direction_weight", "-0.1", ">= 0, got -0.1", "0.0"),
    ("motion-matching", "features.past_weight", "-1", ">= 0, got -1", "0.0"),
    ("motion-matching", "features.pose_weight", "-1", ">= 0, got -1", "0.0"),
    ("motion-matching", "paths.star_points", "2", ">= 3, got 2", "3"),
]


@pytest.mark.parametrize("experiment, key, bad, wording, edge", RANGES, ids=[f"{e}-{k}" for e, k, *_ in RANGES])
def test_an_out_of_range_value_is_refused_in_one_line_naming_the_key(experiment, key, bad, wording, edge):
    # refused at composition, and by the schema's check alone (tests and tools call it directly)
    refused = assert_config_value_refused(experiment, key, bad, f"{key} must be {wording}")
    assert_one_line(refused, key)
    # the edge of the range is still accepted (the same bound the code in `check` had)
    cfg = compose_config(experiment, ["scale=smoke", f"{key}={edge}"], load(experiment).config_class())
    assert OmegaConf.select(cfg, key) == yaml.safe_load(edge)


# list fields: the range bounds each element
LIST_RANGES = [
    ("hopper-ga", "bounds.l", "[0.0,1.0]", "bounds.l[0] must be > 0, got 0"),
    ("hopper-ga", "bounds.kappa", "[-1.0,100.0]", "bounds.kappa[0] must be > 0, got -1"),
    ("hopper-ga", "bounds.m", "[0.0,50.0]", "bounds.m[0] must be > 0, got 0"),
    ("hopper-ga", "bounds.theta0", "[0.1,1.6]", "bounds.theta0[1] must be > 0 and < 1.5708, got 1.6"),
    ("srb", "push.phases", "[0.0,1.0]", "push.phases[1] must be >= 0 and < 1, got 1"),
    ("srb", "push.phases", "[-0.25]", "push.phases[0] must be >= 0 and < 1, got -0.25"),
]


@pytest.mark.parametrize("experiment, key, bad, message", LIST_RANGES, ids=[f"{e}-{v}" for e, _, v, _ in LIST_RANGES])
def test_a_list_element_out_of_range_is_refused_naming_its_index(experiment, key, bad, message):
    with pytest.raises(CharctlError) as exc:
        compose_config(experiment, ["scale=smoke", f"{key}={bad}"], load(experiment).config_class())
    assert str(exc.value) == f"invalid config for {experiment}: {message}"


def test_the_edges_of_the_list_ranges_are_still_accepted():
    hopper = compose_config("hopper-ga", ["scale=smoke", "bounds.theta0=[0.01,1.57]"], load("hopper-ga").config_class())
    assert list(hopper.bounds.theta0) == [0.01, 1.57]
    srb = compose_config("srb", ["scale=smoke", "push.phases=[0.0,0.99]"], load("srb").config_class())
    assert list(srb.push.phases) == [0.0, 0.99]


# the cross-field rules stay in each schema's check, with their messages
CROSS_FIELD = [
    ("hopper-ga", ["ga.population=4", "ga.elite=4"], "ga.elite must lie in [1, population)"),
    ("hopper-ga", ["bounds.theta0=[0.5,0.2]"], "bounds.theta0 must be [low, high] with low < high"),
    (
        "motion-matching",
        ["paths.star_inner=3.0", "paths.star_outer=3.0"],
        "path sizes must be > 0 and paths.star_inner < paths.star_outer",
    ),
    (
        "motion-matching",
        ["features.position_weight=0", "features.velocity_weight=0"],
        "at least one of features.position_weight/velocity_weight/direction_weight must be > 0",
    ),
    (
        "cgail",
        ["reward.w_track=-0.5"],
        "reward.w_track must be >= 0, and > 0 only with reward.pose_error_threshold > 0",
    ),
    (
        "cgail",
        ["disc.style_head=per_skill", "disc.wrong_skill_fakes=-0.1"],
        "disc.wrong_skill_fakes must lie in [0, 1)",
    ),
    ("cgail", ["env.skill_fall_weight=-0.5"], "env.skill_fall_weight must lie in [0, 1], got -0.5"),
]


@pytest.mark.parametrize("experiment, overrides, message", CROSS_FIELD, ids=[m[:30] for _, _, m in CROSS_FIELD])
def test_the_rules_left_in_check_keep_their_messages(experiment, overrides, message):
    with pytest.raises(CharctlError) as exc:
        compose_config(experiment, ["scale=smoke", *overrides], load(experiment).config_class())
    assert_one_line(exc.value, f"invalid config for {experiment}: {message}")


def test_scale_is_a_choice_of_the_presets_in_conf():
    assert schema_choices(BaseConfig)["scale"] == ("smoke", "small", "paper")
    assert sorted(schema_choices(BaseConfig)["scale"]) == scale_choices()  # conf/scale/*.yaml
    schema = load("cgail").config_class()
    recorded = OmegaConf.to_container(compose_config("cgail", ["scale=smoke"], schema))
    recorded["scale"] = "huge"  # a recorded run's config is validated as it is
    with pytest.raises(CharctlError) as exc:
        validate(OmegaConf.create(recorded), schema, "cgail")
    assert str(exc.value) == "invalid config for cgail: scale must be one of smoke, small, paper, got 'huge'"


# what `charctl config EXP --explain KEY` now says each moved rule allows
ALLOWED = [
    ("cgail", "reward.low_style_threshold", ">= 0 and < 1"),
    ("cgail", "reward.low_style_steps", ">= 1"),
    ("cgail", "reward.pose_error_threshold", ">= 0"),
    ("cgail", "reward.pose_error_grace_steps", ">= 0"),
    ("cgail", "reward.root_height_threshold", ">= 0"),
    ("cgail", "reward.yaw_error_threshold", ">= 0"),
    ("cgail", "env.skill_fall_halflife", "> 0"),
    ("cgail", "train.fidelity_every", ">= 0"),
    ("cgail", "train.keep_checkpoint_every", ">= 0"),
    ("cgail", "scale", "one of smoke, small, paper"),
    ("hopper-ga", "beta", ">= 0 and < 1"),
    ("hopper-ga", "hopper.g", "< 0"),
    ("hopper-ga", "hopper.thigh_fraction", ">= 0.2 and <= 0.5"),
    ("hopper-ga", "hopper.knee_max_flexion_deg", "> 0 and < 180"),
    ("hopper-ga", "bounds.theta0", "each > 0 and < 1.5708"),
    ("hopper-ga", "bounds.l", "each > 0"),
    ("hopper-ga", "ga.population", ">= 4"),
    ("hopper-ga", "ga.elite", ">= 1"),
    ("hopper-ga", "limp.speed_factor", "> 0"),
    ("hopper-ga", "limp.cycles", ">= 2"),
    ("motion-matching", "features.position_weight", ">= 0"),
    ("motion-matching", "features.pose_weight", ">= 0"),
    ("motion-matching", "paths.star_points", ">= 3"),
    ("srb", "push.phases", "each >= 0 and < 1"),
]


@pytest.mark.parametrize("experiment, key, allowed", ALLOWED, ids=[f"{e}-{k}" for e, k, _ in ALLOWED])
def test_knobs_show_the_declared_range(experiment, key, allowed):
    ks = {k.key: k for k in knobs(load(experiment).config_class())}
    assert ks[key].allowed() == allowed


@pytest.mark.parametrize(
    "experiment, key, allowed",
    [
        ("cgail", "reward.low_style_threshold", ">= 0 and < 1"),
        ("cgail", "env.skill_fall_halflife", "> 0"),
        ("hopper-ga", "ga.population", ">= 4"),
        ("hopper-ga", "hopper.thigh_fraction", ">= 0.2 and <= 0.5"),
        ("motion-matching", "paths.star_points", ">= 3"),
        ("srb", "push.phases", "each >= 0 and < 1"),
    ],
)
def test_explain_prints_the_moved_range(experiment, key, allowed):
    text = explain(experiment, key, ["scale=smoke"], load(experiment).config_class())
    first, second, *_ = text.splitlines()
    assert first.startswith(f"{key}: ") and second == f"    allowed: {allowed}"
