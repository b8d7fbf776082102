"""`charctl config EXPERIMENT --explain KEY`: help read from the schema's comments, the schema default,
the resolved value and the layer that set it; every knob of every experiment has help."""

import pytest

from charctl.config_help import explain, knobs, source_of
from charctl.errors import CharctlError
from charctl.experiments import EXPERIMENTS, load

from conftest import REPO, charctl_in_process


@pytest.mark.parametrize("experiment", sorted(EXPERIMENTS))
def test_every_knob_has_help(experiment):
    missing = [k.key for k in knobs(load(experiment).config_class()) if not k.help]
    assert missing == [], f"add a comment beside (or above) these fields of the {experiment} schema"


def test_help_default_and_wrapped_definitions_are_read_from_the_schema():
    ks = {k.key: k for k in knobs(load("cgail").config_class())}
    assert ks["env.num_envs"].default == 64 and ks["env.num_envs"].type == "int"
    assert ks["env.num_envs"].help == "humanoids simulated together"
    # the block above a field and the comment beside it, joined
    assert ks["reward.pose_error_threshold"].help.startswith("Early termination on a large pose error")
    assert ks["reward.pose_error_threshold"].help.endswith('docs/cgail.md, "Fidelity recipe".')
    assert ks["experiment"].help.startswith("the experiment this config belongs to")  # from BaseConfig
    srb = {k.key: k for k in knobs(load("srb").config_class())}
    assert "composite inertia" in srb["body.inertia_pose_frame"].help  # a definition ruff wrapped over 3 lines


def test_source_is_the_last_layer_that_sets_the_key():
    assert source_of("env.num_envs", "cgail", "small", []) == "conf/preset/cgail/small.yaml"
    assert source_of("env.num_envs", "cgail", "small", ["env.num_envs=8"]) == "command line"
    assert source_of("reward.kind", "cgail", "small", []) == "schema default"
    assert source_of("scale", "cgail", "small", []) == "conf/scale/small.yaml"


def test_explain_a_section_and_an_unknown_key():
    # scale=smoke: the small preset sets the fidelity recipe's reward keys (tests/test_cgail_presets.py)
    text = explain("cgail", "reward", ["scale=smoke", "env.num_envs=8"], load("cgail").config_class())
    assert "reward.pose_error_threshold: 0.0  (float; schema default 0.0; set by schema default)" in text
    assert "env.num_envs" not in text
    with pytest.raises(CharctlError, match="no config key 'rewards'"):
        explain("cgail", "rewards", [], load("cgail").config_class())


def test_cli_explain():
    """`charctl config ... --explain` through charctl.cli.main in this process, from the repository root."""
    ok = charctl_in_process("config", "cgail", "scale=smoke", "--explain", "env.num_envs", cwd=REPO)
    assert ok.returncode == 0, ok.stderr
    assert ok.stdout.startswith("env.num_envs: ") and "set by conf/preset/cgail/smoke.yaml" in ok.stdout
    bad = charctl_in_process("config", "cgail", "--explain", "nope", cwd=REPO)
    assert bad.returncode == 2 and bad.stderr.strip().startswith("error: no config key 'nope'")


def test_explain_prints_the_declared_choices_and_range():
    schema = load("cgail").config_class()
    ks = {k.key: k for k in knobs(schema)}
    assert ks["reward.kind"].choices == ("adversarial", "tracking") and ks["reward.kind"].type == "str"
    assert ks["ppo.gamma"].allowed() == ">= 0 and < 1" and ks["ppo.hidden"].allowed() == "each >= 1"
    assert ks["reward.w_track"].allowed() == ""  # nothing declared: no line
    text = explain("cgail", "reward", ["scale=smoke"], schema)  # smoke leaves the reward keys at the schema's
    assert "reward.kind: 'adversarial'  (str; schema default 'adversarial'; set by schema default)\n" in text
    assert "\n    allowed: one of adversarial, tracking\n" in text
    assert "reward.w_style: 0.5  (float; schema default 0.5; set by schema default)\n    allowed: >= 0\n" in text
    assert "reward.w_track: 0.0  (float; schema default 0.0; set by schema default)\n    Weight w_T" in text
