"""motion-matching: feature-vector motion matching that follows circle / square / star paths,
and the paper's Table 1 feature study. Declaration only; the work is in the modules:

  config.py           schema (+ the config of a run or of the experiment)
  train.py            builds the feature database into a run (no learning); its checks before the run (preflight)
  evaluate.py         `eval --sweep`: the Table 1 sweep, its tables and plots, report.md
  export.py           one rollout along a path -> BVH / mp4
  cases.py            the Table 1 feature settings
  sources.py          clips (humanoid loops closed + unrolled, or a user's BVH folder)
  database.py         root-local frames, pose/trajectory features, per-block normalisation
  search.py           brute force (reference), scipy cKDTree, bounding boxes
  inertialization.py  critically damped offset decay
  paths.py            circle/square/star/CSV targets and the error metrics
  runtime.py          controller + search loop + root reconstruction
"""

from __future__ import annotations

from charctl.experiments import BVH, FPS, OUT, SECONDS, VIDEO, Experiment, Option

_PKG = "charctl.experiments.motion_matching"

EXPERIMENT = Experiment(
    name="motion-matching",
    summary="feature-vector motion matching along target paths; the Table 1 feature study",
    schema=f"{_PKG}.config:Config",
    train=f"{_PKG}.train:train",
    preflight=f"{_PKG}.train:preflight",
    evaluate=f"{_PKG}.evaluate:evaluate",
    export=f"{_PKG}.export:export",
    eval_options=(Option("sweep", "the Table 1 feature sweep (19 cases x circle, square, star)", mode=True), OUT),
    export_options=(BVH, VIDEO, SECONDS, FPS),
    # no learning: training builds the database; its numbers arrive once, from metrics.json
    tune_metrics={"wall_s": "min", "searchable_frames": "max"},
)
