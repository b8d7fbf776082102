"""Config composition, multirun expansion, run directories/checkpoints and the `charctl` CLI.

The CLI is driven as a user drives it: a subprocess of the installed console script, checking
exit codes, stdout, and that every bad input is exactly one `error: ...` line on stderr with no
traceback. Config/train plumbing is exercised through a tiny throw-away experiment ("demo",
registered at run time, its conf/ in a temp folder via CHARCTL_CONF) so these tests do not
depend on any real experiment; the real ones are checked too once their yaml exists.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from charctl.config import BaseConfig
from charctl.errors import CharctlError

from conftest import REPO, assert_one_line, assert_one_line_error, cli_env, run_charctl

# ---------------------------------------------------------------------------- the demo experiment
DEMO_PACKAGE = '''
"""A throw-away experiment for the CLI tests: a config schema and a train() that checkpoints."""
from dataclasses import dataclass, field

from charctl.config import BaseConfig
from charctl.experiments import Experiment


@dataclass
class PPO:
    lr: float = 3e-4
    hidden: list[int] = field(default_factory=lambda: [64, 64])  # schema only (not in the yaml)
    epochs: int = 4


@dataclass
class Config(BaseConfig):
    iterations: int = 3
    clips: list[str] = field(default_factory=lambda: ["walk"])
    ppo: PPO = field(default_factory=PPO)


EXPERIMENT = Experiment(
    name="demo", summary="a throw-away experiment", schema="charctl_demo_experiment:Config",
    train="charctl_demo_experiment:train",
)


def train(cfg, run):
    import torch

    signature = {"hidden": list(cfg.ppo.hidden)}
    done = int(run.load_checkpoint(signature)["iterations_done"]) if run.resumed else 0
    done += cfg.iterations
    run.save_checkpoint({"iterations_done": done, "weights": torch.arange(3.0)}, signature)
    run.write_metrics({"iterations_done": done, "seed": cfg.seed, "lr": cfg.ppo.lr})
    return {"iterations_done": done}
'''

LAUNCHER = """
import sys
import charctl.experiments as registry
registry.EXPERIMENTS["demo"] = "charctl_demo_experiment"
from charctl.cli import main
sys.argv[0] = "charctl"
main()
"""
DEMO_MODULE = "charctl_demo_experiment"


@pytest.fixture(scope="module")
def demo_root(tmp_path_factory) -> Path:
    """A conf/ copy with a 'demo' experiment (experiment yaml + 3 presets) and the demo package."""
    root = tmp_path_factory.mktemp("demo")
    conf = root / "conf"
    conf.mkdir()
    shutil.copy(REPO / "conf" / "config.yaml", conf / "config.yaml")
    shutil.copytree(REPO / "conf" / "scale", conf / "scale")
    (conf / "experiment").mkdir()
    (conf / "experiment" / "demo.yaml").write_text(
        "# @package _global_\nexperiment: demo\niterations: 5\nclips: [walk, run]\nppo:\n  lr: 0.001\n  epochs: 4\n"
    )
    (conf / "preset" / "demo").mkdir(parents=True)
    for scale, iters in [("smoke", 1), ("small", 2), ("paper", 100)]:
        (conf / "preset" / "demo" / f"{scale}.yaml").write_text(f"# @package _global_\niterations: {iters}\n")
    pkg = root / "pkgs" / DEMO_MODULE
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text(DEMO_PACKAGE)
    (root / "charctl_demo.py").write_text(LAUNCHER)
    return root


@pytest.fixture
def demo(demo_root, charctl_main, monkeypatch):
    """`charctl` in this process with the demo experiment registered and its conf/ active."""
    import charctl.experiments as registry

    monkeypatch.setenv("CHARCTL_CONF", str(demo_root / "conf"))
    monkeypatch.syspath_prepend(str(demo_root / "pkgs"))
    monkeypatch.setitem(registry.EXPERIMENTS, "demo", DEMO_MODULE)
    return charctl_main


def demo_subprocess(demo_root: Path, *args: str) -> subprocess.CompletedProcess:
    """The same, as a separate `python` process (what a user's shell sees)."""
    pythonpath = os.pathsep.join(p for p in [str(demo_root / "pkgs"), os.environ.get("PYTHONPATH", "")] if p)
    env = cli_env(CHARCTL_CONF=str(demo_root / "conf"), PYTHONPATH=pythonpath)
    return subprocess.run(
        [sys.executable, str(demo_root / "charctl_demo.py"), *args],
        cwd=demo_root,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


def _ok(res: subprocess.CompletedProcess) -> str:
    out = res.stdout + res.stderr
    assert res.returncode == 0, out
    assert "Traceback" not in out, out
    return res.stdout


# ---------------------------------------------------------------------------- charctl as a user runs it (subprocess)
def test_help_exits_zero():
    out = _ok(run_charctl("--help"))
    for cmd in ("train", "eval", "export", "config", "data", "play"):
        assert cmd in out


def test_cli_import_is_light():
    """`charctl --help` must not pay for torch/mujoco/hydra/pybullet: cli.py imports them lazily."""
    heavy = "('torch','mujoco','hydra','pybullet','omegaconf','scipy')"
    code = f"import sys, charctl.cli; print(sorted(m for m in {heavy} if m in sys.modules))"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=cli_env(), timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[]"


def test_data_list_lists_all_clips():
    from charctl.motion.library import clip_names

    out = _ok(run_charctl("data", "list"))
    names = clip_names()
    assert len(names) == 20
    for n in names:
        assert re.search(rf"(^|\s){re.escape(n)}\s", out), f"{n} missing from `data list`"


def _value(out: str, key: str) -> str:
    m = re.search(rf"{key}[\s│┃|]+(\[[^\]]*\]|[-\d.]+)", out)
    assert m, f"{key} not in output:\n{out}"
    return m.group(1)


def test_data_show_walk(walk_raw_frames):
    out = _ok(run_charctl("data", "show", "walk"))
    raw = walk_raw_frames
    xz = raw[:, [1, 3]]
    travel = np.linalg.norm(xz[-1] - xz[0])
    path = np.linalg.norm(np.diff(xz, axis=0), axis=1).sum()
    duration = raw[:-1, 0].sum()
    assert float(_value(out, "root_travel_m")) == pytest.approx(travel, abs=1.5e-3)
    assert float(_value(out, "mean_speed_m_s")) == pytest.approx(path / duration, abs=1.5e-3)
    assert 0.9 < path / duration < 1.1  # a walk: about 1 m/s
    lo, hi = json.loads(_value(out, "com_height_range_m"))
    from charctl.motion.library import load_clip

    com_y = load_clip("walk").com()[:, 1]
    assert lo == pytest.approx(com_y.min(), abs=1.5e-3) and hi == pytest.approx(com_y.max(), abs=1.5e-3)
    assert 0.8 < lo < hi < 1.0
    assert _value(out, "frames") == str(raw.shape[0])


@pytest.fixture(scope="module")
def bad_motion_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("bad") / "bad.txt"
    path.write_text('{"Loop": "wrap", "Frames": [[0.03, 1, 2, 3]]}')
    return path


@pytest.mark.parametrize(
    "args,words",
    [
        (("data", "show", "wlak"), ["unknown clip", "walk"]),
        (("data", "show", "{bad}"), ["{bad}", "44"]),
        (("train", "nope"), ["unknown experiment", "nope"]),
        (("frobnicate",), ["frobnicate"]),
    ],
    ids=["unknown-clip", "malformed-file", "unknown-experiment", "unknown-command"],
)
def test_cli_errors_subprocess(args, words, bad_motion_file):
    fill = {"bad": str(bad_motion_file)}
    assert_one_line_error(run_charctl(*(a.format(**fill) for a in args)), *(w.format(**fill) for w in words))


@pytest.mark.parametrize(
    "overrides,words",
    [
        (["scale=smoke", "ppo.lrr=1"], ["unknown config key", "ppo.lrr", "lr"]),
        (["scale=huge"], ["huge", "smoke"]),
        (["seed=abc"], ["seed"]),
    ],
    ids=["unknown-key", "unknown-scale", "wrong-type"],
)
def test_config_errors_subprocess(demo_root, overrides, words):
    assert_one_line_error(demo_subprocess(demo_root, "config", "demo", *overrides), *words)


def test_export_bvh_cli(tmp_path, walk_raw_frames):
    from charctl.motion.bvh import read_bvh_as_clip
    from charctl.motion.library import load_clip

    out = tmp_path / "walk.bvh"
    _ok(run_charctl("export", "bvh", "walk", "-o", str(out)))
    back = read_bvh_as_clip(out)
    clip = load_clip("walk")
    assert back.num_frames == clip.num_frames == walk_raw_frames.shape[0]
    np.testing.assert_allclose(back.body_pos, clip.body_pos, atol=1e-4)

    out60 = tmp_path / "walk60.bvh"
    said = _ok(run_charctl("export", "bvh", "walk", "-o", str(out60), "--fps", "60"))
    back60 = read_bvh_as_clip(out60)
    duration = walk_raw_frames[:-1, 0].sum()
    assert back60.num_frames == round(duration * 60) + 1 == 77
    assert "77 frames at 60.00 fps" in said  # the message states what was written
    assert back60.fps == pytest.approx(60.0, rel=0.01)
    assert back60.duration == pytest.approx(duration, rel=1e-6)
    np.testing.assert_allclose(back60.body_pos, clip.resample(60).body_pos, atol=1e-4)


def _real_experiment_with_conf() -> str | None:
    from charctl.experiments import EXPERIMENTS

    for name, module in sorted(EXPERIMENTS.items(), key=lambda kv: kv[0] != "cgail"):
        pkg = REPO / Path(*module.split("."))
        if (REPO / "conf" / "experiment" / f"{name}.yaml").is_file() and (pkg / "__init__.py").is_file():
            return name
    return None


def test_real_experiment_config_errors():
    """`charctl config cgail scale=smoke ppo.lrr=1` (or the first real experiment that exists)."""
    name = _real_experiment_with_conf()
    if name is None:
        pytest.skip("no experiment package with a conf/experiment yaml exists yet")
    assert_one_line_error(run_charctl("config", name, "scale=smoke", "ppo.lrr=1"), "unknown config key", "ppo.lrr")


# ------------------------------------------------------------------ more of the CLI, in process (main() semantics)
@pytest.mark.parametrize("args", [(), ("data",)], ids=["charctl", "charctl-data"])
def test_no_arguments_shows_help_without_traceback(charctl_main, args):
    res = charctl_main(*args)
    assert "Traceback" not in res.stdout + res.stderr
    assert "Usage" in res.stdout + res.stderr


def test_data_show_mirror_and_file(charctl_main, tmp_path):
    from charctl.motion.deepmimic import write_deepmimic
    from charctl.motion.library import load_clip

    assert "kick:mirror" in _ok(charctl_main("data", "show", "kick:mirror"))
    path = tmp_path / "my_clip.txt"
    write_deepmimic(load_clip("run"), path)
    assert _value(_ok(charctl_main("data", "show", str(path))), "frames") == "25"


@pytest.mark.parametrize(
    "args,words",
    [
        (("data", "show", "{missing}"), ["{missing}", "not found"]),
        (("data", "show", "{garbage}"), ["{garbage}", "invalid JSON"]),
        (("data", "show"), []),
        (("train",), []),
        (("config", "nope"), ["nope"]),
        (("eval", "nope", "--dtw"), ["nope"]),
        (("export", "bvh", "walk"), ["-o"]),
        (("export", "bvh"), ["usage"]),
        (("export", "bvh", "wlak", "-o", "{tmp}/x.bvh"), ["unknown clip"]),
        (("export", "bvh", "{missing}", "-o", "{tmp}/x.bvh"), ["not found"]),
        (("export", "bvh", "walk", "-o", "{tmp}/x.bvh", "--fps", "0"), ["fps"]),
        (("export", "bvh", "walk", "-o", "{tmp}/x.bvh", "--fps", "abc"), ["--fps"]),
        (("export", "nope"), ["nope"]),
        (("train", "demo", "--resume", "{tmp}"), ["not a charctl run directory"]),
    ],
    ids=lambda v: " ".join(v) if isinstance(v, tuple) else None,
)
def test_cli_errors_are_one_line(demo, args, words, tmp_path):
    (tmp_path / "garbage.txt").write_text("{{{ not json")
    fill = {"missing": str(tmp_path / "absent.txt"), "garbage": str(tmp_path / "garbage.txt"), "tmp": str(tmp_path)}
    args = tuple(a.format(**fill) for a in args)
    words = [w.format(**fill) for w in words]
    assert_one_line_error(demo(*args), *words)
    assert not (tmp_path / "x.bvh").exists()


@pytest.mark.parametrize(
    "overrides,words",
    [
        (["scale=smoke", "ppo.lrr=1"], ["unknown config key", "ppo.lrr", "valid keys at ppo: lr, hidden, epochs"]),
        (["nonsense=3"], ["unknown config key", "nonsense"]),
        (["scale=huge"], ["huge", "paper, small, smoke"]),
        (["seed=abc"], ["seed"]),
        (["ppo.lr=fast"], ["ppo.lr"]),
        (["ppo.epochs=2.5"], ["ppo.epochs"]),
        (["iterations=[1,2]"], ["iterations"]),
        (["justaword"], ["key=value"]),
        (["experiment=demo"], ["positional"]),
        (["ppo.lr=(("], []),
        (["clips.lrr=1"], ["clips"]),
        (["ppo.lr.x=1"], ["ppo.lr"]),
    ],
    ids=lambda v: " ".join(v) if isinstance(v, list) else None,
)
def test_config_errors_are_one_line(demo, overrides, words):
    assert_one_line_error(demo("config", "demo", *overrides), *words)


# ---------------------------------------------------------------------------- config composition
def _resolved(demo, *overrides):
    from omegaconf import OmegaConf

    return OmegaConf.create(_ok(demo("config", "demo", *overrides)))


def test_config_composition_order(demo):
    cfg = _resolved(demo)  # default scale small: preset small (2) beats experiment yaml (5)
    assert cfg.experiment == "demo" and cfg.scale == "small" and cfg.iterations == 2
    assert (
        cfg.ppo.lr == 0.001 and cfg.ppo.epochs == 4 and list(cfg.ppo.hidden) == [64, 64]
    )  # yaml, then schema defaults
    assert cfg.seed == 0 and cfg.output_root == "outputs"
    assert _resolved(demo, "scale=paper").iterations == 100
    cfg = _resolved(
        demo, "scale=smoke", "iterations=7", "ppo.lr=1e-2", "seed=3", "ppo.epochs=9"
    )  # command line beats preset
    assert cfg.iterations == 7 and cfg.ppo.lr == 0.01 and cfg.seed == 3 and cfg.scale == "smoke" and cfg.ppo.epochs == 9


def test_schema_only_keys_can_be_overridden(demo):
    """A key the schema defines but the experiment yaml does not spell out (ppo.hidden here) is a
    valid key: the override must apply, not fail as 'unknown config key ... valid keys: ..., hidden'."""
    cfg = _resolved(demo, "ppo.hidden=[8,8,8]", "notes=hello")
    assert list(cfg.ppo.hidden) == [8, 8, 8] and cfg.notes == "hello"


@dataclass
class _DemoPPO:
    lr: float = 3e-4
    hidden: list[int] = field(default_factory=lambda: [64, 64])
    epochs: int = 4


@dataclass
class _DemoConfig(BaseConfig):
    iterations: int = 3
    clips: list[str] = field(default_factory=lambda: ["walk"])
    ppo: _DemoPPO = field(default_factory=_DemoPPO)


def test_compose_config_in_process(demo_root, monkeypatch):
    from charctl.config import compose_config, experiment_choices, scale_choices

    Config = _DemoConfig
    monkeypatch.setenv("CHARCTL_CONF", str(demo_root / "conf"))
    assert experiment_choices() == ["demo"] and scale_choices() == ["paper", "small", "smoke"]
    cfg = compose_config("demo", ["scale=smoke", "ppo.epochs=9"], Config)
    assert cfg.iterations == 1 and cfg.ppo.epochs == 9 and cfg.ppo.lr == 0.001
    with pytest.raises(AttributeError):  # struct mode: reading an unknown key fails (omegaconf's ConfigAttributeError)
        _ = cfg.ppo.lrr
    with pytest.raises(CharctlError) as exc:
        compose_config("demo", ["ppo.lrr=1"], Config)
    assert_one_line(exc.value, "ppo.lrr", "valid keys at ppo: lr, hidden, epochs")
    with pytest.raises(CharctlError) as exc:
        compose_config("nope", [], Config)
    assert_one_line(exc.value, "nope", "demo")
    monkeypatch.setenv("CHARCTL_CONF", str(demo_root / "nowhere"))
    with pytest.raises(CharctlError) as exc:
        compose_config("demo", [], Config)
    assert_one_line(exc.value, "CHARCTL_CONF")


def test_expand_multirun():
    from charctl.config import expand_multirun

    jobs = expand_multirun(["a=1,2", "b=x,y", "c=3"])
    assert jobs == [["a=1", "b=x", "c=3"], ["a=1", "b=y", "c=3"], ["a=2", "b=x", "c=3"], ["a=2", "b=y", "c=3"]]
    assert expand_multirun(["a=range(3)"]) == [["a=0"], ["a=1"], ["a=2"]]
    assert expand_multirun(["ppo.lr=1e-4"]) == [["ppo.lr=1e-4"]]
    assert expand_multirun([]) == [[]]
    assert expand_multirun(["+extra=1,2"]) == [["+extra=1"], ["+extra=2"]]
    with pytest.raises(CharctlError) as exc:
        expand_multirun(["a=[1,"])
    assert_one_line(exc.value, "bad override")


# ---------------------------------------------------------------------------- train / resume / multirun through main()
def test_train_multirun_then_resume(demo, tmp_path):
    import torch

    torch.set_num_threads(1)
    out_root = tmp_path / "outputs"
    out = _ok(demo("train", "demo", "scale=smoke", f"output_root={out_root}", "seed=1,2", "-m"))
    assert "[1/2]" in out and "[2/2]" in out
    runs = sorted((out_root / "demo").iterdir())
    assert len(runs) == 2
    seeds = []
    for run in runs:
        assert (run / "config.yaml").is_file() and (run / "checkpoints" / "last.pt").is_file()
        assert sorted(p.name for p in (run / "checkpoints").iterdir()) == ["last.pt"]  # no temp files left
        metrics = json.loads((run / "metrics.json").read_text())
        assert metrics["iterations_done"] == 1
        seeds.append(metrics["seed"])
        payload = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
        assert payload["experiment"] == "demo" and payload["signature"] == {"hidden": [64, 64]}
    assert sorted(seeds) == [1, 2]
    # --resume continues from the checkpoint (1 + 1 iterations)
    out = _ok(demo("train", "demo", "--resume", str(runs[0])))
    assert "resuming" in out and "iterations_done=2" in out
    assert json.loads((runs[0] / "metrics.json").read_text())["iterations_done"] == 2
    # resuming with a different network shape is a one-line error naming the key
    assert_one_line_error(demo("train", "demo", "--resume", str(runs[0]), "ppo.hidden=[32]"), "hidden")
    assert_one_line_error(demo("train", "demo", "--resume", str(runs[0]), "-m"), "multirun")
    # a multirun whose second job is invalid starts nothing
    n_before = len(list((out_root / "demo").iterdir()))
    assert_one_line_error(demo("train", "demo", f"output_root={out_root}", "ppo.lr=0.1,fast", "-m"), "ppo.lr")
    assert len(list((out_root / "demo").iterdir())) == n_before


# ---------------------------------------------------------------------------- checkpoints and runs
@pytest.fixture
def torch_mod():
    torch = pytest.importorskip("torch")
    torch.set_num_threads(1)
    return torch


def _state(torch):
    return {
        "policy": {"w": torch.randn(4, 3, generator=torch.Generator().manual_seed(0)), "b": torch.zeros(3)},
        "iteration": 12,
        "lr": 3e-4,
        "name": "ppo",
        "history": [1.0, 2.5],
        "nested": {"ok": True},
    }


def test_checkpoint_round_trip(tmp_path, torch_mod):
    from charctl.checkpoints import load_checkpoint, save_checkpoint

    torch = torch_mod
    path = tmp_path / "ckpt" / "last.pt"
    state = _state(torch)
    save_checkpoint(path, "cgail", state, {"obs_dim": 197, "hidden": [1024, 512]})
    assert sorted(p.name for p in path.parent.iterdir()) == ["last.pt"]  # the temp file was renamed away
    back = load_checkpoint(path, "cgail", {"obs_dim": 197, "hidden": [1024, 512]})
    assert torch.equal(back["policy"]["w"], state["policy"]["w"]) and torch.equal(
        back["policy"]["b"], state["policy"]["b"]
    )
    assert {k: back[k] for k in ("iteration", "lr", "name", "history", "nested")} == {
        k: state[k] for k in ("iteration", "lr", "name", "history", "nested")
    }
    # the file is plain data: torch's safe loader reads it
    payload = torch.load(path, weights_only=True)
    assert payload["experiment"] == "cgail" and payload["signature"]["obs_dim"] == 197
    # saving again over it keeps one file
    save_checkpoint(path, "cgail", {"iteration": 13})
    assert load_checkpoint(path, "cgail")["iteration"] == 13
    assert sorted(p.name for p in path.parent.iterdir()) == ["last.pt"]


def test_checkpoint_wrong_experiment_or_signature(tmp_path, torch_mod):
    from charctl.checkpoints import load_checkpoint, save_checkpoint

    path = save_checkpoint(tmp_path / "last.pt", "cgail", _state(torch_mod), {"obs_dim": 197, "hidden": [1024, 512]})
    with pytest.raises(CharctlError) as exc:
        load_checkpoint(path, "srb")
    assert_one_line(exc.value, str(path), "cgail", "srb")
    with pytest.raises(CharctlError) as exc:
        load_checkpoint(path, "cgail", {"obs_dim": 197, "hidden": [256, 256]})
    assert_one_line(exc.value, str(path), "hidden")
    with pytest.raises(CharctlError) as exc:
        load_checkpoint(tmp_path / "absent.pt", "cgail")
    assert_one_line(exc.value, "absent.pt", "not found")


def test_checkpoint_needing_unsafe_pickle_is_refused(tmp_path, torch_mod):
    """weights_only loading: a checkpoint holding a numpy array (arbitrary pickled objects) is refused."""
    from charctl.checkpoints import load_checkpoint, save_checkpoint

    path = save_checkpoint(tmp_path / "last.pt", "cgail", {"obs_mean": np.zeros(5)})
    with pytest.raises(CharctlError) as exc:
        load_checkpoint(path, "cgail")
    assert_one_line(exc.value, str(path))


@pytest.mark.parametrize("kind", ["text", "empty", "random", "zip", "tensor", "truncated"])
def test_not_a_checkpoint(tmp_path, torch_mod, kind):
    import zipfile

    from charctl.checkpoints import load_checkpoint, save_checkpoint

    torch = torch_mod
    path = tmp_path / "last.pt"
    if kind == "text":
        path.write_text("hello, I am not a checkpoint\n")
    elif kind == "empty":
        path.write_bytes(b"")
    elif kind == "random":
        path.write_bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    elif kind == "zip":
        with zipfile.ZipFile(path, "w") as z:
            z.writestr("readme.txt", "not torch")
    elif kind == "tensor":  # a valid torch file that is not a charctl checkpoint
        torch.save(torch.zeros(3), path)
    elif kind == "truncated":
        save_checkpoint(path, "cgail", _state(torch))
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CharctlError) as exc:
        load_checkpoint(path, "cgail")
    assert_one_line(exc.value, str(path))


def test_failed_save_keeps_the_previous_checkpoint(tmp_path, torch_mod, monkeypatch):
    from charctl.checkpoints import load_checkpoint, save_checkpoint

    torch = torch_mod
    path = save_checkpoint(tmp_path / "last.pt", "cgail", {"iteration": 1})

    def broken_save(obj, fh, *a, **k):
        fh.write(b"half a checkpoint")
        raise OSError("disk full")

    monkeypatch.setattr(torch, "save", broken_save)
    with pytest.raises(CharctlError) as exc:  # an OS error of the writer is a one-line error naming the file
        save_checkpoint(path, "cgail", {"iteration": 2})
    assert_one_line(exc.value, str(path), "disk full", "previous checkpoint is kept")
    monkeypatch.undo()
    assert load_checkpoint(path, "cgail")["iteration"] == 1
    assert [p.name for p in tmp_path.iterdir()] == ["last.pt"]  # no temp file left


def test_run_directory_life_cycle(tmp_path, torch_mod):
    from omegaconf import OmegaConf

    from charctl.runs import latest_run, new_run, open_run, read_run_config

    cfg = OmegaConf.create({"experiment": "demo", "output_root": str(tmp_path), "seed": 4, "ppo": {"lr": 0.01}})
    with pytest.raises(CharctlError) as exc:
        latest_run(tmp_path, "demo")
    assert_one_line(exc.value, "charctl train demo")
    run_a = new_run(cfg)
    run_b = new_run(cfg)  # same second: a distinct directory
    assert run_a.dir != run_b.dir and run_a.dir.parent == tmp_path / "demo"
    assert read_run_config(run_a.dir).ppo.lr == 0.01
    assert not run_a.has_checkpoint()
    run_a.save_checkpoint({"it": 3}, {"hidden": [8]})
    assert run_a.has_checkpoint() and latest_run(tmp_path, "demo") == run_a.dir  # b has no checkpoint
    assert latest_run(tmp_path, "demo", require_checkpoint=False) == max(run_a.dir, run_b.dir)
    metrics = run_a.write_metrics({"score": np.float32(0.5), "curve": np.arange(3), "n": np.int64(2)})
    assert json.loads(metrics.read_text()) == {"score": 0.5, "curve": [0, 1, 2], "n": 2}
    reopened = open_run(run_a.dir, overrides=["ppo.lr=0.02"])
    assert reopened.resumed and reopened.experiment == "demo" and reopened.cfg.ppo.lr == 0.02
    assert reopened.load_checkpoint({"hidden": [8]})["it"] == 3
    with pytest.raises(CharctlError) as exc:
        reopened.load_checkpoint({"hidden": [16]})
    assert_one_line(exc.value, "hidden")
    leftovers = [p for p in run_a.dir.rglob("*") if ".tmp" in p.name]
    assert leftovers == []
    with pytest.raises(CharctlError) as exc:
        open_run(tmp_path / "nothing-here")
    assert_one_line(exc.value, "not a charctl run directory")
    (run_b.dir / "config.yaml").write_text("a: [unclosed\n")
    with pytest.raises(CharctlError) as exc:
        read_run_config(run_b.dir)
    assert_one_line(exc.value, "config.yaml")
