"""The one-command device check of the GPU path (`make gpu-check`), for a machine with an NVIDIA GPU:

    .venv/bin/python scripts/gpu_check.py [--out outputs/gpu-check] [--minutes 10] [--envs 1024 4096 8192]

1. parity: tests/test_gpu_path.py with Warp on the GPU (Warp vs C MuJoCo from RSI frames of walk, run and
   kick after 1/10/30 control steps, blow-up resets, device env vs CPU env, a smoke training run);
2. bench: scripts/bench_gpu.py at 1,024 / 4,096 / 8,192 envs (raw physics, rollout, whole loop);
3. a `--minutes`-long `charctl train cgail scale=paper env.backend=warp device=cuda` run, stopped with
   SIGINT (the runner writes its checkpoint), read back from its TensorBoard scalars;
and writes every figure to <out>/report.md (plus the raw logs next to it). Each step runs even when an
earlier one failed; the exit status is non-zero when any failed.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
PY = sys.executable
CHARCTL = str(Path(PY).parent / "charctl")
PAPER_SAMPLES = 150_000_000


def run(
    cmd: list[str],
    log: Path,
    env: dict | None = None,
    timeout: float | None = None,
    interrupt_after: float | None = None,
) -> tuple[int, str]:
    """Run `cmd` from the repo root, tee its output into `log`; with `interrupt_after` seconds, send
    SIGINT then (the training runner's clean stop) and wait for it to finish its iteration."""
    log.parent.mkdir(parents=True, exist_ok=True)
    print("$", " ".join(cmd), flush=True)
    with open(log, "w") as fh:
        proc = subprocess.Popen(cmd, cwd=REPO, env={**os.environ, **(env or {})}, stdout=fh, stderr=subprocess.STDOUT)
        try:
            if interrupt_after is not None:
                try:
                    proc.wait(timeout=interrupt_after)
                except subprocess.TimeoutExpired:
                    proc.send_signal(signal.SIGINT)
            rc = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            rc = -9
    return rc, log.read_text(errors="replace")


def gpu_name() -> str | None:
    import torch

    return torch.cuda.get_device_name(0) if torch.cuda.is_available() else None


def parity(out: Path, timeout: float = 1800, pytest_args: tuple[str, ...] = ()) -> dict:
    rc, text = run(
        [PY, "-m", "pytest", "-q", "-s", "tests/test_gpu_path.py", *pytest_args],
        out / "parity.log",
        env={"CHARCTL_WARP_TEST_DEVICE": "cuda"},
        timeout=timeout,
    )
    errors = re.search(r"max body position error \(m\) after k control steps: (\{[^}]*\})", text)
    summary = [line for line in text.splitlines() if re.search(r"\d+ (passed|failed|error)", line)]
    return {
        "rc": rc,
        "errors": errors.group(1) if errors else "not printed",
        "summary": summary[-1] if summary else text[-300:],
    }


def bench(out: Path, envs: list[int], timeout: float = 3600) -> dict:
    path = out / "bench.json"
    path.unlink(missing_ok=True)
    rc, text = run(
        [PY, "scripts/bench_gpu.py", "--device", "cuda", "--json", str(path), "--envs", *map(str, envs)],
        out / "bench.log",
        timeout=timeout,
    )
    # bench_gpu.py rewrites the file after each env count: a bench stopped early keeps the counts it finished
    figures = json.loads(path.read_text()) if path.is_file() else None
    if figures is not None and not figures.get("runs"):
        figures = None
    return {"rc": rc, "figures": figures, "tail": text[-2000:]}


def training(out: Path, minutes: float, stop_timeout: float = 900) -> dict:
    """`minutes` of the paper-scale run, then SIGINT; `stop_timeout`: how long it may take to stop after it."""
    runs = out / "runs"
    rc, text = run(
        [CHARCTL, "train", "cgail", "scale=paper", "env.backend=warp", "device=cuda", f"output_root={runs}"],
        out / "train.log",
        interrupt_after=60 * minutes,
        timeout=stop_timeout,
    )
    dirs = sorted((runs / "cgail").glob("*/")) if (runs / "cgail").is_dir() else []
    result: dict = {"rc": rc, "tail": text[-1500:]}
    if not dirs:
        return result
    from charctl.eval.tb import read_scalars

    scalars = read_scalars(dirs[-1] / "tb")
    empty = (np.zeros(0), np.zeros(0))
    (ep_s, ep), (_, rs), (_, sps) = (
        scalars.get(t, empty) for t in ("train/episode_length", "train/r_style", "perf/samples_per_s")
    )
    result.update(
        {
            "run_dir": str(dirs[-1]),
            "iterations": len(ep),
            "samples": int(ep_s[-1]) if len(ep) else 0,
            "episode_length_first": float(ep[0]) if len(ep) else None,
            "episode_length_last": float(ep[-1]) if len(ep) else None,
            "r_style_first": float(rs[0]) if len(rs) else None,
            "r_style_last": float(rs[-1]) if len(rs) else None,
            "samples_per_s_mean": float(np.mean(sps[1:])) if len(sps) > 1 else (float(sps[0]) if len(sps) else None),
        }
    )
    if result["samples_per_s_mean"]:
        result["paper_run_minutes"] = PAPER_SAMPLES / result["samples_per_s_mean"] / 60.0
    return result


def _fmt(v, spec: str = ",.0f") -> str:
    return "n/a" if v is None else format(v, spec)


def report(out: Path, gpu: str, par: dict, ben: dict, tr: dict, minutes: float, wall: float) -> Path:
    import torch

    lines = [
        "# GPU check (make gpu-check)",
        "",
        f"- GPU: {gpu}; torch {torch.__version__}; total wall time {wall / 60:.1f} min",
        "",
        "## 1. Parity: MuJoCo Warp (GPU) vs C MuJoCo",
        "",
        f"- tests: {par['summary']} (exit {par['rc']}; log parity.log)",
        f"- max body position error after {{1, 10, 30}} control steps (m): {par['errors']}",
        "",
        "## 2. Throughput (scripts/bench_gpu.py, scale=paper networks)",
        "",
    ]
    figs = ben.get("figures")
    if figs:
        env = figs["environment"]
        lines += [
            f"- {env.get('gpu', '?')}, mujoco {env.get('mujoco')}, mujoco-warp {env.get('mujoco-warp')}, "
            f"warp {env.get('warp-lang')}",
            "",
            "| envs | raw physics (samples/s) | rollout (samples/s) | whole loop (samples/s) | rollout/raw "
            "| loop/raw | 1.5e8 samples |",
            "|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for r in figs["runs"]:
            lines.append(
                f"| {r['num_envs']:,} | {r['raw_physics_samples_per_s']:,.0f} | "
                f"{r['rollout_samples_per_s']:,.0f} | {r['loop_samples_per_s']:,.0f} | "
                f"{r['rollout_over_raw']:.2f} | {r['loop_over_raw']:.2f} | "
                f"{r['paper_run_minutes']:,.1f} min |"
            )
        lines += [
            "",
            "Targets (issue 14, 4,096 envs, one H100/H200-class GPU): whole loop >= 150,000 samples/s, "
            "rollout >= 0.7 of raw physics, 1.5e8 samples <= 20 min.",
        ]
    else:
        lines += [f"- bench failed (exit {ben['rc']}); see bench.log", "", "```", ben["tail"][-800:], "```"]
    lines += ["", f"## 3. {minutes:g}-minute `scale=paper` training run (env.backend=warp, device=cuda)", ""]
    if "run_dir" in tr:
        lines += [
            f"- run: {tr['run_dir']} (exit {tr['rc']}; 130 = stopped by SIGINT after {minutes:g} min, "
            "checkpoint written)",
            f"- iterations {tr['iterations']}, samples {_fmt(tr['samples'])}, mean "
            f"{_fmt(tr['samples_per_s_mean'])} samples/s -> 1.5e8 samples in "
            f"{_fmt(tr.get('paper_run_minutes'), ',.1f')} min",
            f"- episode length (control steps): {_fmt(tr['episode_length_first'], '.1f')} -> "
            f"{_fmt(tr['episode_length_last'], '.1f')}",
            f"- r_S: {_fmt(tr['r_style_first'], '.3f')} -> {_fmt(tr['r_style_last'], '.3f')}",
        ]
    else:
        lines += [
            f"- training did not start a run (exit {tr['rc']}); see train.log",
            "",
            "```",
            tr["tail"][-800:],
            "```",
        ]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=REPO / "outputs" / "gpu-check")
    ap.add_argument("--minutes", type=float, default=10.0, help="length of the scale=paper training run")
    ap.add_argument("--envs", type=int, nargs="+", default=[1024, 4096, 8192])
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    gpu = gpu_name()
    if gpu is None:
        (a.out / "report.md").write_text(
            "# GPU check\n\nNo CUDA device visible to torch: nothing was measured. "
            "Install the CUDA build of torch (README, section GPU).\n"
        )
        sys.exit("gpu-check: torch sees no CUDA device (install the CUDA build of torch; README, section GPU)")
    t0 = time.time()
    par = parity(a.out)
    ben = bench(a.out, a.envs)
    tr = training(a.out, a.minutes)
    path = report(a.out, gpu, par, ben, tr, a.minutes, time.time() - t0)
    print(path.read_text())
    print(f"report: {path}")
    ok = par["rc"] == 0 and ben["rc"] == 0 and "run_dir" in tr and tr["rc"] in (0, 130)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
