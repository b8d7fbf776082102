"""motion-matching: feature-vector motion matching that follows circle / square / star paths,
and the paper's Table 1 feature study (SPEC §4). Light entry points; the work is in the modules:

  sources.py          clips (humanoid loops closed + unrolled, or a user's BVH folder)
  database.py         root-local frames, pose/trajectory features, per-block normalisation
  search.py           brute force (reference), scipy cKDTree, bounding boxes
  inertialization.py  critically damped offset decay
  paths.py            circle/square/star/CSV targets and the error metrics
  runtime.py          controller + search loop + root reconstruction
  study.py            Table 1 cases, the sweep, tables and plots
  app.py              train / eval --sweep / export
"""

from __future__ import annotations


def schema() -> type:
    from charctl.experiments.motion_matching.config import Config

    return Config


def train(cfg, run) -> dict:
    """No learning in motion matching: builds the database and stores it in the run."""
    from charctl.experiments.motion_matching.app import train as _train

    return _train(cfg, run)


def evaluate(targets: list[str], options: dict, overrides: list[str]) -> None:
    """`charctl eval motion-matching --sweep [overrides] [-o DIR]`."""
    from charctl.experiments.motion_matching.app import evaluate as _evaluate

    _evaluate(targets, options, overrides)


def export(target: str, options: dict, overrides: list[str]) -> None:
    """`charctl export motion-matching path=star [case=best] --bvh F --video F [--seconds S] [--fps F]`."""
    from charctl.experiments.motion_matching.app import export as _export

    _export(target, options, overrides)
