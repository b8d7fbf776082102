"""srb: single-rigid-body walker driven by a QP contact-force tracker and a PPO policy (SPEC §2).

Light entry points only; the work happens in the submodules (imported on use).
"""

from __future__ import annotations


def schema() -> type:
    from charctl.experiments.srb.config import Config

    return Config


def train(cfg, run) -> dict:
    from charctl.experiments.srb.trainer import train as _train

    return _train(cfg, run)


def evaluate(targets, options, overrides) -> None:
    from charctl.experiments.srb.study import evaluate as _evaluate

    _evaluate(targets, options, overrides)


def export(target, options, overrides) -> None:
    from charctl.experiments.srb.study import export as _export

    _export(target, options, overrides)
