"""Shared fixtures and helpers for the charctl test suite.

Kept small on purpose: experiment test files add their own fixtures next to their tests.
Helpers here are about the foundation's contract that every command shares: a bad input is a
one-line `CharctlError` (`error: ...` on stderr, non-zero exit), never a traceback.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

import charctl  # noqa: F401  (first: picks MuJoCo's headless GL backend before any test imports mujoco)

REPO = Path(__file__).resolve().parent.parent
AMP_RUN = REPO / "pretrained" / "amp-3skill"  # the shipped unconditional (AMP) three-skill run, read only
VENV_BIN = Path(sys.executable).parent
CHARCTL = VENV_BIN / "charctl"


FAULT_HOOKS = REPO / "tests" / "fault_hooks"  # sitecustomize.py: CHARCTL_FAULT_* checkpoint faults


def load_script(name: str):
    """The module of scripts/<name>.py (scripts are not a package), registered in sys.modules."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, REPO / "scripts" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def with_fault_hooks(env: dict[str, str]) -> dict[str, str]:
    """`env` with the fault hooks on PYTHONPATH when it sets a CHARCTL_FAULT_* variable (a subprocess
    then imports tests/fault_hooks/sitecustomize.py at start-up, which installs the faults)."""
    if any(k.startswith("CHARCTL_FAULT_") for k in env):
        inherited = env.get("PYTHONPATH", os.environ.get("PYTHONPATH", ""))
        env = {**env, "PYTHONPATH": os.pathsep.join(filter(None, [str(FAULT_HOOKS), inherited]))}
    return env


def cgail_paper_recipe() -> list[str]:
    """mk/cgail.mk's CGAIL_PAPER_RECIPE: the `~key` deletions that return the small preset's fidelity-recipe keys to
    the schema's (the paper's) values."""
    import re

    text = (REPO / "mk" / "cgail.mk").read_text()
    body = re.search(r"^CGAIL_PAPER_RECIPE := (.*?)\n(?!\t)", text, re.S | re.M).group(1)
    return body.replace("\\\n", " ").split()


# the fidelity recipe's env rules, for the parity and smoke tests of the torch envs (Warp, torch on the CPU)
FIDELITY_ENV_RULES = (
    "env.phase_obs=true",
    "reward.pose_error_threshold=0.5",
    "reward.w_track=1.0",
    "reward.low_style_threshold=0.05",
    "env.skill_fall_weight=0.5",
)


def assert_step_matches_cpu_env(c_env, c_res, t_env, t_res, fidelity: bool) -> None:
    """A torch env's step (`t_res`, tensors) equals the numpy `CgailEnv`'s (`c_res`) after the same actions: next
    disc obs and state before resets (float32 rounding, 2e-3), goal reward, terminations, the command blend and,
    with the fidelity rules, the phase in the state, the pose ends (some, not all) and r_track (some > 0)."""

    def npy(x):
        return x.detach().cpu().numpy()

    np.testing.assert_allclose(npy(t_res.pair_next), c_res.pair_next, atol=2e-3)
    np.testing.assert_allclose(npy(t_res.final_state), c_res.final_state, atol=2e-3)
    np.testing.assert_allclose(npy(t_res.r_goal), c_res.r_goal, atol=1e-3)
    np.testing.assert_array_equal(npy(t_res.terminated), c_res.terminated)
    np.testing.assert_allclose(npy(t_env.command_blend()), c_env.command_blend(), atol=1e-7)
    if fidelity:
        assert c_env.state_dim == t_env.state_dim == 245  # the phase is in the state
        np.testing.assert_array_equal(npy(t_res.pose_ended), c_res.pose_ended)
        assert c_res.pose_ended.any() and not c_res.pose_ended.all(), c_res.pose_ended
        np.testing.assert_allclose(npy(t_res.r_track), c_res.r_track, atol=2e-3)
        assert (c_res.r_track > 0).any()
        np.testing.assert_allclose(npy(t_res.pose_reference), c_res.pose_reference, atol=2e-3)


def assert_config_value_refused(experiment: str, key: str, value: str, message: str) -> BaseException:
    """The override `key=value` is refused when `experiment`'s config is composed (scale=smoke) with exactly
    'invalid config for EXPERIMENT: MESSAGE', and the schema's check alone (tests and tools call it directly),
    on the schema's defaults with `key` set to `value` read as YAML, returns MESSAGE. Returns the composition's
    CharctlError."""
    import yaml
    from omegaconf import OmegaConf

    from charctl.config import compose_config
    from charctl.errors import CharctlError
    from charctl.experiments import load

    schema = load(experiment).config_class()
    with pytest.raises(CharctlError) as exc:
        compose_config(experiment, ["scale=smoke", f"{key}={value}"], schema)
    assert str(exc.value) == f"invalid config for {experiment}: {message}"
    section, _, name = key.rpartition(".")
    values = {section: {name: yaml.safe_load(value)}} if section else {name: yaml.safe_load(value)}
    assert schema.check(OmegaConf.merge(OmegaConf.structured(schema), values)) == message
    return exc.value


# com-cnn shrunk for the tests that train it (test_com_cnn, test_eval_checkpoints): two clips, the turn held out,
# a 15-frame history, a small network, Adam at 3e-3; each test adds its steps and output_root
TINY_COM_CNN = (
    "scale=smoke",
    "data.clips=[walk,walker/turn_right1]",
    "data.test_clips=[walker/turn_right1]",
    "data.history=15",
    "model.kernel=2",
    "model.channels=[8,16,32]",
    "train.optimizer=adam",
    "train.lr=0.003",
)


def cli_env(**extra: str) -> dict[str, str]:
    """Environment for a charctl subprocess: wide, colourless rich output, no GPU/renderer surprises;
    CHARCTL_FAULT_* variables in `extra` switch the test-only checkpoint faults on (`with_fault_hooks`)."""
    env = dict(os.environ)
    env.update({"COLUMNS": "250", "NO_COLOR": "1", "TERM": "dumb", "OMP_NUM_THREADS": "1"})
    env.update(extra)
    return with_fault_hooks(env)


def run_charctl(
    *args: str, cwd: Path | None = None, env: dict[str, str] | None = None, timeout: float = 120
) -> subprocess.CompletedProcess:
    """Run the installed `charctl` console script as a user would (text mode, captured output)."""
    exe = str(CHARCTL) if CHARCTL.exists() else None
    cmd = [exe, *args] if exe else [sys.executable, "-c", "from charctl.cli import main; main()", *args]
    return subprocess.run(cmd, cwd=cwd or REPO, env=env or cli_env(), capture_output=True, text=True, timeout=timeout)


def assert_one_line_error(res: subprocess.CompletedProcess, *must_contain: str) -> str:
    """A failed command: non-zero exit, exactly one stderr line starting 'error:', no traceback."""
    out = res.stdout + res.stderr
    assert "Traceback" not in out, f"traceback in output:\n{out}"
    assert res.returncode != 0, f"expected failure, got exit 0:\n{out}"
    lines = [l for l in res.stderr.splitlines() if l.strip()]
    assert len(lines) == 1, f"expected exactly one stderr line, got {len(lines)}:\n{res.stderr}"
    assert lines[0].startswith("error:"), lines[0]
    for s in must_contain:
        assert s in lines[0], f"{s!r} not in {lines[0]!r}"
    return lines[0]


def assert_one_line(exc: BaseException, *must_contain: str) -> str:
    """A raised CharctlError: one non-empty line naming what it must name."""
    msg = str(exc)
    assert msg and "\n" not in msg.strip(), f"message is not one line: {msg!r}"
    for s in must_contain:
        assert s in msg, f"{s!r} not in {msg!r}"
    return msg


def charctl_in_process(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """`charctl ARGS` through `charctl.cli.main` in this process, in `cwd` (restored after), with stdout
    and stderr captured (also in module-scoped fixtures, which cannot take `capsys`) and rich output as
    `cli_env` sets it for a subprocess (wide, colourless); returns a CompletedProcess with main()'s exit
    status. An exception escaping main() - a traceback for the user - comes back as its traceback on
    stderr with status 1, so `assert_one_line_error` names it. Use `run_charctl` where the test needs a
    real process: signals, environment read at start-up, fault hooks."""
    from charctl.cli import main

    return _main_in_process(main, ["charctl", *args], cwd)


def script_in_process(name: str, *args: str) -> subprocess.CompletedProcess:
    """`python scripts/<name>.py ARGS` through the script's `main()` in this process (a fresh load of the
    module), captured as `charctl_in_process` captures charctl: the same exit status and streams as the
    interpreter gives (`raise SystemExit("error: ...")` prints its message on stderr with status 1), without
    the ~3 s interpreter and torch start-up of a subprocess."""
    return _main_in_process(load_script(name).main, [f"scripts/{name}.py", *args], None)


def _main_in_process(main, argv: list[str], cwd: Path | None) -> subprocess.CompletedProcess:
    """Run `main()` with sys.argv = `argv` in `cwd`, stdout and stderr captured, rich output wide and colourless;
    SystemExit and an escaping exception become the exit status (and message or traceback) the interpreter
    would give."""
    import contextlib
    import io
    import traceback

    out, err = io.StringIO(), io.StringIO()
    old_argv, old_cwd = sys.argv, os.getcwd()
    rich_env = {"COLUMNS": "250", "NO_COLOR": "1", "TERM": "dumb"}
    old_env = {k: os.environ.get(k) for k in rich_env}
    os.environ.update(rich_env)
    sys.argv = list(argv)
    try:
        if cwd is not None:
            os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                main()
                code = 0
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
                if exc.code is not None and not isinstance(exc.code, int):
                    print(exc.code, file=sys.stderr)
            except Exception:
                traceback.print_exc(file=sys.stderr)
                code = 1
    finally:
        sys.argv = old_argv
        os.chdir(old_cwd)
        for k, v in old_env.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return subprocess.CompletedProcess(argv, code, out.getvalue(), err.getvalue())


@pytest.fixture
def charctl_main(capsys):
    """Call `charctl.cli.main` in this process with the given arguments (same error handling as the
    console script, without the interpreter start-up); returns a CompletedProcess. An exception that
    escapes main() (a traceback for the user) propagates and fails the test."""

    def _call(*args: str) -> subprocess.CompletedProcess:
        from charctl.cli import main

        old = sys.argv
        sys.argv = ["charctl", *args]
        capsys.readouterr()
        try:
            main()
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        finally:
            sys.argv = old
        out, err = capsys.readouterr()
        return subprocess.CompletedProcess(["charctl", *args], code, out, err)

    return _call


@pytest.fixture(scope="session")
def walk_raw_frames() -> np.ndarray:
    """The raw (T, 44) frame array of the shipped DeepMimic walk clip, read with plain json."""
    from charctl.motion.library import motions_dir

    return np.array(json.loads((motions_dir() / "humanoid3d_walk.txt").read_text())["Frames"], dtype=float)


@pytest.fixture
def write_motion(tmp_path):
    """Write a DeepMimic-style JSON motion file into tmp_path; returns its path."""

    def _write(frames, loop="wrap", name="motion.txt", raw: str | None = None) -> Path:
        path = tmp_path / name
        if raw is not None:
            path.write_text(raw)
        else:
            frames = frames.tolist() if isinstance(frames, np.ndarray) else frames
            path.write_text(json.dumps({"Loop": loop, "Frames": frames}))
        return path

    return _write


@pytest.fixture(scope="session")
def smoke_run(tmp_path_factory):
    """`charctl train NAME scale=smoke` through the installed console script, once per experiment and
    pytest run (tests/test_smoke.py checks every one); returns NAME -> its run directory. Under
    pytest-xdist the workers share one copy: the first to ask trains it under a file lock in the run's
    common temp folder, the others wait for it and read it. Tests only read these runs; those that
    change a run (resume, evaluation files) take a copy with `smoke_run_copy`."""
    from filelock import FileLock

    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base  # xdist: <basetemp>/popen-gwN
    runs: dict[str, Path] = {}

    def get(name: str) -> Path:
        if name not in runs:
            done = shared / f"smoke-{name}.path"  # written only after a successful run
            with FileLock(str(shared / f"smoke-{name}.lock")):
                if not done.exists():
                    root = Path(tempfile.mkdtemp(prefix=f"smoke-{name}-", dir=shared))
                    res = run_charctl("train", name, "scale=smoke", f"output_root={root}", timeout=600)
                    assert res.returncode == 0, res.stdout + res.stderr
                    (run_dir,) = (root / name).iterdir()
                    done.write_text(str(run_dir))
            runs[name] = Path(done.read_text())
        return runs[name]

    return get


@pytest.fixture
def smoke_run_copy(smoke_run, tmp_path):
    """A private copy of the session's smoke run of NAME at tmp_path/NAME/<run>/."""

    def copy(name: str) -> Path:
        import shutil

        src = smoke_run(name)
        return Path(shutil.copytree(src, tmp_path / name / src.name))

    return copy


def snapshot(*roots: Path) -> set[str]:
    """Every file and folder under `roots` (what a failed command must not change)."""
    out: set[str] = set()
    for root in roots:
        if root.exists():
            out |= {str(p) for p in root.rglob("*")}
    return out
