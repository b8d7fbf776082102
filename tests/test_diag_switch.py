"""scripts/diag_switch.py times a switched episode's ends under the training rules. Hand-derived: with a radius no
pose can meet (2 cm) and the switch at the reset, the pose check is off for the whole ramp (R steps: the reference
is suspended at the switch and restarts at frame 0 at the end of the step where w reaches 1, step R - 1) and then
for the G grace steps (counted down one per step from the next step on), so every env ends on the first checked
step, step R + G - 1 — one step before ramp_end + G — and none by a fall. (Its one-line error for an unknown skill is
tested with diag_terminations', in tests/test_diag_terminations.py.)"""

from __future__ import annotations

import numpy as np

from charctl.experiments.cgail.rollouts import load_eval_run

from conftest import REPO, load_script

RUN = REPO / "pretrained/cgail-3skill-fidelity"


def test_a_radius_no_pose_meets_ends_every_env_on_the_first_checked_step_after_the_ramp():
    mod = load_script("diag_switch")
    run = load_eval_run(RUN, device="cpu")
    run.cfg.reward.pose_error_threshold = 0.02
    names = [s.name for s in run.agent.skills]
    ramp = int(run.cfg.env.ramp_frames)
    m = mod.measure(run, names.index("walk"), names.index("right_kick"), envs=4, switch_step=0, steps=ramp + 30)
    assert m["ramp_end"] == ramp
    assert m["pose_end"].all()
    np.testing.assert_array_equal(m["end_step"], ramp + m["grace"] - 1)
