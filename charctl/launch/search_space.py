"""The search space of `charctl tune`: override values written as `choice(...)`, `range(lo,hi)` or
`loguniform(lo,hi)`, parsed strictly (a malformed one is a one-line `CharctlError`).

    key=choice(a,b,c)        one of the listed values, each an override value as written
                             (`choice([walk],[walk,run])` keeps the brackets: commas inside (), [], {}
                             or quotes do not split)
    key=range(lo,hi)         integers lo <= x < hi when both bounds are integers (like Python's range),
                             else a uniform float in [lo, hi)
    key=loguniform(lo,hi)    a float in [lo, hi) uniform in log space; 0 < lo < hi

Every other `key=value` is fixed for all trials. Sampled numbers become override text with 6
significant digits, and that text is what the trial runs with and what the tables report.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

from charctl.errors import CharctlError

FUNCTIONS = ("choice", "range", "loguniform")
# look like search functions but are not ours: a clear error instead of a silent fixed value
_MISTAKES = ("uniform", "randint", "interval", "grid", "grid_search", "log_uniform", "logrange", "sweep", "sample")
_HEAD_RE = re.compile(r"^\s*([A-Za-z_]\w*)\s*\((.*)$", re.S)  # name( ... the rest
_OPEN, _CLOSE = "([{", ")]}"
USAGE = "use choice(a,b,...), range(lo,hi) or loguniform(lo,hi)"


@dataclass(frozen=True)
class Dim:
    """One searched key. `kind` is choice | randint | uniform | loguniform."""

    key: str  # as written, with any +/++ prefix
    kind: str
    values: tuple[str, ...] = ()  # choice: the override values as written
    low: float = 0.0
    high: float = 0.0

    @property
    def name(self) -> str:
        """The config key without a +/++ prefix (table columns, plot axes)."""
        return self.key.lstrip("+~")

    @property
    def log(self) -> bool:
        return self.kind == "loguniform"

    def to_tune(self) -> Any:
        """The Ray Tune sampling domain."""
        from ray import tune

        if self.kind == "choice":
            return tune.choice(list(self.values))
        if self.kind == "randint":
            return tune.randint(int(self.low), int(self.high))
        if self.kind == "uniform":
            return tune.uniform(self.low, self.high)
        return tune.loguniform(self.low, self.high)

    def extremes(self) -> list[str]:
        """Override values that bound the space (validated before any trial starts)."""
        if self.kind == "choice":
            return list(self.values)
        if self.kind == "randint":
            return [format_value(int(self.low)), format_value(int(self.high) - 1)]
        return [format_value(self.low), format_value(self.high)]

    def override(self, value: Any) -> str:
        """`key=value` for a sampled value."""
        return f"{self.key}={format_value(value)}"


def format_value(value: Any) -> str:
    """Override text for a sampled value: ints as they are, floats with 6 significant digits."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return str(value)
    if isinstance(value, int):
        return str(value)
    return format(float(value), ".6g")


def is_search(value: str) -> bool:
    """Whether an override value is written as a search function call."""
    m = _HEAD_RE.match(value)
    return bool(m) and m.group(1) in FUNCTIONS + _MISTAKES


def parse_overrides(overrides: list[str]) -> tuple[list[str], list[Dim]]:
    """Split `charctl tune` overrides into the fixed ones and the searched dimensions."""
    fixed: list[str] = []
    dims: list[Dim] = []
    for o in overrides:
        key, eq, value = o.partition("=")
        if not eq or not key.strip():
            raise CharctlError(f"bad override {o!r}: overrides look like key=value or key=choice(a,b)")
        if is_search(value):
            dim = parse_dim(key.strip(), value)
            if any(d.name == dim.name for d in dims):
                raise CharctlError(f"{dim.name} is searched twice; give one choice/range/loguniform per key")
            dims.append(dim)
        else:
            fixed.append(o)
    searched = {d.name for d in dims}
    clash = [o for o in fixed if o.partition("=")[0].strip().lstrip("+~") in searched]
    if clash:
        raise CharctlError(f"{clash[0]!r} fixes a key that is also searched; drop one of them")
    return fixed, dims


def parse_dim(key: str, text: str) -> Dim:
    """`choice(...)`, `range(lo,hi)` or `loguniform(lo,hi)` for `key`; anything else is an error."""
    m = _HEAD_RE.match(text)
    if not m:
        raise CharctlError(f"{key}={text}: not a search space; {USAGE}")
    func, rest = m.group(1), m.group(2).rstrip()
    where = f"{key}={text.strip()}"
    if func not in FUNCTIONS:
        raise CharctlError(f"{where}: unknown search function {func!r}; {USAGE}")
    if not rest.endswith(")"):
        raise CharctlError(f"{where}: missing the closing ')' of {func}(...)")
    args = split_args(rest[:-1], where)
    if func == "choice":
        return _choice(key, args, where)
    if len(args) != 2:
        raise CharctlError(f"{where}: {func} takes two bounds, {func}(lo,hi); got {len(args)} argument(s)")
    low, high = (parse_number(a, where) for a in args)
    if not low < high:
        raise CharctlError(f"{where}: the lower bound must be below the upper one, got {func}({args[0]},{args[1]})")
    if func == "loguniform":
        if low <= 0:
            raise CharctlError(f"{where}: loguniform bounds must be positive, got {args[0]}")
        return Dim(key, "loguniform", low=float(low), high=float(high))
    kind = "randint" if isinstance(low, int) and isinstance(high, int) else "uniform"
    return Dim(key, kind, low=low, high=high)


def _choice(key: str, args: list[str], where: str) -> Dim:
    seen: set[str] = set()
    for a in args:
        if a in seen:
            raise CharctlError(f"{where}: choice lists {a!r} twice")
        seen.add(a)
    return Dim(key, "choice", values=tuple(args))


def split_args(body: str, where: str) -> list[str]:
    """Top-level comma-separated arguments (commas inside brackets or quotes do not split)."""
    args: list[str] = []
    stack: list[str] = []
    quote = ""
    current = ""
    for ch in body:
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch in _OPEN:
            stack.append(_CLOSE[_OPEN.index(ch)])
        elif ch in _CLOSE:
            if not stack or stack.pop() != ch:
                raise CharctlError(f"{where}: unbalanced {ch!r}")
        elif ch == "," and not stack:
            args.append(current.strip())
            current = ""
            continue
        current += ch
    if quote or stack:
        raise CharctlError(f"{where}: unclosed {quote or 'bracket'}")
    args.append(current.strip())
    if any(not a for a in args):
        raise CharctlError(f"{where}: empty argument; {USAGE}")
    return args


def parse_number(text: str, where: str) -> int | float:
    """An int literal as int, any other finite number as float."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        raise CharctlError(f"{where}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise CharctlError(f"{where}: bounds must be finite numbers, got {text}")
    return value
