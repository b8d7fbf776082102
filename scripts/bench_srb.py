"""srb throughput in one run: QP solves/s of the solver alone (and the alternatives), rollout
samples/s (SRB env + QP + policy forward) and training samples/s (rollout + PPO update).

    .venv/bin/python scripts/bench_srb.py [--envs 32] [--steps 32] [--iterations 5] [--json out.json]

Everything runs on one core (torch threads 1; numpy and daqp are single-threaded here). The
paper reports 2e8 samples in 57 min on a 16-core desktop (i9-9900K + RTX 2080 Ti), i.e.
58,480 samples/s or 3,655 samples/s per core; the ratio printed is ours (one core) to that.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

PAPER_SAMPLES_PER_S = 2e8 / (57 * 60)
PAPER_CORES = 16


def timed(fn, repeat: int) -> float:
    """Seconds per call (best of three batches of `repeat` calls)."""
    fn()
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(repeat):
            fn()
        best = min(best, (time.perf_counter() - t0) / repeat)
    return best


def recorded_batch(cfg, n: int, steps: int = 20):
    """QP inputs from a real rollout (zero action) so the solver sees realistic instances."""
    from charctl.experiments.srb import qp as Q
    from charctl.experiments.srb.env import SRBEnv

    env = SRBEnv(cfg, n, seed=0)
    saved = {}
    original = Q.solve_batch

    def spy(batch, params, solver):
        saved["batch"], saved["params"] = batch, params
        return original(batch, params, solver)

    import charctl.experiments.srb.env as E

    E.solve_batch = spy
    try:
        for _ in range(steps):
            env.step(np.zeros((n, 10)))
    finally:
        E.solve_batch = original
    return saved["batch"], saved["params"]


def bench_qp(cfg, n: int) -> dict:
    import daqp
    import scipy.linalg

    from charctl.experiments.srb import qp as Q

    batch, params = recorded_batch(cfg, n)
    h, f, lb, ub, _, _ = Q.reduced_problem(batch, params)
    out: dict = {"envs": n}
    out["build_us_per_env"] = 1e6 * timed(lambda: Q.reduced_problem(batch, params), 50) / n
    for name, solve in Q.SOLVERS.items():
        per = timed(lambda: [solve(h[i], f[i], lb[i], ub[i]) for i in range(n)], 20 if name == "daqp" else 5) / n  # noqa: B023
        out[f"solve_us[{name}]"] = 1e6 * per
        out[f"solves_per_s[{name}]"] = 1.0 / per
    infos = [daqp.solve(h[i], f[i], np.zeros((0, Q.N_VARS)), ub[i], lb[i])[3] for i in range(n)]
    out["daqp_internal_us"] = 1e6 * float(
        np.mean([i["solve_time"] + i["setup_time"] for i in infos])
    )  # C setup + solve
    out["daqp_iterations_mean"] = float(np.mean([i["iterations"] for i in infos]))
    # the alternative: one block-diagonal QP over all envs (daqp is dense, so cost grows with n^2..3)
    big_h = scipy.linalg.block_diag(*h)
    big = (big_h, f.ravel(), np.zeros((0, big_h.shape[0])), ub.ravel(), lb.ravel())
    per_block = timed(lambda: daqp.solve(*big), 3) / n
    out["solve_us[daqp block-diagonal]"] = 1e6 * per_block
    out["solve_batch_us_per_env"] = 1e6 * timed(lambda: Q.solve_batch(batch, params, "daqp"), 10) / n
    return out


def bench_rollout_and_training(cfg, envs: int, steps: int, iterations: int) -> dict:
    import torch

    from charctl.experiments.srb.env import ACT_DIM, OBS_DIM, SRBEnv
    from charctl.experiments.srb.train import build_agent, collect_rollout
    from charctl.rl.storage import RolloutStorage

    torch.set_num_threads(1)
    agent = build_agent(cfg)
    env = SRBEnv(cfg, envs, seed=0)
    storage = RolloutStorage(steps, envs, OBS_DIM, ACT_DIM)
    obs = env.observe()
    obs, _ = collect_rollout(agent, env, storage, obs, 0.995)  # warm-up
    t_roll = t_upd = 0.0
    for _ in range(iterations):
        t0 = time.perf_counter()
        obs, _ = collect_rollout(agent, env, storage, obs, 0.995)
        t1 = time.perf_counter()
        agent.ppo.update(storage)
        t2 = time.perf_counter()
        t_roll += t1 - t0
        t_upd += t2 - t1
    samples = envs * steps * iterations
    zero = timed(lambda: env.step(np.zeros((envs, 10))), 20)
    return {
        "envs": envs,
        "rollout_steps": steps,
        "iterations": iterations,
        "env_only_samples_per_s": envs / zero,
        "rollout_samples_per_s": samples / t_roll,
        "training_samples_per_s": samples / (t_roll + t_upd),
        "ppo_update_s_per_1024": t_upd / iterations * 1024 / (envs * steps),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=32)
    parser.add_argument("--steps", type=int, default=32)
    parser.add_argument("--iterations", type=int, default=5)
    parser.add_argument("--json", type=str, default="")
    args = parser.parse_args()

    from charctl.config import compose_config
    from charctl.experiments.srb.config import Config

    cfg = compose_config("srb", ["scale=small"], Config)
    qp = bench_qp(cfg, args.envs)
    run = bench_rollout_and_training(cfg, args.envs, args.steps, args.iterations)
    per_core_paper = PAPER_SAMPLES_PER_S / PAPER_CORES
    result = {
        "qp": qp,
        "rl": run,
        "paper_samples_per_s": PAPER_SAMPLES_PER_S,
        "paper_samples_per_s_per_core": per_core_paper,
        "ratio_training_per_core_vs_paper": run["training_samples_per_s"] / per_core_paper,
        "ratio_training_vs_paper_machine": run["training_samples_per_s"] / PAPER_SAMPLES_PER_S,
    }
    print(f"QP ({args.envs} envs, 19 variables each, recorded walking instances):")
    for k, v in qp.items():
        if k != "envs":
            print(f"  {k:38s} {v:12,.1f}")
    print(f"rollout / training ({args.envs} envs x {args.steps} steps, {args.iterations} PPO iterations, 1 core):")
    for k, v in run.items():
        print(f"  {k:38s} {v:12,.2f}")
    print(f"paper: {PAPER_SAMPLES_PER_S:,.0f} samples/s on {PAPER_CORES} cores = {per_core_paper:,.0f} per core")
    print(
        f"ours / paper per core: {result['ratio_training_per_core_vs_paper']:.3f}  "
        f"(ours / paper machine: {result['ratio_training_vs_paper_machine']:.4f})"
    )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh, indent=2)


if __name__ == "__main__":
    main()
