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
