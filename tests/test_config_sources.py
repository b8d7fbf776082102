"""One source of truth for every config value.

Each default is stated once, in the experiment's dataclass schema (charctl/experiments/<pkg>/config.py,
with its source); conf/experiment/<name>.yaml and conf/preset/<name>/<scale>.yaml state only what
they change, and conf/config.yaml only the composition. Every experiment x scale composes and
validates.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from omegaconf import OmegaConf

from charctl.config import BaseConfig, compose_config, conf_dir, scale_choices
from charctl.experiments import EXPERIMENTS, load

NAMES = list(EXPERIMENTS)
IDENTITY_KEYS = {"experiment", "scale"}  # what a config file selects, not a value it sets


def _leaves(node: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    """(dotted key, value) of every leaf of a YAML mapping; lists are values."""
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _leaves(value, f"{prefix}{key}.")
    else:
        yield prefix[:-1], node


def _value(cfg, key: str) -> Any:
    found = OmegaConf.select(cfg, key, default="<absent>")
    return OmegaConf.to_container(found, resolve=True) if OmegaConf.is_config(found) else found


def _yaml(path: Path) -> dict:
    return OmegaConf.to_container(OmegaConf.load(path)) or {}


def _repeats(path: Path, base) -> list[str]:
    """The keys of the YAML file `path` whose value equals what `base` already holds."""
    return [
        f"{path.relative_to(conf_dir())}: {key} = {value!r}"
        for key, value in _leaves(_yaml(path))
        if key not in IDENTITY_KEYS and _value(base, key) == value
    ]


def _schema_defaults(schema: type):
    return OmegaConf.create(OmegaConf.to_container(OmegaConf.structured(schema), resolve=True))


def test_root_config_states_no_default():
    assert _repeats(conf_dir() / "config.yaml", _schema_defaults(BaseConfig)) == []


@pytest.mark.parametrize("name", NAMES)
def test_no_yaml_key_repeats_the_value_it_overrides(name):
    """conf/experiment/<name>.yaml against the schema's defaults; each preset against the schema
    defaults merged with the experiment file (what the preset overrides)."""
    defaults = _schema_defaults(load(name).config_class())
    experiment_yaml = conf_dir() / "experiment" / f"{name}.yaml"
    problems = _repeats(experiment_yaml, defaults)
    below_preset = OmegaConf.merge(defaults, _yaml(experiment_yaml))
    for preset in sorted((conf_dir() / "preset" / name).glob("*.yaml")):
        problems += _repeats(preset, below_preset)
    assert problems == [], "keys that merely repeat the value below them:\n" + "\n".join(problems)


@pytest.mark.parametrize("scale", scale_choices())
@pytest.mark.parametrize("name", NAMES)
def test_every_experiment_and_scale_composes_and_validates(name, scale):
    exp = load(name)
    cfg = compose_config(name, [f"scale={scale}"], exp.config_class())
    assert cfg.experiment == name and cfg.scale == scale
    assert (conf_dir() / "preset" / name / f"{scale}.yaml").is_file()
    assert OmegaConf.to_container(cfg, resolve=True, throw_on_missing=True)  # no ??? left


def test_physics_rate_is_stated_once():
    """The simulator, the MJCF builder and cgail's env all default to charctl.sim.PHYSICS_HZ."""
    import inspect

    from charctl.experiments.cgail.config import EnvConfig
    from charctl.sim import CONTROL_HZ, JOINT_ARMATURE, PHYSICS_HZ
    from charctl.sim.batch import SimSettings
    from charctl.sim.humanoid import build_mjcf, load_model

    assert SimSettings().physics_hz == EnvConfig().physics_hz == PHYSICS_HZ
    assert SimSettings().control_hz == EnvConfig().control_hz == CONTROL_HZ
    assert SimSettings().armature == EnvConfig().armature == JOINT_ARMATURE
    assert inspect.signature(load_model).parameters["armature"].default == JOINT_ARMATURE
    for fn in (build_mjcf, load_model):
        assert inspect.signature(fn).parameters["physics_hz"].default == PHYSICS_HZ
