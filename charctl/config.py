"""Config composition: Hydra's compose API over `conf/`, validated against dataclass schemas.

One shared mechanism for every command that takes overrides after its positional arguments
(`charctl train cgail scale=smoke ppo.lr=1e-4`). Composition order (later wins):

    conf/config.yaml  ->  conf/experiment/<name>.yaml  ->  conf/scale/<scale>.yaml
                      ->  conf/preset/<name>/<scale>.yaml  ->  command-line overrides

and the result is merged into the experiment's structured schema (`Config` dataclass in
`charctl/experiments/<pkg>/config.py`), so an unknown key or a wrong value type fails at
start-up with a one-line message listing the valid keys.
"""

from __future__ import annotations

import dataclasses
import itertools
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from charctl.errors import CharctlError


@dataclass
class BaseConfig:
    """Keys every experiment has."""

    experiment: str = "???"
    scale: str = "small"  # smoke | small | paper
    seed: int = 0
    output_root: str = "outputs"  # run directories go to <output_root>/<experiment>/<timestamp>/
    device: str = "auto"  # auto | cpu | cuda
    notes: str = ""  # free text stored with the run


def conf_dir() -> Path:
    """The `conf/` folder (repo root next to the package, or $CHARCTL_CONF)."""
    env = os.environ.get("CHARCTL_CONF")
    path = Path(env) if env else Path(__file__).resolve().parent.parent / "conf"
    if not (path / "config.yaml").is_file():
        raise CharctlError(f"config folder not found at {path} (set CHARCTL_CONF to the repo's conf/)")
    return path


def experiment_choices() -> list[str]:
    return sorted(p.stem for p in (conf_dir() / "experiment").glob("*.yaml"))


def scale_choices() -> list[str]:
    return sorted(p.stem for p in (conf_dir() / "scale").glob("*.yaml"))


def check_experiment(name: str) -> None:
    choices = experiment_choices()
    if name not in choices:
        raise CharctlError(f"unknown experiment {name!r}; choose one of: {', '.join(choices)}")


def compose_config(experiment: str, overrides: list[str] | None = None, schema: type | None = None):
    """Compose and validate the config of `experiment` with Hydra-style `overrides`.

    Returns an OmegaConf DictConfig (struct mode: reading or writing an unknown key raises).
    """
    from hydra import compose, initialize_config_dir
    from hydra.errors import HydraException
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    check_experiment(experiment)
    overrides = list(overrides or [])
    _check_override_syntax(overrides)
    for o in overrides:
        if o.split("=", 1)[0].lstrip("+~") == "experiment":
            raise CharctlError("the experiment is the positional argument, not an override (drop 'experiment=')")
    overrides = _force_schema_keys(overrides, schema)
    try:
        with initialize_config_dir(str(conf_dir()), version_base="1.3"):
            cfg = compose("config", overrides=[f"experiment={experiment}", *overrides])
    except HydraException as exc:
        raise CharctlError(_explain_hydra_error(exc, experiment, schema)) from None
    except (OmegaConfBaseException, ValueError, KeyError, IndexError, TypeError) as exc:  # e.g. `a_list.key=1`
        raise CharctlError(f"bad override for {experiment} ({_first_line(exc)}); overrides: {' '.join(overrides)}") from None
    if schema is not None:
        cfg = validate(cfg, schema, experiment)
    return cfg


def validate(cfg, schema: type, experiment: str):
    """Merge `cfg` into `schema`; unknown keys and wrong types become one-line errors."""
    from omegaconf import OmegaConf
    from omegaconf.errors import ConfigKeyError, OmegaConfBaseException, ValidationError

    base = OmegaConf.structured(schema)
    try:
        merged = OmegaConf.merge(base, cfg)
    except ConfigKeyError as exc:
        key = _full_key(exc)
        raise CharctlError(f"unknown config key {key!r} for {experiment}; {_valid_keys(schema, key)}") from None
    except ValidationError as exc:
        key = _full_key(exc)
        raise CharctlError(f"bad value for config key {key!r} in {experiment}: {_first_line(exc)}") from None
    except OmegaConfBaseException as exc:
        raise CharctlError(f"invalid config for {experiment}: {_first_line(exc)}") from None
    OmegaConf.set_struct(merged, True)
    check = getattr(schema, "check", None)
    if callable(check):
        problem = check(merged)
        if problem:
            raise CharctlError(f"invalid config for {experiment}: {problem}")
    return merged


def expand_multirun(overrides: list[str]) -> list[list[str]]:
    """Expand Hydra sweep syntax (`a=1,2 b=range(3)`) into the cartesian product of override lists."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException

    try:
        parsed = OverridesParser.create().parse_overrides(overrides)
    except HydraException as exc:
        raise CharctlError(f"bad override: {_first_line(exc)}") from None
    axes = []
    for o in parsed:
        prefix = {None: "", "ADD": "+", "FORCE_ADD": "++", "DEL": "~"}.get(getattr(o.type, "name", None), "")
        key = prefix + o.key_or_group
        if o.is_sweep_override():
            axes.append([f"{key}={v}" for v in o.sweep_string_iterator()])
        else:
            axes.append([o.input_line])
    return [list(c) for c in itertools.product(*axes)] if axes else [[]]


def to_yaml(cfg) -> str:
    from omegaconf import OmegaConf

    return OmegaConf.to_yaml(cfg, resolve=True)


# ---------------------------------------------------------------------------- error messages
def _schema_keys(schema: type, prefix: str = "") -> set[str]:
    """Dotted paths of every field of a (nested) dataclass schema."""
    keys: set[str] = set()
    for f in dataclasses.fields(schema):
        keys.add(prefix + f.name)
        sub = _field_type(f)
        if dataclasses.is_dataclass(sub):
            keys |= _schema_keys(sub, f"{prefix}{f.name}.")
    return keys


def _force_schema_keys(overrides: list[str], schema: type | None) -> list[str]:
    """`key=value` -> `++key=value` for keys the schema defines but the yaml files may not spell out,
    so Hydra's struct check accepts them; config groups (scale=...) and unknown keys are left alone
    (an unknown key still fails with the list of valid keys; the schema merge checks the types)."""
    if schema is None or not dataclasses.is_dataclass(schema):
        return overrides
    keys = _schema_keys(schema)
    groups = {p.name for p in conf_dir().iterdir() if p.is_dir()}
    out = []
    for o in overrides:
        key = o.split("=", 1)[0]
        out.append("++" + o if key in keys and key.split(".")[0] not in groups else o)
    return out


def _check_override_syntax(overrides: list[str]) -> None:
    for o in overrides:
        if "=" not in o or o.startswith("="):
            raise CharctlError(f"bad override {o!r}: overrides look like key=value (e.g. scale=smoke ppo.lr=1e-4)")


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def _full_key(exc) -> str:
    key = getattr(exc, "full_key", None) or getattr(exc, "key", None) or ""
    return str(key)


def _explain_hydra_error(exc: Exception, experiment: str, schema: type | None) -> str:
    msg = str(exc)
    first = _first_line(exc)
    if "Could not override" in msg:
        key = first.split("'")[1] if "'" in first else first
        hint = _valid_keys(schema, key) if schema is not None else ""
        return f"unknown config key {key!r} for {experiment}" + (f"; {hint}" if hint else "")
    if "Could not find" in msg and "Available options" in msg:
        group = first.split("'")[-2].split("/")[0] if "'" in first else "option"
        opts = [l.strip() for l in msg.split("Available options")[1].splitlines()[1:] if l.startswith("\t")]
        return f"unknown {group} {first.split('/')[-1].rstrip(chr(39))!r}; choose one of: {', '.join(opts)}"
    if "Could not find" in msg:
        return f"no preset for this experiment/scale: {first}"
    return f"bad override: {first}"


def _valid_keys(schema: type | None, key: str) -> str:
    """'keys under ppo: a, b, c' for the deepest existing dataclass on the path of `key`."""
    if schema is None or not dataclasses.is_dataclass(schema):
        return ""
    node: Any = schema
    parts = [p for p in key.split(".") if p]
    prefix = []
    for part in parts[:-1]:
        f = {x.name: x for x in dataclasses.fields(node)}.get(part)
        if f is None or not dataclasses.is_dataclass(_field_type(f)):
            break
        node = _field_type(f)
        prefix.append(part)
    names = ", ".join(f.name for f in dataclasses.fields(node))
    where = ".".join(prefix) or "top level"
    return f"valid keys at {where}: {names}"


def _field_type(f: dataclasses.Field) -> Any:
    if f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        try:
            return type(f.default_factory())  # type: ignore[misc]
        except Exception:
            return f.type
    return f.type


__all__ = [
    "BaseConfig", "compose_config", "validate", "expand_multirun", "experiment_choices", "scale_choices",
    "check_experiment", "conf_dir", "to_yaml", "field", "dataclass",
]
