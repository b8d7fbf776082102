"""com-cnn: full-body motion generated from the centre-of-mass path (SPEC §3; Park, Sohn, Lee 2020).

Light entry points only: torch and the motion code are imported inside the functions.
    charctl train com-cnn [overrides]                 train (paper §3.4)
    charctl eval RUN... --pose-error [--dtw]          Table 5 style errors, autoregressive curve, baselines
    charctl export RUN --com-path FILE|circle:... --bvh OUT.bvh --video OUT.mp4
"""

from __future__ import annotations

EVAL_OPTIONS = {"pose_error", "dtw", "out"}
EXPORT_OPTIONS = {"com_path", "crouch_at", "bvh", "video", "seconds"}


def schema():
    from charctl.experiments.com_cnn.config import Config

    return Config


def train(cfg, run) -> dict:
    from charctl.experiments.com_cnn.train import train as _train

    return _train(cfg, run)


def evaluate(targets, options, overrides) -> None:
    from charctl.experiments import unsupported_options
    from charctl.experiments.com_cnn.evaluate import evaluate_command

    unsupported_options("com-cnn", options, EVAL_OPTIONS)
    evaluate_command(targets, options, overrides)


def export(target, options, overrides) -> None:
    from charctl.experiments import unsupported_options
    from charctl.experiments.com_cnn.generate import export_command

    unsupported_options("com-cnn", options, EXPORT_OPTIONS)
    export_command(target, options, overrides)
