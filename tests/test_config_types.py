"""Choices and ranges declared on the config fields (charctl.config: `Annotated[str, Literal[...]]`,
`ranged(...)`) and the one generic checker that reads them (check_fields, run by validate)."""

from dataclasses import dataclass, field
from typing import Annotated, Literal

import pytest
from omegaconf import OmegaConf
from omegaconf.errors import ValidationError

from charctl.config import BaseConfig, validate
from charctl.config_fields import check_fields, ranged, schema_choices
from charctl.errors import CharctlError

from conftest import assert_config_value_refused, assert_one_line


@dataclass
class _Mixer:
    mode: Annotated[str, Literal["fast", "slow"]] = "fast"  # a string choice
    rate: float = ranged(0.5, ge=0, le=1)  # a declared range
    widths: list[int] = ranged(factory=lambda: [8, 8], ge=1)  # every element >= 1


@dataclass
class _Other:
    rate: float = 2.0  # same name as _Mixer.rate, no declared range
    gain: float = 1.0  # no declared range: only finiteness is checked


@dataclass
class _Schema(BaseConfig):
    mixer: _Mixer = field(default_factory=_Mixer)
    other: _Other = field(default_factory=_Other)


def _validate(values: dict):
    return validate(OmegaConf.create(values), _Schema, "demo")


def test_a_bad_choice_is_one_line_naming_the_field_and_its_choices():
    assert _validate({"mixer": {"mode": "slow"}}).mixer.mode == "slow"
    with pytest.raises(CharctlError) as exc:
        _validate({"mixer": {"mode": "medium"}})
    assert str(exc.value) == "invalid config for demo: mixer.mode must be one of fast, slow, got 'medium'"
    assert_one_line(exc.value, "mixer.mode", "fast, slow", "medium")


def test_an_out_of_range_value_is_one_line_naming_the_field_and_its_range():
    assert _validate({"mixer": {"rate": 1.0}}).mixer.rate == 1.0  # the bounds are inclusive (ge / le)
    with pytest.raises(CharctlError) as exc:
        _validate({"mixer": {"rate": 1.5}})
    assert str(exc.value) == "invalid config for demo: mixer.rate must be >= 0 and <= 1, got 1.5"
    with pytest.raises(CharctlError) as exc:
        _validate({"mixer": {"widths": [8, 0]}})
    assert str(exc.value) == "invalid config for demo: mixer.widths[1] must be >= 1, got 0"
    with pytest.raises(CharctlError) as exc:  # an undeclared float must still be finite
        _validate({"other": {"gain": float("nan")}})
    assert_one_line(exc.value, "other.gain must be a finite number")
    with pytest.raises(CharctlError) as exc:  # BaseConfig.seed declares >= 0
        _validate({"seed": -1})
    assert str(exc.value) == "invalid config for demo: seed must be >= 0, got -1"


def test_a_rule_belongs_to_its_field_not_to_every_field_of_that_name():
    cfg = _validate({"other": {"rate": 5.0}})  # mixer.rate's [0, 1] does not apply to other.rate
    assert cfg.other.rate == 5.0
    with pytest.raises(CharctlError, match="mixer.rate"):
        _validate({"mixer": {"rate": 5.0}})


def test_check_fields_reads_a_dataclass_instance_too():
    assert check_fields(_Mixer(), _Mixer) is None
    assert check_fields(_Mixer(mode="x"), _Mixer, "m.") == "m.mode must be one of fast, slow, got 'x'"
    assert check_fields(_Mixer(rate=-1.0), _Mixer) == "rate must be >= 0 and <= 1, got -1"
    assert check_fields(_Mixer(rate=-1.0), _Mixer, ranges=False) is None  # choices only (check_ppo)
    assert check_fields(_Mixer(mode="x", rate=-1.0), _Mixer, ranges=False) == "mode must be one of fast, slow, got 'x'"


def test_a_choice_field_is_a_plain_string_for_omegaconf():
    """The decision in charctl/config.py: OmegaConf refuses a bare Literal annotation, reads
    Annotated[str, Literal[...]] as str. If the first assertion fails, OmegaConf accepts Literal now:
    drop the Annotated[str, ...] wrappers (check_fields reads a bare Literal as well)."""

    @dataclass
    class Bare:
        mode: Literal["fast", "slow"] = "fast"

    with pytest.raises(ValidationError, match="Unexpected type annotation"):
        OmegaConf.structured(Bare)
    merged = OmegaConf.merge(OmegaConf.structured(_Mixer), {"mode": 7})
    assert merged.mode == "7" and isinstance(merged.mode, str)  # a plain str, then refused by check_fields
    assert check_fields(merged, _Mixer) == "mode must be one of fast, slow, got '7'"
    assert schema_choices(_Mixer) == {"mode": ("fast", "slow")}


def test_ranged_needs_a_bound_and_one_default():
    with pytest.raises(TypeError, match="at least one"):
        ranged(1)
    with pytest.raises(TypeError, match="not both or neither"):
        ranged([], factory=list, ge=0)
    with pytest.raises(TypeError, match="not both or neither"):
        ranged(ge=0)


# every string-choice field of the experiments (each was a hand-written check before): a wrong value is
# the one-line error naming the key and its choices
CHOICES = [
    ("cgail", "env.backend", "cpu, warp, torch, auto"),
    ("cgail", "reward.class_form", "l1, prob, logratio"),
    ("cgail", "reward.kind", "adversarial, tracking"),
    ("cgail", "disc.style_head", "shared, per_skill"),
    ("cgail", "cgail.class_loss", "ce, ls"),
    ("cgail", "ppo.update_precision", "fp32, bf16, auto"),
    ("cgail", "ppo.activation", "relu, tanh, elu, silu"),
    ("srb", "ppo.update_precision", "fp32, bf16, auto"),
    ("srb", "tracking.solver", "daqp, qpsolvers:daqp, qpsolvers:quadprog"),
    ("srb", "action.foot_mode", "reference, paper"),
    ("com-cnn", "data.frame", "root_t, root_prev"),
    ("com-cnn", "model.fc_activation", "none, relu"),
    ("com-cnn", "train.optimizer", "sgd, adam, adamw"),
    ("hopper-ga", "runtime.kind", "local, process, ray"),
    ("motion-matching", "runtime.index", "bbox, kdtree, brute"),
    ("motion-matching", "data.bvh_forward", "auto, +x, -x, +z, -z"),
]


@pytest.mark.parametrize("experiment, key, choices", CHOICES, ids=[f"{e}-{k}" for e, k, _ in CHOICES])
def test_every_declared_choice_is_checked(experiment, key, choices):
    # refused at composition, and by the schema's check alone (tests and tools call it directly)
    assert_config_value_refused(experiment, key, "nope", f"{key} must be one of {choices}, got 'nope'")


def test_declared_choices_match_the_code_that_uses_them():
    from charctl.experiments.srb.config import TrackingConfig
    from charctl.experiments.srb.qp import SOLVERS
    from charctl.nn.mlp import ACTIVATIONS
    from charctl.rl.config import PPOConfig

    assert schema_choices(TrackingConfig)["solver"] == tuple(SOLVERS)
    assert set(schema_choices(PPOConfig)["activation"]) == set(ACTIVATIONS)
