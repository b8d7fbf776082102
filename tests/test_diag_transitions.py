"""scripts/diag_transitions.py: the per-second reductions by hand values, and on the shipped three-skill policy a
walk -> right_kick rollout whose kick rises to the clip's height after the ramp while the walk stays low."""

from __future__ import annotations

import numpy as np

from conftest import REPO, load_script, script_in_process

RUN = REPO / "pretrained/cgail-3skill-fidelity"


def test_per_second_reduces_whole_seconds_and_drops_the_rest():
    mod = load_script("diag_transitions")
    values = np.array([1.0, 3.0, 2.0, 0.0, 5.0, 4.0, 9.0])  # 3 frames a second: two whole seconds and one frame
    np.testing.assert_array_equal(mod.per_second(values, 3.0), [3.0, 5.0])
    np.testing.assert_array_equal(mod.per_second(values, 3.0, np.min), [1.0, 0.0])


def test_horizontal_speed_ignores_height_and_counts_second_to_second():
    mod = load_script("diag_transitions")
    hz, t = 4.0, np.arange(9) / 4.0  # two seconds at 4 frames a second, and the frame that closes the second
    qpos = np.zeros((9, 10))
    qpos[:, 0] = 3.0 * t  # x at 3 m/s
    qpos[:, 2] = 4.0 * t * (t <= 1.0) + 4.0 * (t > 1.0)  # z at 4 m/s for the first second, then still
    qpos[:, 1] = 0.9 + np.sin(t)  # height moves: not counted
    np.testing.assert_allclose(mod.horizontal_speed(qpos, hz), [5.0, 3.0])


def test_walk_to_kick_on_the_shipped_policy():
    from charctl.experiments.cgail.policy import load_trained_run

    mod = load_script("diag_transitions")
    tr = load_trained_run(RUN)
    names = tr.skill_names
    res = mod.transition(tr, names.index("walk"), names.index("right_kick"), 1.0, 4.0)
    assert res["falls"] == 0 and len(res["foot"]) == len(res["speed"]) == 4
    assert res["foot"][0] < 0.5 and 0.8 < res["speed"][0] < 1.8  # still walking while the ramp starts
    assert res["foot"][2:].max() > 1.0  # the kick after the 2-s ramp (clip 1.28 m)


def test_a_pair_of_unknown_skills_is_one_line_and_exit_2():
    out = script_in_process("diag_transitions", str(RUN), "--pairs", "walk:fly")
    assert out.returncode == 2 and "not: walk:fly" in out.stderr and "Traceback" not in out.stderr
