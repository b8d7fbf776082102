"""hopper-ga (Kang 1999): running from a planar two-leg spring hopper, an upper-body balance
model and a genetic algorithm that trades smoothness against energy per distance with the
briskness beta. Declaration only; numpy/DEAP/matplotlib load inside the submodules.

    charctl train hopper-ga speed=5 beta=0.5 [runtime.kind=local|process|ray] [scale=smoke|small|paper]
    charctl eval RUN... --curves [-o DIR]          figures + the comparison table (report.md with -o)
    charctl eval RUN --checkpoints [--after N]     every kept checkpoint ranked by its best individual's fitness
    charctl export RUN --bvh run.bvh --video run.mp4 [--seconds 3] [--fps 60]
"""

from __future__ import annotations

from charctl.experiments import AFTER, BVH, CHECKPOINTS, FPS, OUT, SECONDS, VIDEO, Experiment, Option

_PKG = "charctl.experiments.hopper_ga"

EXPERIMENT = Experiment(
    name="hopper-ga",
    summary="spring hopper + balance model + genetic algorithm for running (energy vs briskness)",
    schema=f"{_PKG}.config:Config",
    train=f"{_PKG}.train:train",
    evaluate=f"{_PKG}.evaluate:evaluate",
    export=f"{_PKG}.export:export",
    checkpoints=f"{_PKG}.eval_checkpoints:checkpoints",
    eval_options=(
        Option("curves", "re-draw each run's figures and compare the runs (report.md with -o)", mode=True),
        OUT,
        Option(
            CHECKPOINTS.name,
            CHECKPOINTS.help + "; per checkpoint: its best genome's fitness (eq 14), re-evaluated; the lowest wins",
            mode=True,
        ),
        AFTER,
    ),
    export_options=(BVH, VIDEO, SECONDS, FPS),
    tune_metrics={"fitness/best_so_far": "min", "fitness/mean": "min"},  # the GA minimises its evaluation (best so far)
)
