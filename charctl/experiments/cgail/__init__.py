"""cgail: one MuJoCo humanoid policy, many skills switched by a user command.

Declaration only (no torch/mujoco import); the work happens in the submodules, loaded on use.
"""

from __future__ import annotations

from pathlib import Path

from charctl.experiments import BVH, EPISODES, OUT, SECONDS, VIDEO, Experiment, Option

_PKG = "charctl.experiments.cgail"
CHECKPOINT = Option(
    "checkpoint",
    "file in RUN/checkpoints/ to use instead of last.pt (e.g. samples_020000000.pt, train.keep_checkpoint_every)",
    str,
    metavar="FILE",
)

EXPERIMENT = Experiment(
    name="cgail",
    summary="conditional adversarial imitation: one humanoid policy, skills switched by command",
    schema=f"{_PKG}.config:Config",
    train=f"{_PKG}.train:train",
    evaluate=f"{_PKG}.evaluate:evaluate",
    export=f"{_PKG}.export:export",
    play=f"{_PKG}.export:play",
    eval_options=(
        Option("dtw", "DTW pose error against the reference clips (Table 6.1)", mode=True),
        Option("confusion", "classifier confusion matrix (Fig 6.8)", mode=True),
        Option("switch", "command switch study A -> B (Fig 6.10/6.11)", str, nargs=2, mode=True),
        Option("curves", "training-curve figures from TensorBoard logs", mode=True),
        Option(
            "survival", "share of SECONDS-long episodes without a fall, per skill", float, mode=True, metavar="SECONDS"
        ),
        Option(
            "fidelity",
            "per skill against its clip: DTW body-position error, pose coverage, foot/hand peaks, airborne share, "
            "speed, yaw rate, filmstrip",
            mode=True,
        ),
        EPISODES,
        OUT,
        CHECKPOINT,
    ),
    export_options=(
        Option("onnx", "export the policy (normaliser built in) as ONNX", Path),
        Option("torchscript", "export the policy as TorchScript", Path),
        BVH,
        VIDEO,
        Option("commands", 'command schedule, e.g. "walk:0,run:3,kick:6" (seconds)', str),
        SECONDS,
        CHECKPOINT,
        Option(
            "web",
            "write the interactive web demo into DIR: a static site (MuJoCo wasm + onnxruntime-web, docs/web.md)",
            Path,
            metavar="DIR",
        ),
        Option("serve", "with --web: also serve the site on a local port and print its address (Ctrl-C stops)"),
    ),
    provides={"push_rollout": f"{_PKG}.push"},
    tune_metrics={"train/episode_length": "max", "train/r_style": "max"},  # steps before a fall; style reward r_S
)
