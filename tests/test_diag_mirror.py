"""scripts/diag_mirror.py: the mirror loss of a policy on its mirrored pairs, and its one-line errors."""

from __future__ import annotations

from conftest import REPO, script_in_process

TEN = REPO / "pretrained/cgail-10skill-track-skills"


def test_the_shipped_ten_skill_policy_is_measured_on_its_four_paired_skills():
    res = script_in_process("diag_mirror", str(TEN), "--envs", "2", "--steps", "10")
    assert res.returncode == 0, res.stderr
    rows = {line.split()[0]: [float(x) for x in line.split()[1:]] for line in res.stdout.splitlines()[2:]}
    assert sorted(rows) == ["left_kick", "left_punch", "right_kick", "right_punch"]
    for loss, scale in rows.values():  # trained without the mirror loss: not symmetric, but far from random
        assert 0.001 < loss < scale


def test_a_run_without_mirrored_pairs_is_a_one_line_error():
    run = REPO / "pretrained/cgail-3skill-fidelity"
    res = script_in_process("diag_mirror", str(run), "--steps", "5")
    assert res.returncode == 1 and res.stderr.strip() == f"error: {run} has no skills whose clips mirror each other"
    res = script_in_process("diag_mirror", str(run), "--envs", "0")
    assert res.returncode == 1 and res.stderr.strip() == "error: --envs and --steps must be >= 1"
