"""The offline GPU node's bundle (scripts/node_bundle.py, scripts/node_run.py; docs/gpu.md), checked here without
a network or a GPU:

- the dependency closure on hand-built METADATA (markers for CPython 3.12, extras, the node's versions,
  conflicts, shadowing) and the wheel-file checks (tags, Requires-Python, two versions of one package);
- a synthetic bundle packed, split for a small transfer limit, received part by part and unpacked
  bit-identical; every planned call within the limit, also for the real tracked tree and the measured
  archive size;
- charctl reading clips and URDF from CHARCTL_CLIP_DIR, and one-line errors without it;
- charctl importing (config, clips, the warp path) in a subprocess that can import only the node's
  packages and the bundle's, with pybullet absent;
- the node's venv: made from a venv (as the node's python3 is), it still sees that venv's packages and
  the repository, and pip installs offline against them.
"""

from __future__ import annotations

import importlib.metadata as md
import json
import os
import shutil
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import pytest

from conftest import REPO, assert_one_line, load_script

MiB = 1 << 20


_load = load_script


nb = _load("node_bundle")
nr = _load("node_run")
# the closure and import checks read this machine's installed copies of the bundle's packages
needs_roots = pytest.mark.skipif(
    any(nb.local_version(n) is None for n in nb.ROOTS), reason="the bundle's packages are not all installed here"
)


def _meta(name: str, version: str, *requires: str, python: str | None = None) -> str:
    lines = ["Metadata-Version: 2.1", f"Name: {name}", f"Version: {version}"]
    lines += [f"Requires-Python: {python}"] if python else []
    return "\n".join(lines + [f"Requires-Dist: {r}" for r in requires]) + "\n\nlong description\n"


WHEELS = {
    "alpha": _meta(
        "Alpha",
        "1.0",
        "beta>=2",
        "gamma[fast]",
        "numpy>=2.0",
        'oldlib; python_version < "3.11"',
        'docs-only; extra == "docs"',
    ),
    "beta": _meta("beta", "2.1", "typing_extensions>=4", 'winlib; sys_platform == "win32"'),
    "gamma": _meta("Gamma", "0.3", 'zeta; extra == "fast"', 'eta; extra == "slow"'),
    "zeta": _meta("zeta", "1.0", "etils[epath]"),
}
ETILS = _meta("etils", "1.15", 'fsspec; extra == "epath"', 'lostpkg; extra == "epath"', 'gcsfs; extra == "epath-gcs"')


def _target(**packages) -> object:
    return nb.Target(python="3.12.3", packages={nb.canonicalize_name(k): v for k, v in packages.items()})


def _wheels(**override) -> dict:
    return {n: nb.parse_metadata(t, file=f"{n}.whl") for n, t in {**WHEELS, **override}.items()}


def test_closure_follows_metadata_markers_and_extras():
    target = _target(numpy="2.5.2", typing_extensions=None, etils=None, fsspec=None)
    c = nb.closure(["alpha==1.0", 'py310only; python_version < "3.11"'], _wheels(), target, proxy=lambda n: None)
    assert sorted(c.bundled) == ["alpha", "beta", "gamma", "zeta"]
    assert sorted(c.on_node) == ["etils", "numpy", "typing-extensions"]
    assert not c.missing and not c.conflicts and not c.problems and c.ok
    # typing_extensions>=4 is met by name only; the extras of the node's etils could not be read
    assert any("typing_extensions>=4" in u for u in c.unverified)
    assert any("extras of the node's etils" in u for u in c.unverified)
    assert c.pins() == ["alpha==1.0", "beta==2.1", "gamma==0.3", "zeta==1.0"]

    # with the node's etils METADATA, its extra `epath` pulls fsspec (on the node) and lostpkg (nowhere)
    c = nb.closure(["alpha"], _wheels(), target, proxy=lambda n: nb.parse_metadata(ETILS) if n == "etils" else None)
    assert [(str(r), by) for r, by in c.missing] == [('lostpkg; extra == "epath"', "etils[epath]")]
    assert "fsspec" in c.on_node and not c.ok
    lines = "\n".join(c.lines())
    assert "INCOMPLETE" in lines and "missing: lostpkg" in lines and "gcsfs" not in lines


def test_closure_conflicts_and_shadowing():
    # the node's known numpy is too old, and no wheel of it: a conflict
    c = nb.closure(["alpha"], _wheels(), _target(numpy="1.26.4", typing_extensions="4.12", etils=None))
    assert any("numpy>=2.0" in x and "the node has numpy 1.26.4" in x for x in c.conflicts) and not c.ok
    # a numpy wheel in the bundle shadows the node's old one (said in a note, not an error)
    numpy2 = _meta("numpy", "2.1.0")
    c = nb.closure(["alpha"], _wheels(numpy=numpy2), _target(numpy="1.26.4", typing_extensions="4.12", etils=None))
    assert "numpy" in c.bundled and not c.conflicts and any("shadows" in n for n in c.notes)
    # a bundled wheel at a version the requirement excludes
    c = nb.closure(["beta>=3"], _wheels(), _target(typing_extensions="4.12"))
    assert c.conflicts == ["beta>=3 (required by the roots): the bundled wheel is beta 2.1"]
    # a wheel nobody reaches is reported as unused, not bundled
    c = nb.closure(["beta"], _wheels(), _target(typing_extensions="4.12"))
    assert sorted(c.bundled) == ["beta"] and c.unused == ["alpha.whl", "gamma.whl", "zeta.whl"]


def _wheel(dir_: Path, filename: str, metadata: str) -> Path:
    name, version = filename.split("-")[:2]
    path = dir_ / filename
    info = f"{name}-{version}.dist-info"
    files = {
        f"{name}/__init__.py": "VALUE = 1\n" * 200,
        f"{info}/METADATA": metadata,
        f"{info}/WHEEL": "Wheel-Version: 1.0\nGenerator: test\nRoot-Is-Purelib: true\nTag: py3-none-any\n",
    }
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for arc, text in files.items():
            z.writestr(arc, text)
        z.writestr(f"{info}/RECORD", "".join(f"{arc},,\n" for arc in [*files, f"{info}/RECORD"]))
    return path


def test_check_wheels_tags_python_and_duplicates(tmp_path):
    ok = [
        _wheel(tmp_path, "pure-1.0-py3-none-any.whl", _meta("pure", "1.0")),
        _wheel(tmp_path, "ext-1.0-cp312-cp312-manylinux_2_17_x86_64.manylinux2014_x86_64.whl", _meta("ext", "1.0")),
        _wheel(tmp_path, "stable-1.0-cp38-abi3-manylinux_2_28_x86_64.whl", _meta("stable", "1.0")),
    ]
    wheels, problems = nb.check_wheels(ok, _target())
    assert sorted(wheels) == ["ext", "pure", "stable"] and problems == []
    bad = [
        _wheel(tmp_path, "old-1.0-cp311-cp311-manylinux_2_28_x86_64.whl", _meta("old", "1.0")),
        _wheel(tmp_path, "newglibc-1.0-cp312-cp312-manylinux_2_34_x86_64.whl", _meta("newglibc", "1.0")),
        _wheel(tmp_path, "arm-1.0-cp312-cp312-manylinux_2_28_aarch64.whl", _meta("arm", "1.0")),
        _wheel(tmp_path, "strict-1.0-py3-none-any.whl", _meta("strict", "1.0", python="<3.12")),
        _wheel(tmp_path, "pure-1.1-py3-none-any.whl", _meta("pure", "1.1")),
    ]
    _, problems = nb.check_wheels(ok + bad, _target())
    text = "\n".join(problems)
    for name in ("old-1.0", "newglibc-1.0", "arm-1.0"):
        assert f"{name}-" in text and "none of its tags installs on CPython 3.12" in text
    assert "Requires-Python <3.12 excludes 3.12.3" in text
    assert "two versions of pure" in text
    assert len(problems) == 5


def test_node_package_list():
    t = nb.load_node_packages()
    assert t.python == "3.12.3" and t.packages["torch"] == "2.11.0" and t.packages["numpy"] == "2.5.2"
    for absent in ("mujoco", "mujoco-warp", "warp-lang", "hydra-core", "omegaconf", "dtw-python", "pybullet"):
        assert absent not in t.packages
    for present in ("tensorboard", "typer", "rich", "onnx", "onnxruntime", "matplotlib", "pyyaml", "pytest", "numba"):
        assert present in t.packages


def _local_bundle(target) -> object:
    """The closure of ROOTS with this machine's installed METADATA standing in for the wheels (no download)."""
    wheels = {}
    for dist in md.distributions():
        name = nb.canonicalize_name(dist.metadata["Name"] or "")
        if name and name not in target.packages and name not in wheels:
            wheels[name] = nb.dist_metadata(dist)
    return nb.closure(nb.default_roots(), wheels, target, proxy=nb.local_metadata)


@needs_roots
def test_the_roots_close_over_the_node_list():
    c = _local_bundle(nb.load_node_packages())
    assert c.ok, "\n".join(c.lines())
    assert set(nb.ROOTS) <= set(c.bundled)
    assert "torch" not in c.bundled and "numpy" not in c.bundled  # the node's own stay the node's


# ------------------------------------------------------------------------------- transfers
def _synthetic_stage(root: Path) -> Path:
    stage = root / "stage"
    (stage / "wheels").mkdir(parents=True)
    deflated = _wheel(root, "blob-1.0-py3-none-any.whl", _meta("blob", "1.0"))
    with zipfile.ZipFile(deflated, "a") as z:
        z.writestr("blob/data.bin", os.urandom(700_000))  # incompressible: the archive needs several parts
    nb.repack_stored(deflated, stage / "wheels" / deflated.name)
    with zipfile.ZipFile(stage / "wheels" / deflated.name) as z:
        assert {i.compress_type for i in z.infolist()} == {zipfile.ZIP_STORED}
        assert z.read("blob/__init__.py") == b"VALUE = 1\n" * 200
    (stage / "clips" / "humanoid").mkdir(parents=True)
    (stage / "clips" / "humanoid" / "humanoid.urdf").write_bytes(b"<robot/>\x00")
    return stage


def test_synthetic_bundle_split_received_and_rebuilt(tmp_path):
    stage = _synthetic_stage(tmp_path)
    archive = tmp_path / "bundle.tar.xz"
    nb.make_archive(stage, archive, preset="1", dict_mib=1)  # the filter chain `build` uses, small
    limit, tree = 256 * 1024, 100 * 1024
    size = nb.balanced(archive.stat().st_size, 128 * 1024)  # part_size() gives >= 1 MiB: a small part is set here
    parts_dir = tmp_path / "outgoing"
    parts = nb.split(archive, parts_dir, size)
    assert len(parts) >= 5 and sum(p["bytes"] for p in parts) == archive.stat().st_size
    manifest = {"archive": {"name": archive.name, "sha256": nb.sha256(archive)}, "parts": parts, "install": []}
    text = json.dumps(manifest)
    calls = nb.plan(tree, parts, len(text), limit=limit)
    assert [c["call"] for c in calls] == list(range(1, len(parts) + 1))
    assert all(c["fits"] and c["bytes"] <= limit for c in calls)
    assert "node_run.py run" in calls[-1]["command"] and all("run --budget" not in c["command"] for c in calls[:-1])

    # the calls one by one: each brings the manifest and its part; the last one is corrupted once
    carried, recv = tmp_path / "node" / "parts", tmp_path / "node" / "recv"
    carried.mkdir(parents=True)
    (carried / "manifest.json").write_text(text)
    for i, p in enumerate(parts):
        data = (parts_dir / p["name"]).read_bytes()
        if i == len(parts) - 1:
            (carried / p["name"]).write_bytes(data[:-1] + bytes([data[-1] ^ 1]))
            got = nr.receive(carried, recv)
            assert got["bad"] == [p["name"]] and got["todo"] == [p["name"]]
            with pytest.raises(SystemExit, match="not received yet"):
                nr.assemble(recv, tmp_path / "node" / "stage")
        (carried / p["name"]).write_bytes(data)
        got = nr.receive(carried, recv)
        assert not (carried / p["name"]).exists() and got["have"][-1] == p["name"] and not got["bad"]
    assert got["todo"] == []
    out = tmp_path / "node" / "stage"
    nr.assemble(recv, out)
    for f in stage.rglob("*"):
        if f.is_file():
            assert (out / f.relative_to(stage)).read_bytes() == f.read_bytes(), f
    assert (out / ".archive-sha256").read_text() == manifest["archive"]["sha256"]


def test_part_size_rounds_to_mib_and_refuses_a_tree_that_fills_the_call():
    assert nb.part_size(38 * MiB + 5) == 25 * MiB - (64 << 10)  # 64 - 38.x - 1 (margin), down to whole 64 KiB
    with pytest.raises(SystemExit, match="the working tree alone is 62.5 MiB"):
        nb.part_size(62 * MiB + MiB // 2)
    # the fewest parts, evened out: 110.8 MiB with at most 24 MiB a part -> 5 parts of 22.2 MiB, not 4 + 14.8
    assert nb.balanced(int(110.8 * MiB), 24 * MiB) == -(-int(110.8 * MiB) // 5)
    assert nb.balanced(100, 100) == 100 and nb.balanced(101, 100) == 51


def test_real_tree_and_measured_bundle_fit_the_calls():
    if not (REPO / ".git").exists() or shutil.which("git") is None:
        pytest.skip("not a git checkout")
    out = subprocess.run(["git", "ls-files", "-z", "--cached"], cwd=REPO, capture_output=True, check=True).stdout
    tracked = sum(os.lstat(REPO / r).st_size for r in out.decode().split("\0") if r and os.path.lexists(REPO / r))
    size = nb.balanced(nb.MEASURED_ARCHIVE_BYTES, nb.part_size(tracked))
    n = -(-nb.MEASURED_ARCHIVE_BYTES // size)
    parts = [{"name": f"part-{i}", "bytes": size} for i in range(1, n)]
    parts.append({"name": f"part-{n}", "bytes": nb.MEASURED_ARCHIVE_BYTES - size * (n - 1)})
    calls = nb.plan(tracked, parts, 4096)
    assert all(c["bytes"] <= nb.TRANSFER_LIMIT for c in calls)
    assert len(calls) <= 6, f"the tracked tree ({tracked / MiB:.1f} MiB) leaves {size / MiB:.0f} MiB a call"


# ------------------------------------------------------------------------------- clip folder
def test_clips_read_from_charctl_clip_dir(tmp_path, monkeypatch):
    from charctl.errors import CharctlError
    from charctl.motion import skeleton
    from charctl.motion.library import load_clip

    reference = load_clip("walk")
    files = nb.copy_clips(tmp_path / "clips")
    assert "humanoid/humanoid.urdf" in files and len(files) == 21
    monkeypatch.setenv("CHARCTL_CLIP_DIR", str(tmp_path / "clips"))
    monkeypatch.setitem(sys.modules, "pybullet_data", None)  # as on the node: `import pybullet_data` fails
    assert skeleton.pybullet_data_path() == tmp_path / "clips"
    clip = load_clip("walk")
    assert (clip.root_pos == reference.root_pos).all() and (clip.local_rot == reference.local_rot).all()

    monkeypatch.setenv("CHARCTL_CLIP_DIR", str(tmp_path))
    with pytest.raises(CharctlError) as exc:
        load_clip("walk")
    assert_one_line(exc.value, "CHARCTL_CLIP_DIR=", "humanoid/humanoid.urdf")
    monkeypatch.delenv("CHARCTL_CLIP_DIR")
    with pytest.raises(CharctlError) as exc:
        skeleton.pybullet_data_path()
    assert_one_line(exc.value, "'pybullet' package is not installed", "CHARCTL_CLIP_DIR")


# Imports only what the node has or the bundle brings: every other installed distribution's modules fail.
NODE_IMPORTS = textwrap.dedent(
    """
    import importlib.abc, json, os, sys
    BLOCKED = set(json.loads(os.environ["BLOCKED"]))

    class NotOnTheNode(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in BLOCKED:
                raise ModuleNotFoundError(f"No module named {name!r} (not on the node)", name=name)

    sys.meta_path.insert(0, NotOnTheNode())
    clip_dir = os.environ.pop("CHARCTL_CLIP_DIR")
    from charctl.errors import CharctlError
    from charctl.motion.library import load_clip
    try:
        load_clip("walk")
        raise SystemExit("clips loaded without pybullet and without CHARCTL_CLIP_DIR")
    except CharctlError as exc:
        no_dir = str(exc)
    os.environ["CHARCTL_CLIP_DIR"] = clip_dir
    import charctl.cli
    from charctl.config import compose_config
    from charctl.experiments.cgail.config import Config
    from charctl.experiments.cgail.train import CgailLearner
    from charctl.sim.humanoid import load_model
    from charctl.sim.warp_batch import resolve_backend
    import mujoco_warp, warp
    cfg = compose_config("cgail", ["scale=paper", "env.backend=warp", "device=cpu"], Config)
    walk = load_clip("kick:mirror")
    model = load_model()
    try:
        import pybullet_data
        pb = "importable"
    except ImportError:
        pb = "absent"
    print(json.dumps({"no_dir": no_dir, "num_envs": cfg.env.num_envs, "backend": resolve_backend("warp", "cpu"),
                      "frames": walk.num_frames, "nbody": model.nbody, "pybullet_data": pb,
                      "blocked_loaded": sorted(BLOCKED & {m.split(".")[0] for m in sys.modules})}))
    """
)


@needs_roots
def test_charctl_imports_with_the_node_package_set(tmp_path):
    target = nb.load_node_packages()
    bundle = _local_bundle(target)
    allowed = set(target.packages) | set(bundle.bundled) | {"charctl"}
    blocked = set()
    for module, dists in md.packages_distributions().items():
        if not any(nb.canonicalize_name(d) in allowed for d in dists):
            blocked.add(module)
    assert {"pybullet_data", "pybullet", "qpsolvers", "deap"} <= blocked
    assert not {"torch", "mujoco", "mujoco_warp", "warp", "hydra", "omegaconf", "numpy", "typer"} & blocked
    nb.copy_clips(tmp_path / "clips")
    env = {**os.environ, "BLOCKED": json.dumps(sorted(blocked)), "CHARCTL_CLIP_DIR": str(tmp_path / "clips")}
    res = subprocess.run([sys.executable, "-c", NODE_IMPORTS], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-3000:]
    got = json.loads(res.stdout.strip().splitlines()[-1])
    assert "CHARCTL_CLIP_DIR" in got["no_dir"] and got["pybullet_data"] == "absent"
    assert got["num_envs"] == 4096 and got["backend"] == "warp" and got["frames"] > 10 and got["nbody"] > 15
    assert got["blocked_loaded"] == []


# ------------------------------------------------------------------------------- the node's venv
def test_venv_from_a_venv_sees_its_packages_and_installs_offline(tmp_path):
    if sys.prefix == sys.base_prefix:
        pytest.skip("the test imitates the node's python3, itself a venv: run it from .venv")
    py = nr.make_venv(tmp_path / "venv", python=sys.executable, repo=REPO)
    code = (
        "import importlib.util as u; print([m for m in ('torch', 'typer', 'charctl', 'pytest') if not u.find_spec(m)])"
    )
    res = subprocess.run([str(py), "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert res.returncode == 0 and res.stdout.strip() == "[]", res.stdout + res.stderr
    res = subprocess.run([str(tmp_path / "venv" / "bin" / "charctl"), "--help"], capture_output=True, text=True)
    assert res.returncode == 0 and "train" in res.stdout, res.stderr[-2000:]
    # a wheel that needs typer (only in the outer venv): pip finds it installed and adds nothing else
    wheels = tmp_path / "wheels"
    wheels.mkdir()
    _wheel(wheels, "tinypkg-1.0-py3-none-any.whl", _meta("tinypkg", "1.0", "typer>=0.9"))
    log = tmp_path / "install.log"
    assert nr.pip_install(py, wheels, ["tinypkg==1.0"], log) == 0, log.read_text()
    text = log.read_text()
    assert "Requirement already satisfied: typer" in text and "Successfully installed tinypkg-1.0" in text
    res = subprocess.run(
        [str(py), "-c", "import tinypkg, typer; print(typer.__file__)"], capture_output=True, text=True
    )
    assert res.returncode == 0 and str(tmp_path) not in res.stdout, res.stdout + res.stderr


# ------------------------------------------------------------------------------- the node's report
def test_node_report_from_synthetic_results(tmp_path):
    """What `node_run.py run` returns, from made-up results: the files the device tool brings back (at most 8,
    plain names), the bench table and the targets, the learning curve read from TensorBoard, no checkpoints."""
    import re
    import tarfile
    import time

    from torch.utils.tensorboard import SummaryWriter

    work = tmp_path / "work"
    full = work / "gpu-check"
    run_dir = full / "runs" / "cgail" / "2026-01-01_00-00-00"
    (run_dir / "checkpoints").mkdir(parents=True)
    (run_dir / "checkpoints" / "last.pt").write_bytes(b"x" * 1000)
    (run_dir / "config.yaml").write_text("seed: 1\n")
    (work / "install.log").write_text("Successfully installed warp-lang-1.19.0\n")
    (full / "parity.log").write_text("12 passed\n")
    writer = SummaryWriter(str(run_dir / "tb"))
    for i in range(10):
        step = (i + 1) * 131_072
        writer.add_scalar("train/episode_length", 10.0 + i, step)
        writer.add_scalar("train/r_style", 0.1 * i, step)
        writer.add_scalar("perf/samples_per_s", 200_000.0, step)
    writer.close()
    fig = {
        "num_envs": 4096,
        "raw_physics_samples_per_s": 400_000.0,
        "rollout_samples_per_s": 300_000.0,
        "loop_samples_per_s": 200_000.0,
        "rollout_over_raw": 0.75,
        "loop_over_raw": 0.5,
        "paper_run_minutes": 12.5,
        "phase_fractions": {"rollout": 0.6, "reward": 0.05, "ppo": 0.3, "disc": 0.05},
    }
    figures = {"environment": {"gpu": "NVIDIA H200", "mujoco": "4.0.0", "mujoco-warp": "4.0.0", "warp-lang": "1.19.0"}}
    figures["runs"] = [fig, {**fig, "num_envs": 1024, "loop_samples_per_s": 90_000.0}]
    par = {"rc": 0, "summary": "12 passed in 80s", "errors": "{1: 3e-07, 10: 9e-06, 30: 4e-05}"}
    ben = {"rc": 0, "figures": figures, "tail": ""}
    tr = {
        "rc": 130,
        "run_dir": str(run_dir),
        "iterations": 10,
        "samples": 1_310_720,
        "episode_length_first": 10.0,
        "episode_length_last": 19.0,
        "r_style_first": 0.0,
        "r_style_last": 0.9,
        "samples_per_s_mean": 200_000.0,
        "paper_run_minutes": 12.5,
        "tail": "",
    }
    state = {
        "t0": time.time(),
        "steps": {"assemble_s": 20.0, "install_s": 8.0},
        "parts": {"have": ["part-1", "part-2"], "todo": [], "bytes": 116_135_088},
        "install_rc": 0,
        "install": ["warp-lang==1.19.0"],
        "live_check": ["21 installed distributions reached from the bundle's 12 pins: all requirements met"],
        "environment": {"gpu": "NVIDIA H200", "python": "3.12.3", "torch": "2.11.0+cu130", "torch_cuda": "13.0"},
    }
    out = tmp_path / "out"
    out.mkdir()
    # an early write (nothing measured yet) must work too
    not_run = {"rc": "not run", "summary": "not run", "errors": "n/a", "figures": None, "tail": ""}
    nr.write_outputs(out, state, dict(not_run), dict(not_run), dict(not_run), 0, work=work)
    assert "not run" in (out / "report.md").read_text()
    nr.write_outputs(out, state, par, ben, tr, 3.0, work=work)
    names = sorted(p.name for p in out.iterdir())
    assert names == ["bench.json", "logs.tar.gz", "node.json", "report.md", "scalars.json"]
    assert all(re.fullmatch(r"[A-Za-z0-9._-]+", n) for n in names) and len(names) <= 8
    report = (out / "report.md").read_text()
    for text in (
        "# GPU node run",
        "all requirements met",
        "| 4,096 | 400,000 | 300,000 | 200,000 |",
        "whole loop at 4,096 envs: 200,000 samples/s (>= 150,000: met)",
        "1.5e8 samples at that rate: 12.5 min (<= 20: met)",
        "| 1,310,720 | 19.0 | 0.900 |",
        "rollout 60 %",
    ):
        assert text in report, text
    assert len(json.loads((out / "scalars.json").read_text())["train/episode_length"]) == 10
    with tarfile.open(out / "logs.tar.gz") as tf:
        members = tf.getnames()
    assert not any("checkpoints" in m for m in members)
    assert any(m.endswith("config.yaml") for m in members) and any("tfevents" in m for m in members)
    assert any(m.endswith("install.log") for m in members) and any(m.endswith("parity.log") for m in members)
