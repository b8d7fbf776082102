"""cgail: one MuJoCo humanoid policy, many skills switched by a user command.

Declaration only (no torch/mujoco import); the work happens in the submodules, loaded on use.
"""

from __future__ import annotations

from pathlib import Path

from charctl.experiments import (
    AFTER,
    BVH,
    CHECKPOINTS,
    CONFIRM_SEED,
    EPISODES,
    OUT,
    SECONDS,
    SEED,
    VIDEO,
    Experiment,
    Option,
)

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
    preflight=f"{_PKG}.skills:preflight",
    evaluate=f"{_PKG}.evaluate:evaluate",
    export=f"{_PKG}.export:export",
    play=f"{_PKG}.export:play",
    checkpoints=f"{_PKG}.eval_checkpoints:checkpoints",
    eval_options=(
        Option("dtw", "DTW pose error against the reference clips (Table 6.1)", mode=True),
        Option("confusion", "classifier confusion matrix (Fig 6.8)", mode=True),
        Option("switch", "command switch study A -> B (Fig 6.10/6.11)", str, nargs=2, mode=True),
        Option(
            "switch_matrix",
            "the switch study with the ramp for every ordered pair of the run's skills: one table and a picture",
            mode=True,
        ),
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
        Option(
            CHECKPOINTS.name,
            CHECKPOINTS.help + "; per checkpoint: no-fall over -k (default 64) episodes of --survival SECONDS "
            "(default 5) per skill, the Fig 6.8 diagonal (not for an AMP run) and, with --fidelity or --rank "
            "fidelity, fidelity; picks one by --rank and evaluates it again on fresh starts",
            mode=True,
        ),
        Option(
            "rank",
            "with --checkpoints: fidelity (default: the most skills at pose coverage >= --min-coverage with their "
            "named signature (kick foot peak, jump flight, spin yaw rate) within 30 % of the clip's, then the "
            "largest lowest coverage, the worst no-fall, the lowest diagonal; implies --fidelity) or margin (the "
            "largest margin over both targets)",
            str,
            metavar="fidelity|margin",
            requires="checkpoints",
        ),
        Option(
            "confusion_k",
            "with --checkpoints: episodes per skill for the Fig 6.8 diagonal (default 16)",
            int,
            requires="checkpoints",
        ),
        Option(
            "fidelity_k", "with --checkpoints: episodes per skill for fidelity (default 4)", int, requires="checkpoints"
        ),
        Option("min_no_fall", "with --checkpoints: the no-fall target (default 0.8)", float, requires="checkpoints"),
        Option(
            "min_coverage",
            "with --checkpoints --rank fidelity: the pose coverage a skill must reach to count (default 0.5)",
            float,
            requires="checkpoints",
        ),
        Option("min_diagonal", "with --checkpoints: the diagonal target (default 0.9)", float, requires="checkpoints"),
        AFTER,
        SEED,
        CONFIRM_SEED,
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
