"""Every shipped policy still computes what it computed when it was shipped: its policy states on fixed
clip frames (features), its mean actions there (normaliser and networks) and the states 10 control
steps later (physics). A change that keeps every shape but moves any of these fails here."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from charctl.experiments.cgail.pins import PIN_FILE, compute_pins

PRETRAINED = Path(__file__).resolve().parents[1] / "pretrained"
FOLDERS = sorted(p.parent for p in PRETRAINED.glob(f"*/{PIN_FILE}"))


def test_every_shipped_policy_has_a_pin():
    shipped = sorted(p.parent.parent for p in PRETRAINED.glob("*/checkpoints/last.pt"))
    assert shipped and shipped == FOLDERS, "run scripts/pin_pretrained.py on every pretrained/ folder"


@pytest.mark.parametrize("folder", FOLDERS, ids=[f.name for f in FOLDERS])
def test_shipped_policy_matches_its_pin(folder):
    want = np.load(folder / PIN_FILE)
    got = compute_pins(folder)
    assert got["skills"].tolist() == want["skills"].tolist()
    np.testing.assert_allclose(got["state0"], want["state0"], atol=1e-6, err_msg="features changed")
    np.testing.assert_allclose(got["action0"], want["action0"], atol=1e-5, err_msg="policy output changed")
    # 10 control steps of physics: allow round-off to grow, not a changed model
    np.testing.assert_allclose(got["state_after"], want["state_after"], atol=1e-4, err_msg="rollout changed")


RUN_FOLDERS = sorted(p.parent for p in PRETRAINED.glob("**/metrics.json") if (p.parent / "config.yaml").is_file())


@pytest.mark.parametrize("folder", RUN_FOLDERS, ids=[str(f.relative_to(PRETRAINED)) for f in RUN_FOLDERS])
def test_committed_config_records_the_runs_own_budget(folder):
    """A committed run's config.yaml is the one it trained with: its budget covers the samples it reached
    (a harness that resumed the folder in place once overwrote it with a smoke budget)."""
    import json

    import yaml

    samples = json.loads((folder / "metrics.json").read_text()).get("samples")
    cfg = yaml.safe_load((folder / "config.yaml").read_text())
    budget = cfg.get("train", {}).get("total_samples")
    if samples is None or budget is None:
        pytest.skip("not a sample-budgeted run")
    iteration = cfg["env"]["num_envs"] * cfg["train"]["rollout_steps"]  # the last iteration may overshoot
    assert budget > samples - iteration, f"{folder.name}: config.yaml's total_samples={budget}, its run {samples}"
