"""srb: single-rigid-body walker driven by a QP contact-force tracker and a PPO policy.

Declaration only (no torch/mujoco import); the work happens in the submodules, loaded on use.
"""

from __future__ import annotations

from charctl.experiments import EPISODES, OUT, SECONDS, VIDEO, Experiment, Option

_PKG = "charctl.experiments.srb"

EXPERIMENT = Experiment(
    name="srb",
    summary="single rigid body + QP contact-force tracker + PPO; push-robustness study",
    schema=f"{_PKG}.config:Config",
    train=f"{_PKG}.train:train",
    preflight=f"{_PKG}.env:preflight",
    evaluate=f"{_PKG}.evaluate:evaluate",
    export=f"{_PKG}.export:export",
    eval_options=(
        Option("push", "push-robustness study (paper §9, Table 1); a second run = the full-body baseline", mode=True),
        EPISODES,
        OUT,
    ),
    export_options=(VIDEO, SECONDS),
    eval_accepts=("push_rollout",),
    tune_metrics={"rollout/episode_length": "max", "rollout/episode_return": "max"},  # survival: steps before a fall
)
