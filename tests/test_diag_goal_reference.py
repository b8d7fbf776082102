"""scripts/diag_goal_reference.py on the shipped 3-skill policy, whose walk has a full stride: its closest walk
frame moves on along the clip (a shuffle's stays put), and with a window the reference moves 1..w frames a step."""

from __future__ import annotations

import pytest

from charctl.experiments.cgail.rollouts import load_eval_run

from conftest import REPO, load_script, script_in_process

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


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--skill", "right_kick"],
            "error: skill 'right_kick' has no heading goal (it is scored against its timed frame)",
        ),
        (["--skill", "kick"], f"error: unknown skill 'kick' for {RUN}; its skills are walk, run, right_kick"),
        (["--window", "0"], "error: --envs, --steps and --window must be >= 1"),
    ],
)
def test_bad_arguments_are_one_line_errors(args, message):
    res = script_in_process("diag_goal_reference", str(RUN), *args)
    assert res.returncode != 0 and "Traceback" not in res.stderr
    assert res.stderr.strip() == message
