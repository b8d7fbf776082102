"""scripts/diag_track_parts.py: the per-part errors by hand, and on the shipped three-skill policy what holds by
construction."""

from __future__ import annotations

import numpy as np

from charctl.experiments.cgail.rollouts import load_eval_run

from conftest import REPO, load_script


def test_part_errors_by_hand():
    mod = load_script("diag_track_parts")
    from charctl.experiments.cgail import rules

    obs, ref = np.zeros((1, 133)), np.zeros((1, 133))
    obs[0, rules.OBS_ROT.start + 3 * 6 + 1] = 2.0  # joint 3, the right knee: right leg 4
    obs[0, rules.OBS_ROT.start + 11 * 6] = 0.5  # joint 11, the left elbow: left arm 0.25
    obs[0, rules.OBS_EE.start + 3 * 3 + 1] = 0.3  # effector 3, the left hand, 0.3 m up
    parts, ee = mod.part_errors(obs, ref)
    np.testing.assert_allclose(parts, [[0.0, 4.0, 0.0, 0.0, 0.25]])
    np.testing.assert_allclose(ee, [[0.0, 0.0, 0.0, 0.3]])


def test_one_pass_of_the_three_skill_kick():
    """The parts add up to the whole rot6 error (every clip joint in one part), which the pose term of r_track
    sees: r_track <= 0.35 + 0.65 exp(-sum) (the other terms are at most 0.35)."""
    mod = load_script("diag_track_parts")
    run = load_eval_run(REPO / "pretrained/cgail-3skill-fidelity", device="cpu")
    out = mod.one_pass(run, run.skill_index("right_kick"))
    n = len(run.agent.skills[run.skill_index("right_kick")].obs) - 1
    assert out["parts"].shape == (n, 5) and out["alive"].all()
    assert sum(len(v) for v in mod.PARTS.values()) == 12
    assert (out["r_track"] > 0).all()
    assert (out["r_track"] <= 0.35 + 0.65 * np.exp(-out["parts"].sum(axis=1)) + 1e-9).all()
