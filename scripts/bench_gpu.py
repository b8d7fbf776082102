"""cgail throughput on the GPU path (MuJoCo Warp + torch on one device), at several env counts, in one run:

    .venv/bin/python scripts/bench_gpu.py               # 1,024 / 4,096 / 8,192 envs, scale=paper, cuda
    .venv/bin/python scripts/bench_gpu.py --envs 8 --iters 1 --device cpu --steps 4 scale=smoke   # CPU smoke

For each env count, on the same batch (samples = control steps of one env, 1/30 s of simulated time):
1. raw physics: `WarpBatchedHumanoid.step` with fixed PD targets (all substeps, blow-up check, kinematics);
2. rollout: the device env + policy forward per step + one discriminator forward for r_S/r_C;
3. the whole training loop (`CgailLearner.iterate`: rollout, rewards, PPO, discriminator update).
Prints samples/s and the ratios rollout/raw and loop/raw (issue 14 targets at 4,096 envs on one
H100/H200-class GPU: loop >= 150,000 samples/s, rollout >= 0.7 of raw), and the projected wall time of
the paper's 1.5e8 samples. `--json PATH` writes the figures for `scripts/gpu_check.py`.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch

PAPER_SAMPLES = 150_000_000


def _sync(device: str) -> None:
    if torch.device(device).type == "cuda":
        torch.cuda.synchronize(device)


def bench_one(num_envs: int, iters: int, device: str, overrides: list[str], steps: int | None) -> dict:
    """Figures of one env count (a fresh learner, warmed up by one iteration before timing)."""
    from charctl.config import compose_config
    from charctl.experiments.cgail.config import Config
    from charctl.experiments.cgail.reward import discriminator_rewards
    from charctl.experiments.cgail.rollout import collect_rollout
    from charctl.experiments.cgail.train import CgailLearner

    extra = [f"env.num_envs={num_envs}", "env.backend=warp", f"device={device}"]
    if steps is not None:
        extra.append(f"train.rollout_steps={steps}")
    cfg = compose_config("cgail", [*overrides, *extra], Config)
    t0 = time.perf_counter()
    learner = CgailLearner(cfg)
    learner.iterate()  # warm-up: kernel loads, CUDA graph capture, cuBLAS handles
    _sync(learner.device)
    setup_s = time.perf_counter() - t0
    env, agent, T = learner.env, learner.agent, int(cfg.train.rollout_steps)
    sim, N = env.sim, env.N
    # 1. raw physics (fresh RSI states between chunks, not timed, so the characters are not all lying down)
    targets = torch.zeros(N, sim.layout.nu, device=sim.device)
    raw_s = 0.0
    for _ in range(iters):
        env.reset(torch.ones(N, dtype=torch.bool, device=sim.device))
        _sync(learner.device)
        t0 = time.perf_counter()
        for _ in range(T):
            sim.step(targets)
        _sync(learner.device)
        raw_s += time.perf_counter() - t0
    # 2. rollout incl. discriminator reward
    _sync(learner.device)
    t0 = time.perf_counter()
    for _ in range(iters):
        ro = collect_rollout(agent, env, T)
        discriminator_rewards(agent, ro)
    _sync(learner.device)
    rollout_s = time.perf_counter() - t0
    # 3. whole training iterations
    t0 = time.perf_counter()
    phases = {"rollout": 0.0, "reward": 0.0, "ppo": 0.0, "disc": 0.0}
    for _ in range(iters):
        stats = learner.iterate()
        for k in phases:
            phases[k] += stats[f"perf/frac_{k}"] / iters
    _sync(learner.device)
    loop_s = time.perf_counter() - t0
    n = T * N * iters
    raw, rollout, loop = n / raw_s, n / rollout_s, n / loop_s
    out = {
        "num_envs": N,
        "rollout_steps": T,
        "iters": iters,
        "setup_s": round(setup_s, 1),
        "raw_physics_samples_per_s": raw,
        "rollout_samples_per_s": rollout,
        "loop_samples_per_s": loop,
        "rollout_over_raw": rollout / raw,
        "loop_over_raw": loop / raw,
        "paper_run_minutes": PAPER_SAMPLES / loop / 60.0,
        "phase_fractions": phases,
        "unstable_resets": sim.unstable_count,
    }
    del learner, env, agent, sim
    if torch.device(device).type == "cuda":
        torch.cuda.empty_cache()
    return out


def environment(device: str) -> dict:
    """Versions and the device, for the report."""
    import importlib.metadata as md

    info = {"device": device, "torch": torch.__version__}
    for pkg in ("mujoco", "mujoco-warp", "warp-lang"):
        try:
            info[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            info[pkg] = "not installed"
    if torch.device(device).type == "cuda":
        info["gpu"] = torch.cuda.get_device_name(torch.device(device))
    return info


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--envs", type=int, nargs="+", default=[1024, 4096, 8192], help="env counts to measure")
    ap.add_argument("--iters", type=int, default=3, help="timed iterations per phase")
    ap.add_argument("--steps", type=int, default=None, help="rollout steps per iteration (default: the config's)")
    ap.add_argument("--device", default="cuda", help="torch/Warp device: cuda, cuda:N or cpu (smoke check)")
    ap.add_argument("--json", type=Path, default=None, help="also write the figures here")
    ap.add_argument("overrides", nargs="*", default=["scale=paper"], help="config overrides (default scale=paper)")
    a = ap.parse_args()
    from charctl.config import resolve_device

    device = resolve_device(a.device)
    results = {"environment": environment(device), "overrides": a.overrides, "runs": []}
    print(f"cgail GPU-path bench on {results['environment'].get('gpu', device)} ({' '.join(a.overrides)})")
    print(
        f"  {'envs':>6} {'raw physics':>14} {'rollout':>12} {'whole loop':>12} {'rollout/raw':>12} {'loop/raw':>9} "
        f"{'1.5e8 samples':>14}"
    )
    for n in a.envs:
        r = bench_one(n, a.iters, device, list(a.overrides), a.steps)
        results["runs"].append(r)
        print(
            f"  {n:>6} {r['raw_physics_samples_per_s']:>12,.0f}/s {r['rollout_samples_per_s']:>10,.0f}/s "
            f"{r['loop_samples_per_s']:>10,.0f}/s {r['rollout_over_raw']:>12.2f} {r['loop_over_raw']:>9.2f} "
            f"{r['paper_run_minutes']:>11,.1f} min",
            flush=True,
        )
        print("         time per phase: " + ", ".join(f"{k} {100 * v:.0f} %" for k, v in r["phase_fractions"].items()))
        if a.json:  # after each env count, so a bench stopped early keeps what it measured
            a.json.parent.mkdir(parents=True, exist_ok=True)
            a.json.write_text(json.dumps(results, indent=2))
    if a.json:
        print(f"figures: {a.json}")


if __name__ == "__main__":
    main()
