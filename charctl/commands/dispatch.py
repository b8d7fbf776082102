"""`charctl eval` / `charctl export` as groups whose first argument selects the experiment.

`charctl eval TARGET ...`: TARGET is an experiment name or a run directory; its experiment's
declared options (`Experiment.eval_options` / `export_options`) make up the command, so
`charctl eval NAME --help` and `charctl eval RUN_DIR --help` list only the options that apply.
Nothing here knows an experiment: every name and option comes from the registry. Light at import
(typer only); the registry declarations load when a command is resolved or listed.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer
from typer.core import TyperGroup

from charctl.errors import CharctlError
from charctl.experiments import CHECKPOINTS, EXPERIMENTS, Experiment, Option, experiment_of, load, names

VERBS = {"eval": "Evaluate", "export": "Export"}
TARGETS_HELP = {
    "eval": "the experiment's name (its latest run) or run directories, then key=value overrides",
    "export": "the experiment's name (its latest run) or a run directory, then key=value overrides",
}


def _annotation(option: Option, hidden: bool = False) -> Any:
    """The typed, Typer-annotated parameter of one declared option (`hidden`: parsed, not in --help)."""
    decls = [option.flag, *([option.short] if option.short else [])]
    info = typer.Option(*decls, help=option.help, show_default=False, metavar=option.metavar or None, hidden=hidden)
    if option.kind is bool and option.nargs == 1:
        return Annotated[bool, info]
    kind = tuple[(option.kind,) * option.nargs] if option.nargs > 1 else option.kind  # type: ignore[misc]
    return Annotated[kind | None, info]


def _default(option: Option) -> Any:
    return False if option.kind is bool and option.nargs == 1 else None


def _hidden_options(exp: Experiment, command: str) -> tuple[Option, ...]:
    """Options every experiment's command parses but only some declare: `eval --checkpoints` on an
    experiment without it reaches the command, which names the experiments that have it."""
    declared = {o.name for o in exp.options(command)}
    return (CHECKPOINTS,) if command == "eval" and CHECKPOINTS.name not in declared else ()


def experiment_command(exp: Experiment, command: str, run: Callable[[list[str], dict[str, Any]], None]) -> Any:
    """A click command `charctl <command> <exp.name>` with the experiment's options; calls
    run(targets, options) with every positional argument (the first is the selecting target)."""
    options = exp.options(command)
    hidden = _hidden_options(exp, command)
    params = [
        inspect.Parameter(
            "targets",
            inspect.Parameter.POSITIONAL_OR_KEYWORD,
            default=None,
            annotation=Annotated[
                list[str] | None, typer.Argument(help=TARGETS_HELP[command], metavar="TARGETS", show_default=False)
            ],
        )
    ]
    params += [
        inspect.Parameter(
            o.name, inspect.Parameter.KEYWORD_ONLY, default=_default(o), annotation=_annotation(o, o in hidden)
        )
        for o in (*options, *hidden)
    ]

    def callback(targets: list[str] | None = None, **values: Any) -> None:
        run(list(targets or []), values)

    callback.__signature__ = inspect.Signature(params)  # type: ignore[attr-defined]
    callback.__annotations__ = {p.name: p.annotation for p in params}
    callback.__doc__ = f"{VERBS[command]} {exp.name} ({exp.summary})."
    app = typer.Typer(add_completion=False, context_settings={"help_option_names": ["-h", "--help"]})
    app.command(exp.name)(callback)
    return typer.main.get_command(app)


class ExperimentGroup(TyperGroup):
    """Subcommands: the group's own (static) commands, then one per registered experiment; a run
    directory as the first argument selects the experiment that made it."""

    command = "eval"

    def run(self, targets: list[str], options: dict[str, Any]) -> None:
        raise NotImplementedError

    def list_commands(self, ctx: Any) -> list[str]:
        return [*self.commands, *names()]

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        if cmd_name in self.commands:
            return self.commands[cmd_name]
        if cmd_name not in EXPERIMENTS:
            return None
        try:
            return experiment_command(load(cmd_name), self.command, self.run)
        except CharctlError:  # a registered experiment that is not built: not listed
            return None

    def resolve_command(self, ctx: Any, args: list[str]) -> tuple[str, Any, list[str]]:
        if args and args[0] in self.commands:
            return super().resolve_command(ctx, args)
        exp = experiment_of(args[0])  # an experiment name or a run directory; else a one-line error
        return exp.name, experiment_command(exp, self.command, self.run), args


class EvalGroup(ExperimentGroup):
    command = "eval"

    def run(self, targets: list[str], options: dict[str, Any]) -> None:
        from charctl.commands.evaluate import eval_command

        eval_command(targets, options)


class ExportGroup(ExperimentGroup):
    command = "export"

    def run(self, targets: list[str], options: dict[str, Any]) -> None:
        from charctl.commands.export import export_command

        export_command(targets[0], targets[1:], options)


def clip_export(kind: str, clip: str | None, output: Path | None, fps: float | None) -> None:
    """`charctl export bvh|video CLIP -o FILE [--fps F]`."""
    from charctl.commands.export import export_command

    export_command(kind, [clip] if clip else [], {"output": output, "fps": fps})
