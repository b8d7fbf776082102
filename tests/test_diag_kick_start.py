"""scripts/diag_kick_start.py: the start-state change by hand, and on the shipped three-skill policy the per-pass
table against what holds by construction (a frame-0 RSI is 0 m from frame 0; the unchanged start's first pass is
pass 1 itself, the policy and physics being deterministic)."""

from __future__ import annotations

import numpy as np

from charctl.experiments.cgail.rollouts import load_eval_run

from conftest import REPO, load_script

RUN = REPO / "pretrained/cgail-3skill-fidelity"


def test_perturbed_start_keeps_the_root_adds_hinge_noise_and_scales_velocities():
    mod = load_script("diag_kick_start")
    qpos = np.arange(10, dtype=float)  # root 0..6, three hinges 7, 8, 9
    qvel = np.array([1.0, -2.0, 4.0])
    q, v = mod.perturbed_start(qpos, qvel, 0.1, 0.5, np.random.default_rng(3))
    expected_noise = np.random.default_rng(3).normal(0.0, 0.1, 3)
    np.testing.assert_array_equal(q[:7], qpos[:7])
    np.testing.assert_allclose(q[7:], qpos[7:] + expected_noise)
    np.testing.assert_array_equal(v, [0.5, -1.0, 2.0])
    assert qpos[7] == 7.0  # the caller's arrays are not changed
    q, v = mod.perturbed_start(qpos, qvel, 0.0, 0.0, np.random.default_rng(3))
    np.testing.assert_array_equal(q, qpos)
    np.testing.assert_array_equal(v, [0.0, 0.0, 0.0])


def test_the_three_skill_kick_is_done_on_its_first_pass_from_the_clip_state():
    mod = load_script("diag_kick_start")
    run = load_eval_run(RUN, device="cpu")
    k = run.skill_index("right_kick")
    out = mod.passes(run, k, envs=2, n_passes=2)
    assert len(out) == 2
    np.testing.assert_allclose(out[0]["distance"], 0.0, atol=1e-9)
    assert (out[1]["distance"] > 0.05).all()  # the policy's own guard is not the clip's frame 0
    clip = mod.clip_foot_peak(run.agent.skills[k])
    assert 1.0 < clip < 1.5  # the kick clip's foot, 1.28 m (docs/cgail.md)
    assert (out[0]["foot_peak"] >= mod.PERFORM_SHARE * clip).all() and out[0]["alive"].all()
    label, peak, alive = mod.start_sensitivity(run, k, envs=2)[0]
    assert label == "as recorded" and alive.all()
    np.testing.assert_allclose(peak, out[0]["foot_peak"], atol=1e-9)
