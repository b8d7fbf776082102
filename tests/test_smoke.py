"""A smoke training run of every registered experiment through the real CLI (the
lightning-hydra-template pattern): `charctl train NAME scale=smoke` leaves a run directory with
the resolved config, the metrics JSON and a checkpoint or the experiment's artefact."""

from __future__ import annotations

import json

import pytest

from charctl.experiments import EXPERIMENTS, load


@pytest.mark.parametrize("name", list(EXPERIMENTS))
def test_smoke_training_run(smoke_run, name):
    from charctl.checkpoints import load_checkpoint
    from charctl.runs import open_run

    run_dir = smoke_run(name)
    run = open_run(run_dir, load(name).config_class())  # the stored config is resolved and validates
    assert run.experiment == name and run.cfg.scale == "smoke" and "${" not in (run_dir / "config.yaml").read_text()
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["wall_s"] >= 0  # the same key for training time in every experiment
    checkpoint = run_dir / "checkpoints" / "last.pt"
    if checkpoint.is_file():
        assert load_checkpoint(checkpoint, name)  # loads (weights_only) as this experiment's checkpoint
    artefacts = [p for p in run_dir.rglob("*") if p.is_file() and p.name not in ("config.yaml", "metrics.json")]
    assert artefacts, f"{name} wrote no checkpoint or artefact in {run_dir}"
