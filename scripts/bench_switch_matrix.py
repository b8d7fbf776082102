#!/usr/bin/env python
"""`charctl eval RUN --switch-matrix` rollouts: every ordered skill pair in one batched rollout (what the evaluation
does) against one rollout per pair (what it did before), measured in one run on the same policy, CPU time and wall
time, best of `--repeat`:

    .venv/bin/python scripts/bench_switch_matrix.py [RUN] [-k TRIALS] [--repeat N] [--pairs P]

RUN defaults to the shipped ten-skill policy (90 pairs). `--pairs P` times only the first P pairs (a quicker
look). The windows are the matrix's (`switch_frames`: 1 s of A, the run's ramp, 3 s more). Both sides draw their
heading goals from the same seed but in different numbers of envs, so their trials differ; the rollouts are the
same function (`switch_rollout`), and tests/test_cgail_switch_matrix.py checks that the batched one equals the
per-pair ones when nothing is drawn.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from charctl.experiments.cgail.evaluate import switch_frames  # noqa: E402
from charctl.experiments.cgail.rollouts import load_eval_run, switch_rollout  # noqa: E402


def timed(fn) -> tuple[float, float]:
    """(wall s, CPU s of this process) of one call of `fn`."""
    tic, ctic = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - tic, time.process_time() - ctic


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", nargs="?", default="pretrained/cgail-10skill-track-skills")
    ap.add_argument("-k", "--trials", type=int, default=4, help="trials per pair (the matrix's -k)")
    ap.add_argument("--repeat", type=int, default=2, help="timings per side; the best is kept")
    ap.add_argument("--pairs", type=int, default=0, help="time only the first P pairs (0: all)")
    args = ap.parse_args()

    tr = load_eval_run(args.run, device="cpu")
    frames = switch_frames(tr, 1.0, 3.0, perform_seconds=None)
    k = len(tr.skill_names)
    pairs = np.array([(i, j) for i in range(k) for j in range(k) if i != j])
    if args.pairs:
        pairs = pairs[: args.pairs]
    hz = tr.cfg.env.control_hz
    perform = int(round(frames["perform_seconds"] * hz))
    window = (frames["ramp_frames"], frames["switch_frame"], frames["end_frame"], perform)

    def batched() -> None:
        switch_rollout(tr, pairs[:, 0], pairs[:, 1], args.trials, *window)

    def per_pair() -> None:
        for a, b in pairs:
            switch_rollout(tr, a, b, args.trials, *window)

    best = {}
    for name, fn in (("per pair", per_pair), ("batched", batched)):
        runs = [timed(fn) for _ in range(args.repeat)]
        best[name] = (min(r[0] for r in runs), min(r[1] for r in runs))
    steps = frames["end_frame"] * len(pairs) * args.trials
    print(f"{args.run}: {len(pairs)} pairs x {args.trials} trials, {frames['end_frame']} control steps each")
    for name, (wall, cpu) in best.items():
        print(f"  {name:9s} wall {wall:7.2f} s  CPU {cpu:7.2f} s  ({steps / wall:,.0f} env-steps/s)")
    (wp, cp), (wb, cb) = best["per pair"], best["batched"]
    print(f"  batched / per pair: {wp / wb:.1f}x faster (wall), {cp / cb:.1f}x less CPU")


if __name__ == "__main__":
    main()
