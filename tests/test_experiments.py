"""The experiment registry and the command line built from it.

Every experiment declares itself (charctl.experiments.Experiment): its entry points resolve, the
CLI offers exactly the options it declares (`charctl eval NAME --help`, or a run directory in
place of the name), the generic layer (cli.py, charctl/commands) names no experiment, and no
experiment imports another one.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from charctl.config import BaseConfig
from charctl.errors import CharctlError
from charctl.experiments import EXPERIMENTS, ROLES, Experiment, load, providers

from conftest import REPO, assert_one_line, assert_one_line_error, run_charctl

NAMES = list(EXPERIMENTS)
PACKAGE_DIR = REPO / "charctl" / "experiments"


def _flags(help_text: str) -> set[str]:
    return set(re.findall(r"(?<![\w-])--[a-z][a-z-]*", help_text)) - {"--help"}


@pytest.mark.parametrize("name", NAMES)
def test_every_experiment_declares_resolvable_entry_points(name):
    exp = load(name)
    assert isinstance(exp, Experiment) and exp.name == name
    assert issubclass(exp.config_class(), BaseConfig)
    for role in ROLES:
        if getattr(exp, role):
            assert callable(exp.entry(role)), f"{name}.{role} -> {getattr(exp, role)}"
    for capability in exp.provides:
        assert exp.capability(capability) is not None
    flags = [o.flag for o in exp.eval_options] + [o.flag for o in exp.export_options]
    assert len(set(o.flag for o in exp.eval_options)) == len(exp.eval_options)
    assert len(set(o.flag for o in exp.export_options)) == len(exp.export_options)
    assert all(re.fullmatch(r"--[a-z][a-z-]*", f) for f in flags)
    assert any(o.mode for o in exp.eval_options), "eval needs at least one option that says what to evaluate"


def test_unknown_experiment_and_missing_entry_point_are_one_line_errors():
    with pytest.raises(CharctlError) as exc:
        load("nope")
    assert_one_line(exc.value, "nope", "cgail")
    with pytest.raises(CharctlError) as exc:
        load("srb").entry("play")
    assert_one_line(exc.value, "srb", "play")


@pytest.mark.parametrize("command", ["eval", "export"])
@pytest.mark.parametrize("name", NAMES)
def test_help_lists_only_the_chosen_experiments_options(charctl_main, name, command):
    res = charctl_main(command, name, "--help")
    assert res.returncode == 0, res.stdout + res.stderr
    declared = {o.flag for o in load(name).options(command)}
    assert _flags(res.stdout) == declared, res.stdout


def test_help_of_a_run_directory_lists_its_experiments_options(tmp_path):
    """`charctl eval RUN_DIR --help` through the installed console script: the run's experiment decides."""
    run_dir = tmp_path / "srb" / "2026-01-01_00-00-00"
    run_dir.mkdir(parents=True)
    (run_dir / "config.yaml").write_text("experiment: srb\n")
    res = run_charctl("eval", str(run_dir), "--help")
    assert res.returncode == 0, res.stdout + res.stderr
    assert _flags(res.stdout) == {o.flag for o in load("srb").eval_options}
    assert "--dtw" not in res.stdout and "--sweep" not in res.stdout


def test_group_help_lists_the_experiments(charctl_main):
    for command in ("eval", "export"):
        out = charctl_main(command, "--help").stdout
        assert all(name in out for name in NAMES), out
    assert {"bvh", "video"} <= set(re.findall(r"\w+", charctl_main("export", "--help").stdout))


def test_an_option_of_another_experiment_is_refused(charctl_main):
    res = charctl_main("eval", "srb", "--dtw")
    assert res.returncode != 0 and "--dtw" in res.stderr


def test_checkpoints_on_an_experiment_without_them_names_those_that_have_them(charctl_main):
    """`charctl eval NAME --checkpoints` is parsed for every experiment (not listed in its --help where it
    does not apply); one without a `checkpoints` entry point says which experiments have one."""
    from charctl.experiments import supporting

    have = supporting("checkpoints")
    assert have == [n for n in NAMES if load(n).checkpoints] and "cgail" in have
    for name in (n for n in NAMES if n not in have):
        res = charctl_main("eval", name, "--checkpoints")
        assert_one_line_error(res, name, "--checkpoints", *have)
    res = charctl_main("eval", "cgail", "--survival", "5", "--after", "1000")  # a --checkpoints option alone
    assert_one_line_error(res, "--after", "--checkpoints")


def test_generic_layer_names_no_experiment():
    """cli.py and charctl/commands/ take every experiment name and option from the registry."""
    files = [REPO / "charctl" / "cli.py", *sorted((REPO / "charctl" / "commands").glob("*.py"))]
    for path in files:
        text = path.read_text()
        for name in NAMES:
            assert not re.search(rf"(?<![\w-]){re.escape(name)}(?![\w-])", text), f"{path.name} names {name!r}"


def _imported_modules(path: Path) -> set[str]:
    mods: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            mods |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            mods.add(node.module)
            mods |= {f"{node.module}.{a.name}" for a in node.names}
    return mods


@pytest.mark.parametrize("package", sorted(p.name for p in PACKAGE_DIR.iterdir() if (p / "__init__.py").is_file()))
def test_no_experiment_imports_another(package):
    others = {p.name for p in PACKAGE_DIR.iterdir() if (p / "__init__.py").is_file()} - {package}
    for path in sorted((PACKAGE_DIR / package).glob("*.py")):
        for mod in _imported_modules(path):
            parts = mod.split(".")
            assert not (parts[:2] == ["charctl", "experiments"] and len(parts) > 2 and parts[2] in others), (
                f"{package}/{path.name} imports {mod}"
            )


def test_capabilities_are_reached_through_the_registry():
    """srb's push study takes its full-body baseline from whichever experiment provides `push_rollout`."""
    assert [exp.name for exp in providers("push_rollout")] == ["cgail"]
    rollout = load("cgail").capability("push_rollout")
    for fn in ("make_push_simulator", "find_baseline_run", "baseline_label"):
        assert callable(getattr(rollout, fn))
    assert "push_rollout" in load("srb").eval_accepts
