"""The offline GPU node's side of docs/gpu.md: take the bundle's parts in, install, measure, report.

    python3 scripts/node_run.py receive              # every transfer call: check the part that came, keep it
    python3 scripts/node_run.py run [--budget 540]   # the last call: assemble, install, measure, report

Run with the node's own python3 (Python 3.12, its CUDA torch); nothing is fetched. `receive` checks each
part of .node/parts/ against manifest.json (size, sha256) and moves it to .node/recv/, where the next
calls (sent within the node's 30-s keep window) find it. `run`, inside --budget seconds (one device
command may take 600):

1. joins .node/recv/part-* (sha256 of each part and of the whole) and unpacks the tar.xz to .node/stage/;
2. makes .node/venv with --system-site-packages. The node's python3 is itself a virtual environment
   (/opt/torch/.venv), whose packages --system-site-packages does not show (it shows the base
   interpreter's), so a .pth file adds this interpreter's site-packages (torch and the rest, their own
   .pth files processed) and the repository (charctl, no build step); bin/charctl is its console script;
3. pip-installs the bundle's wheels offline (--no-index --find-links; what the node has is not installed
   again) and re-checks every requirement of the bundle against what is now installed;
4. in the venv, scripts/gpu_check.py's steps, each time-boxed: the GPU parity tests (Warp vs C MuJoCo;
   the smoke training test is left to step 3 of this list), scripts/bench_gpu.py at 4,096 / 1,024 / 8,192
   envs (4,096 first: the target's size), then `charctl train cgail scale=paper env.backend=warp
   device=cuda` for the time left, read back from TensorBoard;
5. writes report.md, node.json, bench.json, scalars.json and logs.tar.gz to --out ($OUT when set, else
   outputs/gpu-node) after every step, so a command stopped at its limit still returns what it measured.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import os
import platform
import shutil
import subprocess
import sys
import tarfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
NODE = REPO / ".node"
PARTS, RECV, STAGE, VENV, WORK = (NODE / n for n in ("parts", "recv", "stage", "venv", "work"))
MiB = 1 << 20
BENCH_ENVS = (4096, 1024, 8192)
PTH_NAME = "_charctl_node.pth"
# seconds kept back, from the budget, for what comes after a step (the smallest useful bench and run)
BENCH_MIN_S, TRAIN_MIN_S, TAIL_S, STOP_S = 120, 120, 25, 60


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(MiB):
            h.update(block)
    return h.hexdigest()


def _out_dir(arg: Path | None) -> Path:
    out = arg or (Path(os.environ["OUT"]) if os.environ.get("OUT") else REPO / "outputs" / "gpu-node")
    out.mkdir(parents=True, exist_ok=True)
    return out


# ----------------------------------------------------------------------------------------- receive
def probe(out: Path) -> dict:
    """This interpreter and its packages against scripts/node_packages.txt (what the bundle was resolved for)."""
    sys.path.insert(0, str(REPO / "scripts"))
    import node_bundle as nb

    listed, real = nb.load_node_packages(), nb.installed_target()
    info = {
        "python": platform.python_version(),
        "listed_python": listed.python,
        "machine": platform.machine(),
        "libc": " ".join(platform.libc_ver()),
        "listed_but_absent": sorted(n for n in listed.packages if n not in real.packages),
        "other_version": {
            n: [v, real.packages[n]]
            for n, v in listed.packages.items()
            if v and n in real.packages and real.packages[n] != v
        },
        "packages": real.packages,
    }
    (out / "probe.json").write_text(json.dumps(info, indent=1))
    return info


def receive(parts: Path = PARTS, recv: Path = RECV) -> dict:
    """Move every part that came (and checks out) from parts/ to recv/; say which are still to come."""
    recv.mkdir(parents=True, exist_ok=True)
    src_manifest = parts / "manifest.json"
    if src_manifest.is_file():
        manifest = json.loads(src_manifest.read_text())
        old = recv / "manifest.json"
        if old.is_file() and json.loads(old.read_text())["archive"]["sha256"] != manifest["archive"]["sha256"]:
            for stale in recv.glob("part-*"):  # parts of another bundle
                stale.unlink()
        shutil.copyfile(src_manifest, recv / "manifest.json")
    elif (recv / "manifest.json").is_file():
        manifest = json.loads((recv / "manifest.json").read_text())
    else:
        raise SystemExit("error: no .node/parts/manifest.json: carry it in every call (docs/gpu.md)")
    bad = []
    for p in manifest["parts"]:
        src, dst = parts / p["name"], recv / p["name"]
        if not src.is_file():
            continue
        if src.stat().st_size == p["bytes"] and _sha256(src) == p["sha256"]:
            os.replace(src, dst)
        else:
            bad.append(p["name"])
    have = [p["name"] for p in manifest["parts"] if (recv / p["name"]).is_file() and p["name"] not in bad]
    todo = [p["name"] for p in manifest["parts"] if p["name"] not in have]
    return {"have": have, "todo": todo, "bad": bad, "bytes": sum(p["bytes"] for p in manifest["parts"])}


class _Joined(io.RawIOBase):
    """The parts read one after the other as one stream, hashed on the way."""

    def __init__(self, paths: list[Path]):
        self.paths, self.f, self.sha = list(paths), None, hashlib.sha256()

    def readable(self) -> bool:
        return True

    def readinto(self, buf) -> int:
        while True:
            if self.f is None:
                if not self.paths:
                    return 0
                self.f = open(self.paths.pop(0), "rb")  # noqa: SIM115 - closed when exhausted
            n = self.f.readinto(buf)
            if n:
                self.sha.update(memoryview(buf)[:n])
                return n
            self.f.close()
            self.f = None


def assemble(recv: Path = RECV, stage: Path = STAGE) -> dict:
    """Join and unpack the parts into stage/ (skipped when stage/ already holds this archive)."""
    manifest = json.loads((recv / "manifest.json").read_text())
    digest = manifest["archive"]["sha256"]
    done = stage / ".archive-sha256"
    if done.is_file() and done.read_text() == digest:
        return manifest
    missing = [p["name"] for p in manifest["parts"] if not (recv / p["name"]).is_file()]
    if missing:
        raise SystemExit(f"error: parts not received yet: {', '.join(missing)} (each call: node_run.py receive)")
    shutil.rmtree(stage, ignore_errors=True)
    stage.mkdir(parents=True)
    stream = _Joined([recv / p["name"] for p in manifest["parts"]])
    with tarfile.open(fileobj=io.BufferedReader(stream, MiB), mode="r|xz") as tf:
        if hasattr(tarfile, "data_filter"):
            tf.extractall(stage, filter="data")
        else:  # pragma: no cover - Python < 3.11.4
            tf.extractall(stage)
    while stream.readinto(bytearray(MiB)):  # the tar end may leave padding unread: hash all of it
        pass
    if stream.sha.hexdigest() != digest:
        raise SystemExit("error: the joined parts do not match the manifest's sha256")
    done.write_text(digest)
    return manifest


# ---------------------------------------------------------------------------------------- the venv
def site_dirs(python: str = sys.executable) -> list[str]:
    code = "import site, json; print(json.dumps(site.getsitepackages()))"
    return json.loads(subprocess.run([python, "-c", code], capture_output=True, text=True, check=True).stdout)


def make_venv(venv: Path = VENV, python: str = sys.executable, repo: Path = REPO) -> Path:
    """A venv that sees `python`'s own packages (also when `python` is itself a venv) and the repository."""
    py = venv / "bin" / "python"
    if not py.exists():
        subprocess.run([python, "-m", "venv", "--system-site-packages", "--without-pip", str(venv)], check=True)
    purelib = subprocess.run(
        [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    lines = [str(repo)] + [f"import site; site.addsitedir({d!r})" for d in site_dirs(python)]
    (Path(purelib) / PTH_NAME).write_text("\n".join(lines) + "\n")
    script = venv / "bin" / "charctl"
    script.write_text(f"#!{py}\nimport sys\n\nfrom charctl.cli import main\n\nsys.exit(main())\n")
    script.chmod(0o755)
    return py


def pip_install(py: Path, wheel_dir: Path, pins: list[str], log: Path) -> int:
    """Offline install of `pins` from wheel_dir; the venv's pip is the node's own (seen through the .pth)."""
    cmd = [str(py), "-m", "pip", "install", "--no-index", "--find-links", str(wheel_dir), "--no-cache-dir"]
    cmd += ["--no-compile", "--disable-pip-version-check", "--progress-bar", "off", *pins]
    env = {**os.environ, "PIP_CONFIG_FILE": os.devnull}  # the node's pip settings (an index, constraints) aside
    with open(log, "a") as fh:
        fh.write("$ " + " ".join(cmd) + "\n")
        fh.flush()
        return subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT, env=env).returncode


# ------------------------------------------------------------------------------------------- run
def run(args: argparse.Namespace) -> int:
    t0 = time.time()
    deadline = t0 + args.budget
    out = _out_dir(args.out)
    WORK.mkdir(parents=True, exist_ok=True)
    log = WORK / "install.log"
    log.write_text("")
    state: dict = {"started": time.strftime("%Y-%m-%d %H:%M:%S"), "steps": {}}
    got = receive()
    state["parts"] = got
    manifest = assemble()
    state["steps"]["assemble_s"] = round(time.time() - t0, 1)
    py = make_venv()
    t1 = time.time()
    rc = pip_install(py, STAGE / "wheels", manifest["install"], log)
    state["steps"]["install_s"] = round(time.time() - t1, 1)
    state["install_rc"] = rc
    state["install"] = manifest["install"]
    (WORK / "state.json").write_text(json.dumps(state, indent=1))
    if rc != 0:
        print(log.read_text()[-3000:])
        print(f"error: pip install failed (exit {rc}); see {log}", file=sys.stderr)
    cmd = [str(py), str(Path(__file__).resolve()), "measure", "--deadline", str(deadline), "--out", str(out)]
    cmd += ["--minutes", str(args.minutes)]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.run(cmd, env=env).returncode


def _left(deadline: float) -> float:
    return deadline - time.time()


def _environment() -> dict:
    import importlib.metadata as md

    import torch

    info = {
        "python": platform.python_version(),
        "executable": sys.executable,
        "torch": torch.__version__,
        "torch_cuda": torch.version.cuda,
        "cuda_available": torch.cuda.is_available(),
        "gpu": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
    }
    for pkg in ("mujoco", "mujoco-warp", "warp-lang", "hydra-core", "omegaconf", "dtw-python", "numpy"):
        try:
            info[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            info[pkg] = None
    try:
        info["nvidia_smi"] = subprocess.run(
            ["nvidia-smi", "--query-gpu=name,driver_version,memory.total,clocks.max.sm", "--format=csv,noheader"],
            capture_output=True,
            text=True,
            timeout=20,
        ).stdout.strip()
    except (OSError, subprocess.TimeoutExpired):
        info["nvidia_smi"] = None
    return info


def live_check(pins: list[str]) -> list[str]:
    """The bundle's pins and everything they require, followed through the METADATA of what this interpreter
    has installed (node_bundle's closure, the installed distributions standing in for wheels)."""
    import importlib.metadata as md

    sys.path.insert(0, str(REPO / "scripts"))
    import node_bundle as nb

    installed: dict = {}
    for dist in md.distributions():
        if dist.metadata["Name"]:
            installed.setdefault(nb.canonicalize_name(dist.metadata["Name"]), nb.dist_metadata(dist))
    c = nb.closure(pins, installed, nb.Target(python=platform.python_version()))
    head = f"{len(c.bundled)} installed distributions reached from the bundle's {len(pins)} pins: " + (
        "all requirements met" if not (c.missing or c.conflicts) else "NOT all met"
    )
    return [head, "  reached: " + ", ".join(c.pins())] + [x for x in c.lines() if "missing" in x or "conflict" in x]


def _scalars(run_dir: str | None) -> dict:
    if not run_dir:
        return {}
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(Path(run_dir) / "tb"), size_guidance={"scalars": 0})
    acc.Reload()
    return {t: [[e.step, e.value, e.wall_time] for e in acc.Scalars(t)] for t in acc.Tags().get("scalars", [])}


def _curve_lines(scalars: dict) -> list[str]:
    ep, rs = scalars.get("train/episode_length", []), dict((s, v) for s, v, _ in scalars.get("train/r_style", []))
    if not ep:
        return []
    idx = sorted({round(i * (len(ep) - 1) / 7) for i in range(8)})
    lines = ["", "Learning curve (train/episode_length, train/r_style by samples):", ""]
    lines += ["| samples | episode length | r_S |", "|---:|---:|---:|"]
    for i in idx:
        s, v, _ = ep[i]
        r = rs.get(s)
        lines.append(f"| {s:,} | {v:.1f} | {'n/a' if r is None else f'{r:.3f}'} |")
    return lines


def _targets(ben: dict, tr: dict) -> list[str]:
    lines = ["", "## Targets (issue 28)", ""]
    runs = {r["num_envs"]: r for r in (ben.get("figures") or {}).get("runs", [])}
    r = runs.get(4096)
    if r:
        loop = r["loop_samples_per_s"]
        verdict = "met" if loop >= 150_000 else "NOT met"
        lines.append(f"- whole loop at 4,096 envs: {loop:,.0f} samples/s (>= 150,000: {verdict})")
        lines.append(
            f"- 1.5e8 samples at that rate: {r['paper_run_minutes']:.1f} min (<= 20: "
            f"{'met' if r['paper_run_minutes'] <= 20 else 'NOT met'})"
        )
    else:
        lines.append("- 4,096 envs: not measured")
    for n, r in sorted(runs.items()):
        ph = ", ".join(f"{k} {100 * v:.0f} %" for k, v in r["phase_fractions"].items())
        lines.append(f"- {n:,} envs, time per phase of the loop: {ph}; rollout/raw {r['rollout_over_raw']:.2f}")
    if tr.get("paper_run_minutes"):
        lines.append(f"- the paper run's own rate: 1.5e8 samples in {tr['paper_run_minutes']:.1f} min")
    lines.append(
        "- learning per sample vs the CPU run: compare scalars.json's train/episode_length and train/r_style by "
        "step with a CPU run of the same config (not run on the node)"
    )
    return lines


def write_outputs(out: Path, state: dict, par: dict, ben: dict, tr: dict, minutes: float, work: Path = WORK) -> None:
    """report.md (node section + gpu_check's report + targets), node.json, bench.json, scalars.json, logs.tar.gz."""
    if str(REPO / "scripts") not in sys.path:
        sys.path.insert(0, str(REPO / "scripts"))
    import gpu_check as G

    full = work / "gpu-check"
    env = state.get("environment", {})
    G.report(full, env.get("gpu") or "?", par, ben, tr, minutes, time.time() - state["t0"])
    gpu_report = (full / "report.md").read_text()
    steps = ", ".join(f"{k} {v}" for k, v in state["steps"].items())
    lines = [
        "# GPU node run (scripts/node_run.py)",
        "",
        f"- node: {env.get('nvidia_smi')}; Python {env.get('python')}; torch {env.get('torch')} (CUDA "
        f"{env.get('torch_cuda')}); mujoco {env.get('mujoco')}, mujoco-warp {env.get('mujoco-warp')}, "
        f"warp {env.get('warp-lang')}, numpy {env.get('numpy')}",
        f"- bundle: {len(state['parts']['have'])} parts, {state['parts']['bytes'] / MiB:.1f} MiB; pip install exit "
        f"{state.get('install_rc')}; step times (s): {steps}",
        "- requirements re-checked on the node: " + (state.get("live_check") or ["not run"])[0],
        *(["- **torch sees no CUDA device: nothing was measured**"] if env.get("cuda_available") is False else []),
        "",
        gpu_report.replace("# GPU check (make gpu-check)\n", "", 1),
    ]
    scalars = _scalars(tr.get("run_dir"))
    lines += _curve_lines(scalars) + _targets(ben, tr)
    (out / "report.md").write_text("\n".join(lines) + "\n")
    node = {**state, "parity": par, "bench_rc": ben.get("rc"), "train": tr}
    (out / "node.json").write_text(json.dumps(node, indent=1))
    if ben.get("figures"):
        (out / "bench.json").write_text(json.dumps(ben["figures"], indent=1))
    if scalars:
        (out / "scalars.json").write_text(json.dumps(scalars))
    logs = [work / "install.log", *sorted(full.glob("*.log"))]
    if tr.get("run_dir"):
        rd = Path(tr["run_dir"])
        logs += [p for p in rd.rglob("*") if p.is_file() and "checkpoints" not in p.parts]
    with tarfile.open(out / "logs.tar.gz", "w:gz") as tf:
        for p in logs:
            if p.is_file():
                arc = p.relative_to(REPO) if p.is_relative_to(REPO) else p.name
                if p.stat().st_size > 4 * MiB:  # a log's tail is what matters; keep the file small enough to return
                    data = p.read_bytes()[-4 * MiB :]
                    ti = tarfile.TarInfo(str(arc))
                    ti.size = len(data)
                    tf.addfile(ti, io.BytesIO(data))
                else:
                    tf.add(p, arcname=str(arc))


def measure(args: argparse.Namespace) -> int:
    """Under the venv: the steps of scripts/gpu_check.py, each given what the deadline leaves."""
    sys.path.insert(0, str(REPO / "scripts"))
    import gpu_check as G

    os.environ.setdefault("CHARCTL_CLIP_DIR", str(STAGE / "clips"))
    os.environ.setdefault("MUJOCO_GL", "disable")  # nothing is rendered; the node's GL stack is not needed
    state = json.loads((WORK / "state.json").read_text())
    state["t0"] = time.time()
    deadline, out = args.deadline, Path(args.out)
    full = WORK / "gpu-check"
    shutil.rmtree(full, ignore_errors=True)
    full.mkdir(parents=True)
    not_run = {"rc": "not run", "summary": "not run", "errors": "n/a", "figures": None, "tail": ""}
    par, ben, tr = dict(not_run), dict(not_run), dict(not_run)
    state["environment"] = _environment()
    state["live_check"] = live_check(state["install"])
    print("\n".join(state["live_check"]))
    write_outputs(out, state, par, ben, tr, 0)
    if not state["environment"]["cuda_available"]:
        print("error: torch sees no CUDA device", file=sys.stderr)
        return 1
    t = time.time()
    timeout = max(30, min(300, _left(deadline) - BENCH_MIN_S - TRAIN_MIN_S - TAIL_S))
    par = G.parity(full, timeout=timeout, pytest_args=("-m", "not slow"))
    state["steps"]["parity_s"] = round(time.time() - t, 1)
    write_outputs(out, state, par, ben, tr, 0)
    t = time.time()
    ben = G.bench(full, list(args.envs), timeout=max(30, min(360, _left(deadline) - TRAIN_MIN_S - TAIL_S)))
    state["steps"]["bench_s"] = round(time.time() - t, 1)
    write_outputs(out, state, par, ben, tr, 0)
    minutes = min(args.minutes, (_left(deadline) - TAIL_S - STOP_S) / 60)
    if minutes >= 0.5:
        t = time.time()
        tr = G.training(full, minutes, stop_timeout=STOP_S)
        state["steps"]["train_s"] = round(time.time() - t, 1)
    else:
        tr = {"rc": "not run", "tail": f"no time left for the training run ({_left(deadline):.0f} s)"}
    write_outputs(out, state, par, ben, tr, max(minutes, 0))
    print((out / "report.md").read_text())
    ok = par["rc"] == 0 and ben["rc"] == 0 and "run_dir" in tr and tr["rc"] in (0, 130)
    return 0 if ok else 1


def _print_probe() -> None:
    try:
        info = probe(_out_dir(None))
    except Exception as exc:  # noqa: BLE001 - the probe only reports: never a reason to fail a transfer call
        print(f"probe failed: {exc!r}")
        return
    absent = info["listed_but_absent"]
    more = f" and {len(absent) - 15} more" if len(absent) > 15 else ""
    print(f"python {info['python']} (listed {info['listed_python']}); listed but absent: {absent[:15]}{more}")
    print(f"other versions than listed: {info['other_version']}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    sub.add_parser("receive", help="check and keep the part(s) this call carried")
    r = sub.add_parser("run", help="assemble, install, measure (one device command)")
    r.add_argument("--budget", type=float, default=540, help="seconds for all of it (a device command: <= 600)")
    r.add_argument("--minutes", type=float, default=10, help="at most this long a training run")
    r.add_argument("--out", type=Path, default=None, help="default: $OUT, else outputs/gpu-node")
    m = sub.add_parser("measure", help=argparse.SUPPRESS)
    m.add_argument("--deadline", type=float, required=True)
    m.add_argument("--out", required=True)
    m.add_argument("--minutes", type=float, default=10)
    m.add_argument("--envs", type=int, nargs="+", default=list(BENCH_ENVS))
    a = ap.parse_args()
    if a.cmd == "receive":
        got = receive()
        print(f"parts: {len(got['have'])} of {len(got['have']) + len(got['todo'])} received", end="")
        print(f"; to come: {', '.join(got['todo'])}" if got["todo"] else "; all here: run `node_run.py run`")
        if os.environ.get("OUT"):  # a device call: also say how the node differs from the list the bundle assumed
            _print_probe()
        if got["bad"]:
            sys.exit(f"error: {', '.join(got['bad'])} did not match the manifest (size or sha256): send again")
        return
    if a.cmd == "run":
        sys.exit(run(a))
    sys.exit(measure(a))


if __name__ == "__main__":
    main()
