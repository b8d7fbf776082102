"""cgail throughput, measured in one run on the same batch:

    .venv/bin/python scripts/bench_cgail.py [--envs 64] [--iters 4] [overrides...]
    .venv/bin/python scripts/bench_cgail.py --envs 256 --against REV   # this tree vs commit REV


1. raw batched physics: BatchedHumanoid.step with fixed PD targets (control steps/s = samples/s); only
   the step calls are timed (the states restored every 15 steps with set_state are not)
2. rollout: sim + observations + policy forward + discriminator reward (samples/s)
3. the whole training loop, `CgailLearner.iterate` as `charctl train` runs it (rollout + reward + PPO +
   discriminator update; with train.overlap_update the updates run beside the next rollout), with the
   share of wall time of each phase.
Prints rollout/raw (target >= 70 %) and what limits it.

`--against REV` exports commit REV's tree (git archive) to a temporary folder and runs its own
bench_cgail.py and this tree's, each with its own `scale=small` preset, alternately A B A B in
subprocesses, then prints the whole-loop samples/s of both and their ratio (means over the rounds,
so background load that drifts during the run hits both sides alike).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np
import torch


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--envs", type=int, default=64)
    ap.add_argument("--iters", type=int, default=4)
    ap.add_argument("--against", metavar="REV", help="also bench commit REV's tree and print the ratio")
    ap.add_argument("--rounds", type=int, default=2, help="A/B rounds with --against")
    ap.add_argument("overrides", nargs="*", default=["scale=small"])
    a = ap.parse_args()
    if a.against:
        compare_with_revision(a.against, a.envs, a.iters, a.rounds, a.overrides)
        return
    from charctl.config import compose_config
    from charctl.experiments.cgail.agent import build_agent
    from charctl.experiments.cgail.config import Config
    from charctl.experiments.cgail.env import CgailEnv
    from charctl.experiments.cgail.reward import discriminator_rewards
    from charctl.experiments.cgail.rollout import collect_rollout
    from charctl.experiments.cgail.train import CgailLearner

    cfg = compose_config("cgail", [*a.overrides, f"env.num_envs={a.envs}"], Config)
    torch.set_num_threads(int(cfg.train.torch_threads))
    agent = build_agent(cfg)
    env = CgailEnv(agent.skills, cfg.env, seed=0)
    T = cfg.train.rollout_steps
    # 1. raw batched physics on the same env batch: only the BatchedHumanoid.step calls are timed. Every
    # 15 control steps (with zero PD targets the characters would fall over) the RSI states of one env.reset
    # are written back with set_state, outside the timed region: env.reset would add its features, RNG and
    # bookkeeping to the "raw" figure
    targets = np.zeros((env.N, env.sim.layout.nu))
    env.reset(np.arange(env.N))
    ids = np.arange(env.N)
    qpos0, qvel0 = env.sim.qpos.copy(), env.sim.qvel.copy()
    stepping = 0.0
    for i in range(T * a.iters):
        t0 = time.perf_counter()
        env.sim.step(targets)
        stepping += time.perf_counter() - t0
        if i % 15 == 14:
            env.sim.set_state(ids, qpos0, qvel0)
    raw = T * a.iters * env.N / stepping
    # 2. rollout incl. discriminator reward
    collect_rollout(agent, env, 4)
    t0 = time.perf_counter()
    for _ in range(a.iters):
        ro = collect_rollout(agent, env, T)
        discriminator_rewards(agent, ro)
    rollout = T * a.iters * env.N / (time.perf_counter() - t0)
    # 3. full training iterations: the training loop itself (CgailLearner.iterate), after one warm-up
    # iteration (with train.overlap_update the first iteration has no update to overlap)
    learner = CgailLearner(cfg)
    learner.iterate()
    phases: dict[str, float] = {}
    t_all = time.perf_counter()
    for _ in range(a.iters):
        stats = learner.iterate()
        for k, v in stats.items():
            if k.startswith("perf/frac_"):
                phases[k.removeprefix("perf/frac_")] = phases.get(k.removeprefix("perf/frac_"), 0.0) + v / a.iters
    full = T * a.iters * env.N / (time.perf_counter() - t_all)
    print(
        f"cgail bench: {env.N} envs, physics {cfg.env.physics_hz:.0f} Hz / control "
        f"{cfg.env.control_hz:.0f} Hz, policy {list(cfg.ppo.hidden)}, disc {list(cfg.disc.hidden)}"
    )
    print(f"  raw batched physics     {raw:10,.0f} samples/s (control steps of all envs)")
    print(
        f"  rollout (+obs, policy, disc reward) {rollout:10,.0f} samples/s "
        f"= {100 * rollout / raw:.0f} % of raw physics (target >= 70 %)"
    )
    print(
        f"  whole training loop     {full:10,.0f} samples/s "
        f"= {full / raw:.2f} x raw physics at {env.N} envs (goal >= 0.8: the loop not the bottleneck)"
    )
    overlap = "overlapped with the rollout, " if learner.overlap else ""
    print(
        f"  time per phase ({overlap}share of the loop's wall time): "
        + ", ".join(f"{k} {100 * v:.0f} %" for k, v in phases.items())
    )


LOOP_LINE = re.compile(r"whole training loop\s+([\d,]+) samples/s")


def bench_tree(root: Path, envs: int, iters: int, overrides: list[str]) -> float:
    """Run `root`'s own bench_cgail.py in a subprocess (imports from `root`); whole-loop samples/s."""
    cmd = [sys.executable, str(root / "scripts" / "bench_cgail.py"), "--envs", str(envs), "--iters", str(iters)]
    env = {**os.environ, "PYTHONPATH": str(root)}
    out = subprocess.run([*cmd, *overrides], cwd=root, env=env, capture_output=True, text=True, check=True).stdout
    print("\n".join("    " + line for line in out.strip().splitlines()))
    match = LOOP_LINE.search(out)
    if match is None:
        raise SystemExit(f"no 'whole training loop' line in the output of {root}")
    return float(match.group(1).replace(",", ""))


def compare_with_revision(rev: str, envs: int, iters: int, rounds: int, overrides: list[str]) -> None:
    """Whole-loop samples/s of this tree and of commit `rev`, alternated, and their ratio."""
    here = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp:
        archive = Path(tmp) / "rev.tar"
        subprocess.run(["git", "archive", "-o", str(archive), rev], cwd=here, check=True)
        with tarfile.open(archive) as tar:
            tar.extractall(Path(tmp) / "rev", filter="data")
        old_root = Path(tmp) / "rev"
        old, new = [], []
        for r in range(rounds):
            print(f"round {r + 1}/{rounds}: {rev}")
            old.append(bench_tree(old_root, envs, iters, overrides))
            print(f"round {r + 1}/{rounds}: this tree")
            new.append(bench_tree(here, envs, iters, overrides))
    mean_old, mean_new = sum(old) / len(old), sum(new) / len(new)
    print(f"whole training loop, {envs} envs, {' '.join(overrides)} of each tree:")
    print(f"  {rev}: {mean_old:10,.0f} samples/s")
    print(f"  this tree: {mean_new:10,.0f} samples/s   ratio {mean_new / mean_old:.2f}x")


if __name__ == "__main__":
    main()
