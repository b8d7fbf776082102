"""cgail: one MuJoCo humanoid policy, many skills switched by a user command (SPEC §1).

Light entry points only; the work happens in the submodules (imported on use).
"""

from __future__ import annotations


def schema() -> type:
    from charctl.experiments.cgail.config import Config

    return Config


def train(cfg, run) -> dict:
    from charctl.experiments.cgail.train import train as _train

    return _train(cfg, run)


def evaluate(targets, options, overrides) -> None:
    from charctl.experiments.cgail.evaluate import evaluate as _evaluate

    _evaluate(targets, options, overrides)


def export(target, options, overrides) -> None:
    from charctl.experiments.cgail.export import export as _export

    _export(target, options, overrides)


def play(run_dir) -> None:
    from charctl.experiments.cgail.export import play as _play

    _play(run_dir)
