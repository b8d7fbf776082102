"""Checks of the command-line options of `charctl eval` / `charctl export`, run before any work and
before anything is written: numbers in range (no nan / inf), output files writable.

    from charctl.options import check_options
    check_options(options)          # options: the dict the CLI builds, e.g. {"fps": 60.0, "bvh": Path(...)}

Declared once here for every experiment; an option that is None / False (not given) is not checked.
"""

from __future__ import annotations

import math
import operator
from pathlib import Path
from typing import Any

from charctl.errors import CharctlError

# option name -> (bound, limit): the value must be > / >= the limit
NUMBER_RULES: dict[str, tuple[str, float]] = {
    "fps": (">", 0.0),
    "seconds": (">", 0.0),
    "crouch_at": (">=", 0.0),
    "episodes": (">=", 1),
    "survival": (">", 0.0),
    "confusion_k": (">=", 1),
    "fidelity_k": (">=", 1),
    "after": (">=", 0.0),
    "min_no_fall": (">=", 0.0),
    "min_diagonal": (">=", 0.0),
    "min_coverage": (">=", 0.0),
    "seed": (">=", 0),
    "confirm_seed": (">=", 0),
}
# option name -> (bound, limit): the value must also be < / <= the limit
UPPER_RULES: dict[str, tuple[str, float]] = {
    "min_no_fall": ("<=", 1.0),  # shares in [0, 1]
    "min_diagonal": ("<=", 1.0),
    "min_coverage": ("<=", 1.0),
}
_COMPARE = {">": operator.gt, ">=": operator.ge, "<": operator.lt, "<=": operator.le}
# options that name a file charctl writes
OUTPUT_FILES = ("output", "bvh", "video", "onnx", "torchscript")


def flag(name: str) -> str:
    short = {"episodes": "--episodes/-k", "output": "-o/--output", "out": "-o/--out"}
    return short.get(name, "--" + name.replace("_", "-"))


def check_numbers(options: dict[str, Any]) -> None:
    """Every option of NUMBER_RULES / UPPER_RULES that is given: a finite number within its bounds."""
    for name, (bound, limit) in [*NUMBER_RULES.items(), *UPPER_RULES.items()]:
        value = options.get(name)
        if value is None or isinstance(value, bool):
            continue
        if not isinstance(value, (int, float)) or not math.isfinite(value):
            raise CharctlError(f"{flag(name)} must be a finite number, got {value}")
        if not _COMPARE[bound](value, limit):
            raise CharctlError(f"{flag(name)} must be {bound} {limit:g}, got {value:g}")


def check_outputs(options: dict[str, Any]) -> None:
    from charctl.paths import check_output_file, check_writable_dir

    for name in OUTPUT_FILES:
        value = options.get(name)
        if value:
            check_output_file(Path(value), flag(name))
    out = options.get("out")
    if out:
        check_writable_dir(Path(out), flag("out"))


def check_options(options: dict[str, Any]) -> None:
    """Every eval/export option value in range and every output writable; one-line errors."""
    check_numbers(options)
    check_outputs(options)
