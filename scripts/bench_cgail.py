"""cgail throughput, measured in one run on the same batch:

    .venv/bin/python scripts/bench_cgail.py [--envs 64] [--iters 4] [overrides...]
    .venv/bin/python scripts/bench_cgail.py --envs 256 --against REV   # this tree vs commit REV
    .venv/bin/python scripts/bench_cgail.py --envs 256 --ab "env.backend=cpu" "env.backend=torch"  # two override sets


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

`--ab A B` does the same for two override sets A and B (each a space-separated list, added after the
common overrides) in this tree, and prints each side's loop / raw physics as well. The rollout figure
(2.) and the whole loop (3.) follow env.backend (the numpy env, or the torch env for torch); the raw
physics (1.) is C MuJoCo's `BatchedHumanoid.step` on either side.
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
    ap.add_argument("--ab", nargs=2, metavar=("A", "B"), help="two override sets (quoted) to compare in this tree")
    ap.add_argument("--rounds", type=int, default=2, help="A/B rounds with --against or --ab")
    ap.add_argument("overrides", nargs="*", default=["scale=small"])
    a = ap.parse_intermixed_args()
    if a.against:
        compare_with_revision(a.against, a.envs, a.iters, a.rounds, a.overrides)
        return
    if a.ab:
        compare_overrides(a.ab[0], a.ab[1], a.envs, a.iters, a.rounds, a.overrides)
        return
    bench(a.envs, a.iters, a.overrides)


def bench(envs: int, iters: int, overrides: list[str]) -> None:
    """Raw physics, rollout and whole-loop samples/s of `overrides` at `envs` envs (printed)."""
    from charctl.config import compose_config
    from charctl.experiments.cgail.config import Config
    from charctl.experiments.cgail.env import CgailEnv
    from charctl.experiments.cgail.reward import discriminator_rewards
    from charctl.experiments.cgail.rollout import collect_rollout
    from charctl.experiments.cgail.train import CgailLearner

    cfg = compose_config("cgail", [*overrides, f"env.num_envs={envs}"], Config)
    torch.set_num_threads(int(cfg.train.torch_threads))
    learner = CgailLearner(cfg)  # the env of env.backend (numpy, or the torch env for env.backend=torch)
    agent = learner.agent
    env = CgailEnv(agent.skills, cfg.env, seed=0)  # raw physics: C MuJoCo's BatchedHumanoid whatever the backend
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
    for i in range(T * iters):
        t0 = time.perf_counter()
        env.sim.step(targets)
        stepping += time.perf_counter() - t0
        if i % 15 == 14:
            env.sim.set_state(ids, qpos0, qvel0)
    raw = T * iters * env.N / stepping
    # 2. rollout incl. discriminator reward, on the learner's env
    collect_rollout(agent, learner.env, 4)
    t0 = time.perf_counter()
    for _ in range(iters):
        ro = collect_rollout(agent, learner.env, T)
        discriminator_rewards(agent, ro)
    rollout = T * iters * env.N / (time.perf_counter() - t0)
    # 3. full training iterations: the training loop itself (CgailLearner.iterate), after one warm-up
    # iteration (with train.overlap_update the first iteration has no update to overlap)
    learner.iterate()
    phases: dict[str, float] = {}
    t_all = time.perf_counter()
    for _ in range(iters):
        stats = learner.iterate()
        for k, v in stats.items():
            if k.startswith("perf/frac_"):
                phases[k.removeprefix("perf/frac_")] = phases.get(k.removeprefix("perf/frac_"), 0.0) + v / iters
    full = T * iters * env.N / (time.perf_counter() - t_all)
    _report(cfg, env.N, raw, rollout, full, phases, learner.overlap)


def _report(cfg, n: int, raw: float, rollout: float, full: float, phases: dict[str, float], overlapped: bool) -> None:
    """Print the three figures (samples/s) and the loop's time per phase (shares of its wall time)."""
    print(
        f"cgail bench: {n} envs, env.backend={cfg.env.backend}, physics {cfg.env.physics_hz:.0f} Hz / control "
        f"{cfg.env.control_hz:.0f} Hz, policy {list(cfg.ppo.hidden)}, disc {list(cfg.disc.hidden)}"
    )
    print(f"  raw batched physics     {raw:10,.0f} samples/s (control steps of all envs)")
    print(
        f"  rollout (+obs, policy, disc reward) {rollout:10,.0f} samples/s "
        f"= {100 * rollout / raw:.0f} % of raw physics (target >= 70 %)"
    )
    print(
        f"  whole training loop     {full:10,.0f} samples/s "
        f"= {full / raw:.2f} x raw physics at {n} envs (goal >= 0.8: the loop not the bottleneck)"
    )
    overlap = "overlapped with the rollout, " if overlapped else ""
    print(
        f"  time per phase ({overlap}share of the loop's wall time): "
        + ", ".join(f"{k} {100 * v:.0f} %" for k, v in phases.items())
    )


LOOP_LINE = re.compile(r"whole training loop\s+([\d,]+) samples/s")
RAW_LINE = re.compile(r"raw batched physics\s+([\d,]+) samples/s")


def _figure(pattern: re.Pattern, out: str, root: Path) -> float:
    match = pattern.search(out)
    if match is None:
        raise SystemExit(f"no {pattern.pattern!r} line in the output of {root}")
    return float(match.group(1).replace(",", ""))


def bench_tree(root: Path, envs: int, iters: int, overrides: list[str]) -> tuple[float, float]:
    """Run `root`'s own bench_cgail.py in a subprocess (imports from `root`): (whole loop, raw physics) samples/s."""
    cmd = [sys.executable, str(root / "scripts" / "bench_cgail.py"), "--envs", str(envs), "--iters", str(iters)]
    env = {**os.environ, "PYTHONPATH": str(root)}
    out = subprocess.run([*cmd, *overrides], cwd=root, env=env, capture_output=True, text=True, check=True).stdout
    print("\n".join("    " + line for line in out.strip().splitlines()))
    return _figure(LOOP_LINE, out, root), _figure(RAW_LINE, out, root)


def alternate(sides: list[tuple[str, Path, list[str]]], envs: int, iters: int, rounds: int) -> list[dict]:
    """Bench each (label, tree, overrides) side in turn, `rounds` times (A B A B ...); per side the means over
    the rounds of the whole-loop samples/s and of loop / raw physics (each round's own ratio)."""
    runs: list[list[tuple[float, float]]] = [[] for _ in sides]
    for r in range(rounds):
        for (label, root, overrides), out in zip(sides, runs):
            print(f"round {r + 1}/{rounds}: {label}")
            out.append(bench_tree(root, envs, iters, overrides))
    return [
        {"loop": float(np.mean([lp for lp, _ in out])), "per_raw": float(np.mean([lp / raw for lp, raw in out]))}
        for out in runs
    ]


def compare_with_revision(rev: str, envs: int, iters: int, rounds: int, overrides: list[str]) -> None:
    """Whole-loop samples/s of this tree and of commit `rev`, alternated, and their ratio."""
    here = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp:
        archive = Path(tmp) / "rev.tar"
        subprocess.run(["git", "archive", "-o", str(archive), rev], cwd=here, check=True)
        with tarfile.open(archive) as tar:
            tar.extractall(Path(tmp) / "rev", filter="data")
        old_root = Path(tmp) / "rev"
        old, new = alternate([(rev, old_root, overrides), ("this tree", here, overrides)], envs, iters, rounds)
    print(f"whole training loop, {envs} envs, {' '.join(overrides)} of each tree:")
    print(f"  {rev}: {old['loop']:10,.0f} samples/s")
    print(f"  this tree: {new['loop']:10,.0f} samples/s   ratio {new['loop'] / old['loop']:.2f}x")


def compare_overrides(a: str, b: str, envs: int, iters: int, rounds: int, overrides: list[str]) -> None:
    """Whole-loop samples/s of override sets `a` and `b` (space-separated, after `overrides`) in this tree,
    alternated: both, their ratio b / a, and each side's loop / raw physics."""
    here = Path(__file__).resolve().parents[1]
    sides = [(label, here, [*overrides, *label.split()]) for label in (a, b)]
    res_a, res_b = alternate(sides, envs, iters, rounds)
    print(f"whole training loop, {envs} envs, {' '.join(overrides)}, means over {rounds} rounds:")
    for label, res in ((f"A {a}", res_a), (f"B {b}", res_b)):
        print(f"  {label}: {res['loop']:10,.0f} samples/s   loop / raw physics {res['per_raw']:.3f}")
    print(f"  ratio B / A {res_b['loop'] / res_a['loop']:.3f}x")


if __name__ == "__main__":
    main()
