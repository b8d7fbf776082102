"""scripts/diag_goal_reference.py on the shipped 3-skill policy, whose walk has a full stride: its closest walk
frame moves on along the clip (a shuffle's stays put), and with a window the reference moves 1..w frames a step."""

from __future__ import annotations

import subprocess
import sys

from charctl.experiments.cgail.rollouts import load_eval_run

from conftest import REPO, load_script

RUN = REPO / "pretrained/cgail-3skill-fidelity"


def test_a_full_stride_walk_moves_its_closest_frame_along_the_clip():
    mod = load_script("diag_goal_reference")
    run = load_eval_run(RUN, device="cpu")
    walk = [s.name for s in run.agent.skills].index("walk")
    anywhere = mod.measure(run, walk, envs=4, steps=90, window=0)
    windowed = mod.measure(run, walk, envs=4, steps=90, window=3)
    assert anywhere["advance"] > 0.8  # the shuffle of the radii run: -0.00 (docs/cgail.md)
    assert 1.0 <= windowed["advance"] <= 3.0  # the window's rule: 1..3 frames per step
    assert windowed["pose_ends_per_1k"] == 0.0 and 0.5 < windowed["r_track"] <= 1.0


def test_a_skill_without_a_heading_goal_is_a_one_line_error():
    res = subprocess.run(
        [sys.executable, str(REPO / "scripts/diag_goal_reference.py"), str(RUN), "--skill", "right_kick"],
        capture_output=True,
        text=True,
    )
    assert res.returncode != 0 and "Traceback" not in res.stderr
    assert res.stderr.strip() == "error: skill 'right_kick' has no heading goal (it is scored against its timed frame)"
