"""Wall time of one 4-job smoke multirun, one job after another (`--launcher basic`) vs side by side on
Ray (`--launcher ray`, a local Ray instance started by the command, so its start-up is counted).

    .venv/bin/python scripts/bench_launcher.py [--experiment hopper-ga] [--sweep seed=0,1,2,3]
        [--extra ga.generations=600] [--address ADDR] [--out outputs/bench-launcher]

Both runs go through the real CLI (`charctl train EXP scale=smoke -m SWEEP EXTRA ...`) as a user types
it, into their own output folders; the script prints both wall times and their ratio. On a 2-core
machine the gain is bounded by 2x, less Ray's start (~5-10 s) and one interpreter per job.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def run(cmd: list[str]) -> float:
    """Wall seconds of one CLI command (its output hidden unless it fails)."""
    t0 = time.perf_counter()
    res = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        sys.exit(f"failed ({res.returncode}): {' '.join(cmd)}\n{res.stdout[-2000:]}\n{res.stderr[-2000:]}")
    return wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--experiment", default="hopper-ga")
    ap.add_argument("--sweep", default="seed=0,1,2,3", help="the -m sweep (4 jobs by default)")
    ap.add_argument("--extra", nargs="*", default=["ga.generations=600"], help="further overrides of every job")
    ap.add_argument("--address", default="", help="a Ray cluster to use instead of a local instance")
    ap.add_argument("--out", default="outputs/bench-launcher")
    args = ap.parse_args()
    out = Path(args.out)
    shutil.rmtree(out, ignore_errors=True)
    charctl = [sys.executable, "-c", "from charctl.cli import main; main()"]
    base = [*charctl, "train", args.experiment, "scale=smoke", *args.extra, "-m", args.sweep]
    seq = run([*base, f"output_root={out / 'basic'}"])
    ray_cmd = [*base, f"output_root={out / 'ray'}", "--launcher", "ray"]
    ray_cmd += ["--address", args.address] if args.address else []
    par = run(ray_cmd)
    jobs = len(list((out / "ray" / args.experiment).glob("*")))
    print(f"{args.experiment} scale=smoke {' '.join(args.extra)} -m {args.sweep} ({jobs} jobs)")
    print(f"  --launcher basic  {seq:7.1f} s")
    print(f"  --launcher ray    {par:7.1f} s")
    print(f"  ratio basic/ray   {seq / par:7.2f}x")


if __name__ == "__main__":
    main()
