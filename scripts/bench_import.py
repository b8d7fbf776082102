"""Speed of `charctl data import` and the PD-tracking reference of its report.

    .venv/bin/python scripts/bench_import.py [FILE.bvh ...] [--repeat 3] [--fps 60]
    .venv/bin/python scripts/bench_import.py --reference

Default: every BVH file under tests/data/ (or the files given) retargeted `--repeat` times, after one
warm-up import (it pays the one-off imports of mink and MuJoCo and the model build); prints, per file,
the source frames read per second of wall time (the issue's target: >= 1,000 frames/s), the clip
frames written per second, the time per stage, and how many frames mink refined.

`--reference`: the PD tracking error (charctl.sim.tracking.track_clip_with_noise with the report's
settings, charctl.motion.import_report.TRACKING) of every shipped DeepMimic clip, and their median,
the number the report compares an imported clip against (DEEPMIMIC_TRACKING_MEDIAN).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def bench(files: list[Path], repeat: int, fps: float) -> None:
    from charctl.motion.retarget import retarget

    retarget(files[0], fps=fps)  # warm-up: mink / mujoco imports, model compile
    print(
        f"{'file':28} {'skeleton':9} {'src frames':>10} {'clip frames':>11} {'s/import':>9} {'src frames/s':>12} "
        f"{'clip frames/s':>13} {'mink frames':>11}  stages (s)"
    )
    total_src, total_s = 0, 0.0
    for f in files:
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            r = retarget(f, fps=fps)
            times.append(time.perf_counter() - t0)
        s = statistics.median(times)
        n_src = r.source.frames_in_file
        total_src += n_src
        total_s += s
        stages = " ".join(f"{k} {v:.3f}" for k, v in r.timings.items())
        print(
            f"{f.name:28} {r.source.jmap.name:9} {n_src:10d} {r.clip.num_frames:11d} {s:9.3f} {n_src / s:12,.0f} "
            f"{r.clip.num_frames / s:13,.0f} {r.refined_frames:11d}  {stages}"
        )
    print(f"all files: {total_src} source frames in {total_s:.3f} s = {total_src / total_s:,.0f} frames/s")


def reference() -> None:
    from charctl.motion.import_report import TRACKING, deepmimic_reference

    t0 = time.perf_counter()
    errs = deepmimic_reference()
    for name, e in sorted(errs.items(), key=lambda kv: kv[1]):
        print(f"{name:22} {e:.4f} rad")
    print(
        f"median over {len(errs)} clips: {statistics.median(errs.values()):.4f} rad "
        f"(settings {TRACKING}; {time.perf_counter() - t0:.0f} s)"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("files", nargs="*", type=Path)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--fps", type=float, default=60.0)
    ap.add_argument("--reference", action="store_true")
    a = ap.parse_args()
    if a.reference:
        return reference()
    files = a.files or sorted((REPO / "tests" / "data").glob("*.bvh"))
    bench(files, a.repeat, a.fps)


if __name__ == "__main__":
    main()
