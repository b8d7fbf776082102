"""Experiment registry: name -> package. Each package's `__init__` stays light (no torch/mujoco
imports at module level) and provides:

    schema() -> type                      the structured config dataclass (subclass of BaseConfig)
    train(cfg, run) -> dict               run one training job into `run` (charctl.runs.Run)
    evaluate(targets, options, overrides) `charctl eval`: targets are run dirs (or the experiment
                                          name), options the eval flags that were given
    export(target, options, overrides)    `charctl export RUN_DIR|EXPERIMENT ...`

Optional: `play(run_dir, overrides)`. Missing functions give a clear "not supported" error.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from charctl.errors import CharctlError

EXPERIMENTS: dict[str, str] = {
    "cgail": "charctl.experiments.cgail",
    "srb": "charctl.experiments.srb",
    "com-cnn": "charctl.experiments.com_cnn",
    "motion-matching": "charctl.experiments.motion_matching",
    "hopper-ga": "charctl.experiments.hopper_ga",
}


def get_experiment(name: str) -> ModuleType:
    """Import an experiment package by name; unknown or unbuilt ones are one-line errors."""
    if name not in EXPERIMENTS:
        raise CharctlError(f"unknown experiment {name!r}; choose one of: {', '.join(sorted(EXPERIMENTS))}")
    try:
        return importlib.import_module(EXPERIMENTS[name])
    except ModuleNotFoundError as exc:
        if exc.name and exc.name.startswith(EXPERIMENTS[name]):
            raise CharctlError(f"experiment {name!r} is not implemented in this version of charctl") from None
        raise


def entry(name: str, func: str):
    """The function `func` of experiment `name`, or a one-line error if it does not provide it."""
    mod = get_experiment(name)
    fn = getattr(mod, func, None)
    if isinstance(fn, ModuleType):
        # a submodule named like the entry point (e.g. train.py) shadows the function once it is
        # imported; fall back to the function of the same name inside that submodule
        fn = getattr(fn, func, None)
    if fn is None:
        raise CharctlError(f"experiment {name!r} does not support `{func}`")
    return fn


def unsupported_options(name: str, options: dict, supported: set[str]) -> None:
    """Raise a one-line error if `options` holds flags the experiment does not implement."""
    extra = sorted(k for k, v in options.items() if v not in (None, False) and k not in supported)
    if extra:
        raise CharctlError(f"{name} does not support {', '.join('--' + e.replace('_', '-') for e in extra)}; it supports {', '.join('--' + s.replace('_', '-') for s in sorted(supported))}")
