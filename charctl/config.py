"""Config composition: Hydra's compose API over `conf/`, validated against dataclass schemas.

One shared mechanism for every command that takes overrides after its positional arguments
(`charctl train cgail scale=smoke ppo.lr=1e-4`). Composition order (later wins):

    conf/config.yaml  ->  conf/experiment/<name>.yaml  ->  conf/scale/<scale>.yaml
                      ->  conf/preset/<name>/<scale>.yaml  ->  command-line overrides

and the result is merged into the experiment's structured schema (`Config` dataclass in
`charctl/experiments/<pkg>/config.py`), so an unknown key or a wrong value type fails at
start-up with a one-line message listing the valid keys, and a value outside the choices or the
range its field declares with one naming them (charctl.config_fields.check_fields).
Declared choices and ranges, and the checker that reads them, are in charctl/config_fields.py.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

from charctl.config_fields import check_fields, field_type, ranged
from charctl.errors import CharctlError


@dataclass
class BaseConfig:
    """Keys every experiment has."""

    experiment: str = "???"  # the experiment this config belongs to (the positional argument sets it)
    # smoke | small | paper: the presets of conf/scale/ (the command line picks one with scale=NAME)
    scale: Annotated[str, Literal["smoke", "small", "paper"]] = "small"
    seed: int = ranged(0, ge=0)  # every RNG (numpy, torch, env resets) derives from this
    output_root: str = "outputs"  # run directories go to <output_root>/<experiment>/<timestamp>/
    device: str = "auto"  # auto | cpu | cuda (auto: cuda when available)
    notes: str = ""  # free text stored with the run

    @classmethod
    def check(cls, cfg) -> str | None:
        """The first problem of a composed config, or None: each field's declared choices and range
        (`charctl.config_fields.check_fields`), then the experiment's cross-field rules (`cross_checks`).
        `validate` runs the same two; this is the one call for code that builds a config without it."""
        return check_fields(cfg, cls) or cls.cross_checks(cfg)

    @staticmethod
    def cross_checks(cfg) -> str | None:
        """The experiment's rules between fields (each experiment's Config overrides it): a message or None."""
        return None


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
        raise CharctlError(
            f"bad override for {experiment} ({_first_line(exc)}); overrides: {' '.join(overrides)}"
        ) from None
    if schema is not None:
        given = frozenset(o.split("=", 1)[0].lstrip("+~") for o in overrides)
        cfg = validate(cfg, schema, experiment, given=given)
        problem = check_device_available(str(cfg.get("device", "auto")))
        if problem:
            raise CharctlError(problem)
    return cfg


def validate(cfg, schema: type, experiment: str, given: frozenset[str] | None = None):
    """Merge `cfg` into `schema`; unknown keys and wrong types become one-line errors.

    A freshly composed config (`given` = the keys set on the command line) first has the keys that do not
    apply to it (the schema's `inapplicable(cfg)`, e.g. a preset's per-skill style head in an AMP run)
    reset to the schema's defaults, unless the command line set them; a recorded run's config
    (`given` None) is taken as it is."""
    from omegaconf import OmegaConf
    from omegaconf.errors import ConfigKeyError, OmegaConfBaseException, ValidationError

    base = schema_defaults(schema)
    try:
        merged = OmegaConf.merge(base, cfg)  # a deep copy of base: the cached defaults stay as they are
    except ConfigKeyError as exc:
        key = _full_key(exc)
        raise CharctlError(f"unknown config key {key!r} for {experiment}; {_valid_keys(schema, key)}") from None
    except ValidationError as exc:
        key = _full_key(exc)
        raise CharctlError(f"bad value for config key {key!r} in {experiment}: {_first_line(exc)}") from None
    except OmegaConfBaseException as exc:
        raise CharctlError(f"invalid config for {experiment}: {_first_line(exc)}") from None
    OmegaConf.set_struct(merged, True)
    if given is not None:
        _reset_inapplicable(merged, schema, given)
    problem = check_fields(merged, schema) or check_device_name(merged.get("device", "auto"), schema, experiment)
    if problem:
        raise CharctlError(f"invalid config for {experiment}: {problem}")
    cross_checks = getattr(schema, "cross_checks", None)  # BaseConfig's subclasses
    if callable(cross_checks):
        problem = cross_checks(merged)
        if problem:
            raise CharctlError(f"invalid config for {experiment}: {problem}")
    return merged


@functools.cache
def schema_defaults(schema: type):
    """`OmegaConf.structured(schema)`, built once per schema class (~0.15 s each: OmegaConf walks every
    dataclass field); callers only read it or merge it (OmegaConf.merge copies it first)."""
    from omegaconf import OmegaConf

    return OmegaConf.structured(schema)


def _reset_inapplicable(cfg, schema: type, given: frozenset[str]) -> None:
    """Reset, in place, the keys `schema.inapplicable(cfg)` names to the schema's defaults, except those in `given`."""
    from omegaconf import OmegaConf

    inapplicable = getattr(schema, "inapplicable", None)
    if not callable(inapplicable):
        return
    defaults = schema_defaults(schema)
    for key in inapplicable(cfg):
        if key not in given:
            OmegaConf.update(cfg, key, OmegaConf.select(defaults, key))


ANY_VALUE = object()  # a removed key whose every value behaves as the code that remains (RemovedKeys.neutral)


@dataclass(frozen=True)
class RemovedKeys:
    """Keys a schema no longer has, so that the config.yaml of a run recorded before still opens
    (`drop_removed_keys`): a schema lists them, one batch per removal, as its class attribute `REMOVED` (a tuple)."""

    date: str  # when they were removed
    commit: str  # the last commit that had them: a run that used one is evaluated with charctl there
    neutral: dict[str, Any]  # dotted key -> its value that behaves as the code that remains (or ANY_VALUE)


def drop_removed_keys(cfg, schema: type, source: str | Path) -> None:
    """Delete, in place, from a recorded run's config the keys `schema.REMOVED` lists when they hold their
    neutral value (the run behaves as the code that remains). A run that set one to anything else cannot
    be rebuilt by this code: a one-line error naming the commit that still can (the oldest such batch's).
    `source`: the run's folder, for the message. Called where a recorded run is opened (charctl.runs.open_run)."""
    for removed in getattr(schema, "REMOVED", ()):
        used = _drop_batch(cfg, removed)
        if used:
            raise CharctlError(
                f"{source}: this run used {', '.join(used)}, removed on {removed.date}; "
                f"evaluate it with charctl at commit {removed.commit}"
            )


def _drop_batch(cfg, removed: RemovedKeys) -> list[str]:
    """Delete one batch's keys from `cfg`; returns `key=value` of those set to a value other than their neutral one."""
    from omegaconf import OmegaConf

    used = []
    for key, neutral in removed.neutral.items():
        section, _, leaf = key.rpartition(".")
        node = OmegaConf.select(cfg, section) if section else cfg
        if not OmegaConf.is_dict(node) or leaf not in node:
            continue
        value = node[leaf]
        if neutral is not ANY_VALUE and value != neutral:
            used.append(f"{key}={str(value).lower() if isinstance(value, bool) else value}")
        del node[leaf]
    return used


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


def plain_section(section: Any) -> Any:
    """A structured OmegaConf section as its plain dataclass (same values), anything else unchanged.

    Hot loops read their section's fields thousands of times per second; through OmegaConf each read
    costs ~40 us, on a dataclass ~50 ns."""
    from omegaconf import OmegaConf

    if OmegaConf.is_config(section) and dataclasses.is_dataclass(OmegaConf.get_type(section)):
        return OmegaConf.to_object(section)
    return section


def to_yaml(cfg) -> str:
    from omegaconf import OmegaConf

    return OmegaConf.to_yaml(cfg, resolve=True)


# ---------------------------------------------------------------------------- device
_DEVICE_RE = re.compile(r"^(auto|cpu|cuda(:\d+)?)$")


def check_device_name(device: Any, schema: type | None = None, experiment: str = "") -> str | None:
    """`device` is auto | cpu | cuda | cuda:N, and one the experiment can use: a schema whose code has
    no GPU path declares `DEVICES = ("cpu",)` (a class attribute) and refuses cuda instead of ignoring it."""
    if not _DEVICE_RE.match(str(device)):
        return f"device must be auto, cpu, cuda or cuda:N, got {device!r}"
    devices = getattr(schema, "DEVICES", ("cpu", "cuda"))
    if str(device).startswith("cuda") and "cuda" not in devices:
        return (
            f"{experiment or 'this experiment'} runs on the CPU only (no GPU code path); use device=cpu or device=auto"
        )
    return None


def check_device_available(device: str) -> str | None:
    """A one-line problem when `device` names a CUDA device this machine does not have (imports torch
    only for cuda devices)."""
    if not str(device).startswith("cuda"):
        return None
    import torch

    if not torch.cuda.is_available():
        return f"device={device} but no CUDA device is available on this machine (use device=cpu or device=auto)"
    index = int(str(device).split(":")[1]) if ":" in str(device) else 0
    if index >= torch.cuda.device_count():
        return f"device={device} but this machine has {torch.cuda.device_count()} CUDA device(s)"
    return None


def resolve_device(device: str) -> str:
    """The torch device an experiment should use: auto -> cuda when available, else cpu; a missing
    CUDA device is a one-line CharctlError (also when a resumed run's config asks for one)."""
    problem = check_device_name(device) or check_device_available(device)
    if problem:
        raise CharctlError(problem)
    if device == "auto":
        import torch

        return "cuda" if torch.cuda.is_available() else "cpu"
    return str(device)


# ---------------------------------------------------------------------------- error messages
def _schema_keys(schema: type, prefix: str = "") -> set[str]:
    """Dotted paths of every field of a (nested) dataclass schema."""
    keys: set[str] = set()
    for f in dataclasses.fields(schema):
        keys.add(prefix + f.name)
        sub = field_type(f)
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


def apply_overrides(cfg, overrides: list[str]):
    """`cfg` (a recorded run's OmegaConf config) with Hydra-style `overrides` applied as a fresh `charctl train`
    applies them (Hydra's own parser: `k={a:1,b:2}`, `k=[1,2]`, `~k`), for `--resume RUN k=v ...`.

    A value replaces a leaf and merges into a mapping (Hydra's `OmegaConf.update(..., merge=True)`); `~k` removes
    the key, so validation gives it the schema's default. A value Hydra cannot parse is a one-line CharctlError."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException
    from omegaconf import OmegaConf

    _check_override_syntax(overrides)
    try:
        parsed = OverridesParser.create().parse_overrides(overrides)
    except HydraException as exc:
        raise CharctlError(f"bad override ({_first_line(exc)}); overrides: {' '.join(overrides)}") from None
    cfg = OmegaConf.create(OmegaConf.to_container(cfg))  # plain and unlocked: a copy the overrides may extend
    for o in parsed:
        key = o.key_or_group
        if o.is_delete():
            parent, _, leaf = key.rpartition(".")
            node = OmegaConf.select(cfg, parent) if parent else cfg
            if node is not None and leaf in node:
                node.pop(leaf)
        else:
            OmegaConf.update(cfg, key, o.value(), merge=True)
    return cfg


def _check_override_syntax(overrides: list[str]) -> None:
    """Each override is key=value, or ~key (Hydra's delete: the key falls back to the schema's default)."""
    for o in overrides:
        if o.startswith("~") and len(o) > 1:
            continue
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
        if f is None or not dataclasses.is_dataclass(field_type(f)):
            break
        node = field_type(f)
        prefix.append(part)
    names = ", ".join(f.name for f in dataclasses.fields(node))
    where = ".".join(prefix) or "top level"
    return f"valid keys at {where}: {names}"


__all__ = [
    "BaseConfig",
    "compose_config",
    "validate",
    "expand_multirun",
    "experiment_choices",
    "scale_choices",
    "check_experiment",
    "conf_dir",
    "to_yaml",
    "field",
    "dataclass",
    "resolve_device",
]
