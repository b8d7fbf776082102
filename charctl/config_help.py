"""`charctl config EXPERIMENT --explain KEY`: each knob's help, type, declared choices or range, schema
default, resolved value and the config layer that set it.

The help of a knob is the comment written beside its field in the experiment's schema (and the comment
lines right above it), so it is stated once, where the default is; this module reads it back from the
dataclass source. The layer is the last of conf/config.yaml -> experiment -> scale -> preset -> command
line that names the key (charctl.config's composition order), or the schema when none does. The
choices and the range are the field's own declarations (`Annotated[str, Literal[...]]`, `ranged(...)`),
the ones charctl.config_fields.check_fields enforces.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import io
import textwrap
import tokenize
import typing
from dataclasses import dataclass
from pathlib import Path

from charctl.errors import CharctlError


@dataclass(frozen=True)
class Knob:
    key: str  # dotted key, e.g. "reward.pose_error_threshold"
    type: str
    default: object
    help: str
    choices: tuple | None = None  # a string-choice field's allowed values
    range: dict | None = None  # a numeric field's declared bounds, e.g. {"ge": 0, "lt": 1}
    each: bool = False  # the range bounds every element (a list field)

    def allowed(self) -> str:
        """'one of a, b' or '>= 0 and < 1' (list fields: 'each >= 1'); '' when nothing is declared."""
        from charctl.config_fields import range_text

        if self.choices:
            return "one of " + ", ".join(str(c) for c in self.choices)
        if self.range:
            return ("each " if self.each else "") + range_text(self.range)
        return ""


def _comments(cls: type) -> dict[str, str]:
    """field name -> its help: the comment lines right above the field, then the comment beside it (on
    any line of a definition that the formatter wrapped)."""
    try:
        source = textwrap.dedent(inspect.getsource(cls))
    except (OSError, TypeError):
        return {}
    comments = {
        tok.start[0]: tok.string.lstrip("#").strip()
        for tok in tokenize.generate_tokens(io.StringIO(source).readline)
        if tok.type == tokenize.COMMENT
    }
    lines = source.splitlines()
    node_cls = ast.parse(source).body[0]
    body = node_cls.body
    out, prev_end = {}, node_cls.lineno
    for node in body:
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            gap = range(prev_end + 1, node.lineno)
            above = [comments[n] for n in gap if n in comments and lines[n - 1].lstrip().startswith("#")]
            own = [comments[n] for n in range(node.lineno, node.end_lineno + 1) if n in comments]
            out[node.target.id] = " ".join([*above, *own])
        prev_end = node.end_lineno
    return out


def _default(f: dataclasses.Field) -> object:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return "???"


def knobs(schema: type, prefix: str = "") -> list[Knob]:
    """Every leaf field of `schema` (nested dataclasses walked), in declaration order."""
    from charctl.config_fields import field_range, schema_choices

    hints = typing.get_type_hints(schema)
    choices = schema_choices(schema)
    docs = {}
    for cls in reversed(schema.__mro__):  # a base class's comments, then the subclass's
        if dataclasses.is_dataclass(cls):
            docs.update({name: text for name, text in _comments(cls).items() if text})
    out = []
    for f in dataclasses.fields(schema):
        hint = hints.get(f.name, f.type)
        if isinstance(hint, type) and dataclasses.is_dataclass(hint):
            out += knobs(hint, f"{prefix}{f.name}.")
            continue
        name = getattr(hint, "__name__", None) if isinstance(hint, type) else None
        out.append(
            Knob(
                prefix + f.name,
                name or str(hint).replace("typing.", ""),
                _default(f),
                docs.get(f.name, ""),
                choices=choices.get(f.name),
                range=field_range(f),
                each=typing.get_origin(hint) is list,
            )
        )
    return out


def _layer_files(experiment: str, scale: str) -> list[tuple[str, Path]]:
    from charctl.config import conf_dir

    root = conf_dir()
    return [
        ("conf/config.yaml", root / "config.yaml"),
        (f"conf/experiment/{experiment}.yaml", root / "experiment" / f"{experiment}.yaml"),
        (f"conf/scale/{scale}.yaml", root / "scale" / f"{scale}.yaml"),
        (f"conf/preset/{experiment}/{scale}.yaml", root / "preset" / experiment / f"{scale}.yaml"),
    ]


def _sets(path: Path, key: str) -> bool:
    from omegaconf import OmegaConf

    if not path.is_file():
        return False
    return OmegaConf.select(OmegaConf.load(path), key, default="__unset__") != "__unset__"


def source_of(key: str, experiment: str, scale: str, overrides: list[str]) -> str:
    """The last layer that sets `key`: the command line, a conf/ file, or the schema's default."""
    if any(o.split("=", 1)[0].lstrip("+~") == key for o in overrides):
        return "command line"
    found = "schema default"
    for label, path in _layer_files(experiment, scale):
        if _sets(path, key):
            found = label
    return found


def explain(experiment: str, key: str, overrides: list[str], schema: type) -> str:
    """The explanation of every knob whose dotted key is `key` or lies under it (`reward` lists them all)."""
    from omegaconf import OmegaConf

    from charctl.config import compose_config

    cfg = compose_config(experiment, overrides, schema)
    chosen = [k for k in knobs(schema) if k.key == key or k.key.startswith(key + ".")]
    if not chosen:
        near = sorted({k.key.split(".")[0] for k in knobs(schema)})
        raise CharctlError(f"no config key {key!r} in {experiment}; its sections and keys: {', '.join(near)}")
    blocks = []
    for k in chosen:
        value = OmegaConf.select(cfg, k.key)
        value = OmegaConf.to_container(value) if OmegaConf.is_config(value) else value
        src = source_of(k.key, experiment, str(cfg.scale), overrides)
        lines = [f"{k.key}: {value!r}  ({k.type}; schema default {k.default!r}; set by {src})"]
        if k.allowed():
            lines.append(f"    allowed: {k.allowed()}")
        if k.help:
            lines.append(f"    {k.help}")
        blocks.append("\n".join(lines))
    return "\n".join(blocks)
