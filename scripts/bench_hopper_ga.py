"""GA wall time of hopper-ga per runtime (local | process | ray) for one population x generations.

    .venv/bin/python scripts/bench_hopper_ga.py [--population 100] [--generations 100] [--speed 5] [--beta 0.5]
        [--runtimes local,process,ray] [--workers 2]

Times `evolve` alone (no TensorBoard/figures); prints wall and CPU seconds of this process (the
pool / Ray workers' CPU is not in it), evaluations and the best eval, which must be identical
across runtimes for the same seed.
"""

from __future__ import annotations

import argparse
import time

from omegaconf import OmegaConf

from charctl.experiments.hopper_ga.config import Config
from charctl.experiments.hopper_ga.ga import evolve
from charctl.experiments.hopper_ga.runtime import make_evaluator
from charctl.experiments.hopper_ga.settings import settings_from_config


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--population", type=int, default=100)
    ap.add_argument("--generations", type=int, default=100)
    ap.add_argument("--speed", type=float, default=5.0)
    ap.add_argument("--beta", type=float, default=0.5)
    ap.add_argument("--runtimes", default="local,process,ray")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    print(
        f"hopper-ga GA {args.population} x {args.generations}, speed "
        f"{args.speed} m/s, beta {args.beta}, workers {args.workers}"
    )
    print(f"{'runtime':>8} {'wall s':>8} {'setup s':>8} {'cpu s':>8} {'evals':>7} {'eval s':>8} {'best eval':>12}")
    for kind in args.runtimes.split(","):
        cfg = OmegaConf.structured(Config)
        cfg.speed, cfg.beta = args.speed, args.beta
        cfg.ga.population, cfg.ga.generations = args.population, args.generations
        cfg.runtime.kind, cfg.runtime.workers = kind, args.workers
        s = settings_from_config(cfg)
        t0, c0 = time.perf_counter(), time.process_time()
        with make_evaluator(cfg.runtime, s) as ev:
            setup = time.perf_counter() - t0
            st = evolve(cfg.ga, args.seed, s.low, s.high, ev)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        print(
            f"{kind:>8} {wall:>8.1f} {setup:>8.1f} {cpu:>8.1f} {st.evaluations:>7d} "
            f"{st.eval_seconds:>8.1f} {st.best_fitness:>12.8f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
