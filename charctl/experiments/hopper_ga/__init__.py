"""hopper-ga (SPEC §5, Kang 1999): running from a planar two-leg spring hopper, an upper-body
balance model and a genetic algorithm that trades smoothness against energy per distance with
the briskness beta. Light entry points only; numpy/DEAP/matplotlib load inside the functions.

    charctl train hopper-ga speed=5 beta=0.5 [runtime.kind=local|process|ray] [scale=smoke|small|paper]
    charctl eval RUN... --curves [-o DIR]          figures + the comparison table (report.md with -o)
    charctl export RUN --bvh run.bvh --video run.mp4 [--seconds 3] [--fps 60]
"""

from __future__ import annotations

from pathlib import Path

from charctl.errors import CharctlError

NAME = "hopper-ga"


def schema() -> type:
    from charctl.experiments.hopper_ga.config import Config

    return Config


def train(cfg, run) -> dict:
    from charctl.experiments.hopper_ga.train import train as _train

    return _train(cfg, run)


def _run_dirs(targets: list[str]) -> list[Path]:
    from charctl.runs import latest_run

    dirs = []
    for t in targets:
        if t == NAME:
            dirs.append(latest_run("outputs", NAME))
        else:
            p = Path(t)
            runs = sorted(q.parent for q in p.glob("*/config.yaml")) if not (p / "config.yaml").is_file() else [p]
            if not runs:
                raise CharctlError(f"{t} is not a hopper-ga run directory (nor a folder of runs)")
            dirs += runs
    return dirs


def evaluate(targets: list[str], options: dict, overrides: list[str]) -> None:
    """`--curves`: re-draw each run's figures and print the comparison table; with `-o DIR` also
    write DIR/report.md with the table and the figures."""
    from charctl.experiments import unsupported_options
    from charctl.experiments.hopper_ga.report import build_report

    unsupported_options(NAME, options, {"curves", "out"})
    build_report(_run_dirs(targets), options.get("out"), overrides)


def export(target: str, options: dict, overrides: list[str]) -> None:
    """`--bvh FILE` / `--video FILE` of the best genome's running motion (`--seconds`, `--fps`)."""
    from charctl.experiments import unsupported_options
    from charctl.experiments.hopper_ga.report import export_run

    unsupported_options(NAME, options, {"bvh", "video", "seconds", "fps"})
    if not options.get("bvh") and not options.get("video"):
        raise CharctlError("say what to export: --bvh FILE.bvh and/or --video FILE.mp4")
    (run_dir,) = _run_dirs([target])[-1:]
    export_run(run_dir, options, overrides)
