#!/usr/bin/env python
"""motion-matching benchmark: query latency of the indices vs brute force, and the real-time factor.

* real database (default config: 120 Hz, 14 clips) with the queries the runtime really makes
  while following circle/square/star (recorded, then replayed against each index);
* synthetic 50,000-frame databases of the same feature width:
    takes        the real database repeated as further "takes" (in frame order, so consecutive
                 rows stay close, as in any mocap database), each take moved by a slowly
                 varying random offset (0.15 x the per-column spread) plus white noise (0.02 x)
    iid          i.i.d. Gaussian rows with the real per-column spread: no structure at all,
                 the worst case for any tree or box pruning
  queried with the recorded queries and a random current row (exclusion window k = 20 rows);
* real-time factor: frames generated per wall-clock second (search + pose inertialization +
  root reconstruction) divided by the database rate.

  python scripts/bench_mm.py [--json FILE] [--repeat N] [--synthetic N] [overrides ...]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from charctl.config import compose_config
from charctl.experiments.motion_matching.config import Config  # noqa: E402
from charctl.experiments.motion_matching.database import build_database  # noqa: E402
from charctl.experiments.motion_matching.paths import make_path  # noqa: E402
from charctl.experiments.motion_matching.runtime import run_path  # noqa: E402
from charctl.experiments.motion_matching.search import RowInfo, make_index  # noqa: E402

KINDS = ("brute", "kdtree", "bbox")


class Recorder:
    """Wraps an index and records every query the runtime makes."""

    def __init__(self, index):
        self.index, self.calls = index, []

    def query(self, q, clip=-1, phase=0.0):
        self.calls.append((q.copy(), clip, phase))
        return self.index.query(q, clip, phase)


def time_queries(index, calls, repeat: int) -> tuple[float, float, list[int]]:
    """Best-of-`repeat` mean wall and CPU (this thread) seconds per query, and the rows answered.

    The CPU time leaves out the time the thread waits for a core, so it is the fairer figure on
    a shared machine; the wall time is what a single user would see.
    """
    index.query(*calls[0])  # warm-up (numba compiles or loads its cache here)
    wall = cpu = np.inf
    answers: list[int] = []
    for _ in range(repeat):
        tic, ctic = time.perf_counter(), time.thread_time()
        answers = [index.query(*c)[0] for c in calls]
        wall = min(wall, (time.perf_counter() - tic) / len(calls))
        cpu = min(cpu, (time.thread_time() - ctic) / len(calls))
    return wall, cpu, answers


def synthetic_takes(feats: np.ndarray, n: int, rng) -> tuple[np.ndarray, RowInfo]:
    """n rows: the real rows repeated take after take, each with a smooth random offset + noise."""
    from scipy.ndimage import uniform_filter1d

    m, d = feats.shape
    spread = feats.std(axis=0)
    parts, clips = [], []
    for c in range(-(-n // m)):
        drift = uniform_filter1d(rng.normal(0, 1, (m, d)), size=121, axis=0, mode="nearest")
        drift *= 0.15 * spread / np.maximum(drift.std(axis=0), 1e-12)
        parts.append(feats + drift + rng.normal(0, 1, (m, d)) * 0.02 * spread)
        clips.append(np.full(m, c))
    data = np.concatenate(parts)[:n]
    clip = np.concatenate(clips)[:n]
    phase = np.concatenate([np.arange(m, dtype=float)] * len(parts))[:n]
    return data, RowInfo(clip, phase, np.zeros(n), 20.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", type=Path, default=None, help="write the figures as JSON here")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--synthetic", type=int, default=50_000)
    ap.add_argument("overrides", nargs="*")
    args = ap.parse_args()
    cfg = compose_config("motion-matching", args.overrides, Config)
    rng = np.random.default_rng(0)
    tic = time.perf_counter()
    db = build_database(cfg)
    build_s = time.perf_counter() - tic
    feats = db.search_features
    n, d = feats.shape
    print(f"database: {n} searchable frames x {d} features at {db.fps:.0f} Hz (built in {build_s:.2f} s)")

    # ---- the runtime's own queries on the real database
    rec = Recorder(make_index("brute", db))
    paths = [make_path(p, cfg.paths) for p in ("circle", "square", "star")]
    for p in paths:
        run_path(db, rec, p, cfg, with_pose=False)
    calls = rec.calls
    results = {"database_frames": n, "feature_dims": d, "fps": db.fps, "queries": len(calls), "latency_us": {}}

    def measure(label: str, make, queries) -> None:
        row, ref = {}, None
        for kind in KINDS:
            tic = time.perf_counter()
            index = make(kind)
            built = time.perf_counter() - tic
            wall, cpu, ans = time_queries(index, queries, args.repeat)
            ref = ans if ref is None else ref
            row[kind] = {
                "us_per_query": wall * 1e6,
                "cpu_us_per_query": cpu * 1e6,
                "build_s": built,
                "same_as_brute": ans == ref,
            }
        results["latency_us"][label] = row

    measure(f"real ({n} frames)", lambda k: make_index(k, db), calls)
    takes, info = synthetic_takes(feats, args.synthetic, rng)
    cur = rng.integers(0, args.synthetic, 300)
    syn_calls = [(calls[i % len(calls)][0], int(info.clip[c]), float(info.phase[c])) for i, c in enumerate(cur)]
    measure(f"takes ({args.synthetic} frames)", lambda k: make_index(k, takes, info), syn_calls)
    iid = rng.normal(0, 1, (args.synthetic, d)) * feats.std(axis=0) + feats.mean(axis=0)
    measure(f"iid ({args.synthetic} frames)", lambda k: make_index(k, iid, info), syn_calls)

    # ---- real-time factor of the whole runtime (pose blending on)
    results["runtime"] = {}
    for kind in ("kdtree", "bbox"):
        index = make_index(kind, db)
        frames, wall = 0, 0.0
        for p in paths:
            tic = time.perf_counter()
            r = run_path(db, index, p, cfg, with_pose=True)
            wall += time.perf_counter() - tic
            frames += r.num_frames
        results["runtime"][kind] = {
            "frames": frames,
            "seconds": wall,
            "frames_per_s": frames / wall,
            "realtime_factor": frames / wall / db.fps,
        }

    print(
        f"\nquery latency (µs per query, best of {args.repeat}; {len(calls)} recorded runtime queries, "
        f"{len(syn_calls)} on the synthetic sets):"
    )
    print(f"{'database':<24}" + "".join(f"{k + ' wall/cpu':>20}" for k in KINDS) + "   same answers as brute")
    for label, row in results["latency_us"].items():
        same = all(v["same_as_brute"] for v in row.values())
        cells = "".join(f"{row[k]['us_per_query']:>11.1f} /{row[k]['cpu_us_per_query']:>7.1f}" for k in KINDS)
        print(f"{label:<24}{cells}   {same}")
    for kind, rt in results["runtime"].items():
        print(
            f"runtime ({kind}): {rt['frames']} frames in {rt['seconds']:.2f} s = {rt['frames_per_s']:.0f} frames/s "
            f"= {rt['realtime_factor']:.1f}x real time at {db.fps:.0f} Hz (pose inertialization on)"
        )
    best = min(results["latency_us"][f"takes ({args.synthetic} frames)"].items(), key=lambda kv: kv[1]["us_per_query"])
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    results["machine"] = {"cpus": os.cpu_count(), "load_1min": load}
    print(
        f"target (< 100 µs per query at {args.synthetic} frames, 'takes'): best index {best[0]} "
        f"{best[1]['us_per_query']:.1f} µs wall, {best[1]['cpu_us_per_query']:.1f} µs CPU -> "
        f"{'met' if best[1]['us_per_query'] < 100 else 'not met'} in wall time "
        f"(machine: {os.cpu_count()} CPUs, load average {load:.1f})"
    )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2))
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
