"""What a schema field may hold, declared where the field is defined (`Annotated[str, Literal[...]]` choices,
`ranged(...)` bounds), and the one generic checker that reads every experiment's declarations (check_fields)."""

from __future__ import annotations

import dataclasses
import functools
import math
import typing
from dataclasses import field
from typing import Any

# ---------------------------------------------------------------------------- declared choices and ranges
# Each schema declares what its fields may hold where the field is defined; one generic checker
# (check_fields, run by validate before the schema's own `check`) reads the declarations of every
# experiment. All of this runs before any file is written.
#
# Choices. Decision: a string-choice field is annotated `Annotated[str, Literal["a", "b"]]`. A bare
# `Literal["a", "b"]` annotation is what we would want, but OmegaConf 2.3's structured configs refuse
# it when the schema is built ("ValidationError: Unexpected type annotation: Literal[a, b]", tried
# with the installed omegaconf 2.3.1). OmegaConf reads `Annotated[str, ...]` as plain `str` (its
# typing.get_type_hints drops the extras), so the field stays a `str` node and a CLI override a plain
# string; check_fields reads the Literal back (get_type_hints(include_extras=True)) and reports a value
# outside it as "<key> must be one of a, b, got 'c'". The alternative, `str` plus the choices in the
# field's metadata, would keep them out of the type. When OmegaConf accepts Literal, drop the
# `Annotated[str, ...]` wrapper: check_fields reads a bare Literal too. Each schema's `check` starts
# with check_fields(cfg, Config, ranges=False), so a caller of `check` alone gets the choice errors.
#
# Ranges. A numeric field declares its bounds with `ranged(default, ge=..., gt=..., le=..., lt=...)`
# (a dataclasses.field whose metadata["range"] holds them; `ranged(factory=..., ge=1)` on a list
# field bounds every element). Every float must also be finite (no nan / inf), declared or not.
# A rule belongs to its field only: another section's field of the same name is not hit by it.
# Rules that involve several fields stay as code in the schema's `check`.
_BOUND_TEXT = {"ge": ">=", "gt": ">", "le": "<=", "lt": "<"}
_BOUND_OK = {"ge": lambda v, b: v >= b, "gt": lambda v, b: v > b, "le": lambda v, b: v <= b, "lt": lambda v, b: v < b}


def ranged(
    default: Any = dataclasses.MISSING,
    *,
    factory: Any = None,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
) -> Any:
    """A dataclass field with a declared range: `x: int = ranged(64, ge=1)`, `lam: float = ranged(0.95,
    ge=0, le=1)`, `hidden: list[int] = ranged(factory=lambda: [256], ge=1)` (each element >= 1)."""
    bounds = {k: v for k, v in (("ge", ge), ("gt", gt), ("le", le), ("lt", lt)) if v is not None}
    if not bounds:
        raise TypeError("ranged() needs at least one of ge, gt, le, lt")
    if (default is dataclasses.MISSING) == (factory is None):
        raise TypeError("ranged() takes a default or a factory, not both or neither")
    if factory is not None:
        return field(default_factory=factory, metadata={"range": bounds})
    return field(default=default, metadata={"range": bounds})


# ---------------------------------------------------------------------------- the generic field checker
def field_range(f: dataclasses.Field) -> dict | None:
    """The bounds a field declares ({"ge": 0, "lt": 1}), or None."""
    return (f.metadata or {}).get("range")


def range_text(bounds: dict) -> str:
    """{"ge": 0, "lt": 1} -> '>= 0 and < 1'."""
    return " and ".join(f"{_BOUND_TEXT[b]} {lim:g}" for b, lim in bounds.items() if b in _BOUND_TEXT)


def annotation_choices(hint: Any) -> tuple | None:
    """The choices of an `Annotated[str, Literal[...]]` (or a bare `Literal[...]`) annotation, or None."""
    if typing.get_origin(hint) is typing.Literal:
        return typing.get_args(hint)
    if typing.get_origin(hint) is typing.Annotated:
        for extra in hint.__metadata__:
            if typing.get_origin(extra) is typing.Literal:
                return typing.get_args(extra)
    return None


@functools.cache
def schema_choices(schema: type) -> dict[str, tuple]:
    """field name -> its declared choices, for the string-choice fields of one dataclass."""
    hints = typing.get_type_hints(schema, include_extras=True)
    found = {name: annotation_choices(hint) for name, hint in hints.items()}
    return {name: choices for name, choices in found.items() if choices is not None}


def _range_problem(key: str, value: Any, rule: dict | None) -> str | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    if not math.isfinite(value):
        return f"{key} must be a finite number, got {value}"
    for bound, limit in (rule or {}).items():
        if bound in _BOUND_OK and not _BOUND_OK[bound](value, limit):
            return f"{key} must be {range_text(rule)}, got {value:g}"
    return None


def _choice_problem(key: str, value: Any, choices: tuple | None) -> str | None:
    if choices is None or value in choices:
        return None
    return f"{key} must be one of {', '.join(str(c) for c in choices)}, got {value!r}"


_ABSENT = object()


def _get(cfg: Any, name: str) -> Any:
    """cfg[name] of a DictConfig (or dict) or cfg.name of a dataclass instance; _ABSENT when it has none."""
    if dataclasses.is_dataclass(cfg):
        return getattr(cfg, name, _ABSENT)
    return cfg[name] if name in cfg else _ABSENT


def check_fields(cfg, schema: type, prefix: str = "", ranges: bool = True) -> str | None:
    """The first value of `cfg` (a DictConfig or an instance of `schema`) outside its declared choices
    or range, or a non-finite float, as a one-line message naming the dotted key; None when all fit.
    ranges=False checks the choices only."""
    if not dataclasses.is_dataclass(schema):
        return None
    choices = schema_choices(schema)
    for f in dataclasses.fields(schema):
        value = _get(cfg, f.name)
        if value is _ABSENT:
            continue
        key = prefix + f.name
        sub = field_type(f)
        if dataclasses.is_dataclass(sub):
            problem = check_fields(value, sub, key + ".", ranges)
        elif _is_list(value):
            elem = _list_element_type(f)
            problem = None
            for i, v in enumerate(value):
                if elem is not None and dataclasses.is_dataclass(elem):
                    problem = check_fields(v, elem, f"{key}[{i}].", ranges)
                elif ranges:
                    problem = _range_problem(f"{key}[{i}]", v, field_range(f))
                if problem:
                    break
        else:
            problem = _choice_problem(key, value, choices.get(f.name))
            if problem is None and ranges:
                problem = _range_problem(key, value, field_range(f))
        if problem:
            return problem
    return None


def _is_list(value: Any) -> bool:
    from omegaconf import ListConfig

    return isinstance(value, (list, tuple, ListConfig))


def _list_element_type(f: dataclasses.Field) -> Any:
    if f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        try:
            items = f.default_factory()  # type: ignore[misc]
        except Exception:
            return None
        if items and isinstance(items, list):
            return type(items[0])
    return None


def field_type(f: dataclasses.Field) -> Any:
    if f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        try:
            return type(f.default_factory())  # type: ignore[misc]
        except Exception:
            return f.type
    return f.type
