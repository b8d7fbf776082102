"""scripts/diag_terminations.py splits the pose check's ends by cause: with one radius made tiny and the others
huge or off, every end is put down to that radius (hand-derived: a radius no pose can meet ends every checked
step, so episodes last about one step), and falls are not counted as pose ends."""

from __future__ import annotations

import pytest

from charctl.experiments.cgail.rollouts import load_eval_run

from conftest import REPO, load_script, script_in_process

RUN = REPO / "pretrained/cgail-3skill-fidelity"


@pytest.mark.parametrize(
    ("radii", "cause"),
    [
        ((0.02, 0.0, 0.0), "effector"),  # 2 cm: no policy's hands and feet are that close to the clip's
        ((10.0, 0.001, 0.0), "root"),  # effectors never off by 10 m; the root always off by 1 mm
        ((10.0, 0.0, 1e-4), "heading"),  # the kick turns (2.7 rad/s in its clip): 1e-4 rad is passed at once
    ],
)
def test_each_cause_is_counted_for_its_own_radius(radii, cause):
    mod = load_script("diag_terminations")
    run = load_eval_run(RUN, device="cpu")
    r = run.cfg.reward
    r.pose_error_threshold, r.root_height_threshold, r.yaw_error_threshold = radii
    kick = [s.name for s in run.agent.skills].index("right_kick")
    m = mod.measure(run, kick, envs=4, steps=40)
    assert m[cause] > 100.0  # ends per 1000 steps
    assert all(m[c] == 0.0 for c in ("fall", "effector", "root", "heading") if c != cause)
    assert m["len"] < 3.0
    assert (m["worst"] != "-") == (cause == "effector")


@pytest.mark.parametrize(
    ("script", "option"), [("diag_terminations", "--skills"), ("diag_switch", "--to"), ("diag_kick_start", "--skill")]
)
def test_an_unknown_skill_is_a_one_line_error(script, option):
    """The diagnostics that replay a run's skills name the run's skills for a wrong one."""
    res = script_in_process(script, str(RUN), option, "kick")
    assert res.returncode != 0 and "Traceback" not in res.stderr
    assert res.stderr.strip() == f"error: unknown skill 'kick' for {RUN}; its skills are walk, run, right_kick"
