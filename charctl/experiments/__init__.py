"""The experiment registry: one explicit `Experiment` record per experiment, in one dict.

`EXPERIMENTS` maps an experiment name to its package; the package's `__init__` holds a single
`EXPERIMENT = Experiment(...)` and nothing heavy (no torch/mujoco at import), so the CLI can list
experiments and their options without loading any of them. Entry points are "module:attribute"
references, imported only when called:

    schema    the structured config dataclass (a `charctl.config.BaseConfig` subclass)
    train     train(cfg, run) -> metrics dict            `charctl train NAME [overrides]`
    evaluate  evaluate(targets, options, overrides)      `charctl eval NAME|RUN... [options]`
    export    export(target, options, overrides)         `charctl export NAME|RUN [options]`
    play      play(run_dir)                              `charctl play NAME|RUN` (optional)
    checkpoints  checkpoints(targets, options, overrides) -> CheckpointEvaluation
                                                         `charctl eval NAME|RUN --checkpoints` (optional)
    preflight  preflight(cfg) -> None                    `charctl train NAME`, `--resume RUN` (optional)

`preflight` raises a one-line CharctlError for a problem the schema cannot see because it lies in the data
the config names (an unknown clip, a database with too few searchable frames). `charctl train` calls it on
every composed job (all of a `-m` sweep's) before the first run directory is made, and on a `--resume` run's
config before anything is written there. It reads, never writes, and is cheap (what it loads, `train` loads
again: 0.011 s for cgail's ten clips, so `train` keeps its signature rather than take preflight's products); a
problem only the training itself finds stays `train`'s.

`eval_options` / `export_options` declare the command-line options the experiment adds to
`charctl eval` / `charctl export`; the CLI builds each experiment's option set from them.
`charctl eval RUN --checkpoints` evaluates every kept checkpoint of a run and picks one: the loop,
the choice and its confirmation on fresh starts are the command's (charctl/commands/eval_checkpoints.py),
what is measured per checkpoint and how it is ranked the experiment's `checkpoints` entry point
(charctl/eval/checkpoints.py: what the entry points share, and the evaluation by one deterministic number).
`provides` names optional capabilities another experiment may use through the registry (never by
importing the provider), e.g. cgail's `push_rollout` is srb's full-body push baseline.
`tune_metrics` names the scalars the experiment logs as it trains (TensorBoard names, or
metrics.json keys for the final value) that `charctl tune` can optimise, each with its direction
("max" or "min"); the first is the default `--metric`.

    from charctl.experiments import load
    exp = load("srb")
    exp.entry("train")(cfg, run)
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from charctl.errors import CharctlError

EXPERIMENTS: dict[str, str] = {
    "cgail": "charctl.experiments.cgail",
    "srb": "charctl.experiments.srb",
    "com-cnn": "charctl.experiments.com_cnn",
    "motion-matching": "charctl.experiments.motion_matching",
    "hopper-ga": "charctl.experiments.hopper_ga",
}

ROLES = ("schema", "train", "evaluate", "export", "play", "checkpoints", "preflight")


@dataclass(frozen=True)
class Option:
    """One command-line option an experiment adds to `charctl eval` or `charctl export`.

    `kind` is bool (a flag), int, float, str or Path; `nargs` > 1 takes that many values (a tuple).
    A `mode` option says what to evaluate: `charctl eval` needs at least one mode option. An option
    that `requires` another (e.g. "checkpoints") is refused without it.
    """

    name: str  # Python name; the flag is --name-with-dashes
    help: str
    kind: type = bool
    short: str = ""  # e.g. "-k"
    nargs: int = 1
    mode: bool = False
    metavar: str = ""
    requires: str = ""  # the name of an option this one only refines (one-line error without it)

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")


@dataclass(frozen=True)
class Experiment:
    """What an experiment declares: its name, config schema, entry points and CLI options."""

    name: str
    summary: str  # one line, shown by `charctl eval --help` and `charctl export --help`
    schema: str  # "module:Config"
    train: str  # "module:function"
    evaluate: str = ""
    export: str = ""
    play: str = ""
    checkpoints: str = ""  # "module:factory" of `charctl eval RUN --checkpoints` (a CheckpointEvaluation)
    preflight: str = ""  # "module:function" checking a train config against its data before anything is written
    eval_options: tuple[Option, ...] = ()
    export_options: tuple[Option, ...] = ()
    provides: Mapping[str, str] = field(default_factory=dict)  # capability -> module implementing it
    eval_accepts: tuple[str, ...] = ()  # capabilities whose providers' runs `eval` also takes as targets
    tune_metrics: Mapping[str, str] = field(default_factory=dict)  # logged scalar -> "max" | "min" (charctl tune)

    def entry(self, role: str) -> Callable[..., Any]:
        """The callable behind `role` (one of ROLES); a one-line error if the experiment has none."""
        ref = getattr(self, role, "") if role in ROLES else ""
        if not ref:
            raise CharctlError(f"experiment {self.name!r} does not support `{role}`")
        return _resolve(ref)

    def preflight_check(self, cfg) -> None:
        """The experiment's `preflight` on `cfg` (a one-line CharctlError); nothing when it declares none."""
        if self.preflight:
            self.entry("preflight")(cfg)

    def config_class(self) -> type:
        """The structured config dataclass."""
        return self.entry("schema")

    def options(self, command: str) -> tuple[Option, ...]:
        """The options the experiment adds to `command` ('eval' or 'export')."""
        return {"eval": self.eval_options, "export": self.export_options}[command]

    def capability(self, name: str) -> Any:
        """The module implementing capability `name` (see `provides`)."""
        if name not in self.provides:
            raise CharctlError(f"experiment {self.name!r} does not provide {name!r}")
        return importlib.import_module(self.provides[name])


class PushRollout(Protocol):
    """Capability `push_rollout`: a trained full-body policy that can be pushed (srb's baseline)."""

    def make_push_simulator(self, run_dir: str | Path) -> Callable[[Any, int], bool]:
        """simulate(case, seed) -> survived, for charctl.experiments.srb.push.PushCase cases."""

    def find_baseline_run(self, output_root: Path) -> str:
        """The newest suitable run under `output_root` (any depth), '' if none."""

    def baseline_label(self, run_dir: str) -> str:
        """Column label of the run in the push table."""


class CheckpointEvaluation(Protocol):
    """What an experiment's `checkpoints` entry point returns for `charctl eval RUN --checkpoints`: built
    from the command's targets, options and overrides, every one of them checked (nothing is written
    before it returns). The command lists the kept checkpoints, `check`s that every one of them loads
    (still writing nothing), evaluates each with `evaluate`, picks the largest `rank_key`, evaluates that
    one again with `confirm_seed` (unless it is None), writes checkpoints.json and calls `write_report`.
    `charctl.eval.checkpoints.ScalarCheckpoints` is one for a single deterministic number."""

    run_dir: Path  # the run whose checkpoints/ are evaluated
    out: Path  # folder of the results: out/<checkpoint stem>/, out/checkpoints.*
    samples_key: str  # the key of a checkpoint state's sample count (last.pt's place among the kept ones)
    seed: int | None  # starts of the selection evaluation (None: a deterministic evaluation draws none)
    confirm_seed: int | None  # fresh starts of the chosen checkpoint's second evaluation (None: no second one)

    def check(self, name: str) -> None:
        """Load checkpoint file `name` as `evaluate` will (a one-line CharctlError if it cannot); writes nothing."""

    def evaluate(self, name: str, samples: int, out: Path, seed: int | None, confirm: bool = False) -> dict:
        """The row of checkpoint file `name` (`samples` samples), its files in `out` (reused when unchanged);
        it names "checkpoint" and "samples"."""

    def rank_key(self, row: dict) -> tuple:
        """Sort key of a row under the chosen selection rule (larger is better)."""

    def write_report(self, rows: list[dict], chosen: dict, confirm: dict | None) -> str:
        """Write the table and figures beside checkpoints.json; returns the table's text."""


def names() -> list[str]:
    """The registered experiment names, in registry order."""
    return list(EXPERIMENTS)


def load(name: str) -> Experiment:
    """The `Experiment` declared by `name`'s package; unknown or unbuilt ones are one-line errors."""
    if name not in EXPERIMENTS:
        raise CharctlError(f"unknown experiment {name!r}; choose one of: {', '.join(sorted(EXPERIMENTS))}")
    package = EXPERIMENTS[name]
    try:
        module = importlib.import_module(package)
    except ModuleNotFoundError as exc:
        if exc.name and exc.name.startswith(package):
            raise CharctlError(f"experiment {name!r} is not implemented in this version of charctl") from None
        raise
    exp = getattr(module, "EXPERIMENT", None)
    if not isinstance(exp, Experiment) or exp.name != name:
        raise CharctlError(f"{package} declares no EXPERIMENT = Experiment(name={name!r}, ...)")
    return exp


def providers(capability: str) -> list[Experiment]:
    """Every registered experiment that provides `capability`."""
    return [exp for exp in map(load, EXPERIMENTS) if capability in exp.provides]


def experiment_of(target: str | Path) -> Experiment:
    """The experiment named by `target`, or the one that made the run directory `target`."""
    from charctl.runs import run_experiment

    if str(target) in EXPERIMENTS:
        return load(str(target))
    if Path(target).is_dir():
        return load(run_experiment(target))
    raise CharctlError(
        f"{str(target)!r} is neither a run directory nor an experiment ({', '.join(sorted(EXPERIMENTS))})"
    )


def supporting(role: str) -> list[str]:
    """The registered (and built) experiments that declare entry point `role`."""
    found = []
    for name in EXPERIMENTS:
        try:
            if getattr(load(name), role, ""):
                found.append(name)
        except CharctlError:  # not built in this version
            continue
    return found


def latest_run_dir(name: str, overrides: Sequence[str] = ()) -> Path:
    """The newest run of `name` with a checkpoint under its configured `output_root`."""
    from charctl.config import compose_config
    from charctl.runs import latest_run

    cfg = compose_config(name, list(overrides), load(name).config_class())
    return latest_run(str(cfg.output_root), name)


def select_options(exp: Experiment, command: str, options: Mapping[str, Any]) -> dict[str, Any]:
    """The options `exp` declares for `command`, taken from `options`; a one-line error names any
    other option that was given (a value other than None / False)."""
    declared = {o.name for o in exp.options(command)}
    extra = sorted(k for k, v in options.items() if v not in (None, False) and k not in declared)
    if extra:
        given = ", ".join(_flag(e) for e in extra)
        supported = ", ".join(o.flag for o in exp.options(command))
        raise CharctlError(f"{exp.name} does not support {given}; it supports {supported}")
    chosen = {
        o.name: options.get(o.name, False if o.kind is bool and o.nargs == 1 else None) for o in exp.options(command)
    }
    for o in exp.options(command):
        if o.requires and chosen[o.name] not in (None, False) and chosen.get(o.requires) in (None, False):
            raise CharctlError(f"{o.flag} applies to {_flag(o.requires)} only; give {_flag(o.requires)} too")
    return chosen


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def _resolve(ref: str) -> Any:
    module, _, attr = ref.partition(":")
    return getattr(importlib.import_module(module), attr)


# ---------------------------------------------------------------------------- options several experiments share
OUT = Option("out", "folder for tables and figures (default: inside the run)", Path, short="-o")
EPISODES = Option("episodes", "episodes/trials per case", int, short="-k")
BVH = Option("bvh", "write a BVH of the policy/generated motion", Path)
VIDEO = Option("video", "write an mp4 of the policy/generated motion", Path)
SECONDS = Option("seconds", "length of a generated rollout", float)
FPS = Option("fps", "resample to this frame rate", float)
# `charctl eval RUN --checkpoints` (an experiment with a `checkpoints` entry point declares these)
CHECKPOINTS = Option(
    "checkpoints",
    "evaluate every kept checkpoint of the run (train.keep_checkpoint_every, and last.pt) and pick the best: "
    "RUN/eval/checkpoints.{json,md,png}; re-runs evaluate new ones only",
    mode=True,
)
AFTER = Option("after", "with --checkpoints: skip checkpoints before this many samples", float, requires="checkpoints")
SEED = Option("seed", "with --checkpoints: seed of the selection evaluation's starts", int, requires="checkpoints")
CONFIRM_SEED = Option(
    "confirm_seed",
    "with --checkpoints: seed of the fresh starts the chosen checkpoint is evaluated on again",
    int,
    requires="checkpoints",
)
