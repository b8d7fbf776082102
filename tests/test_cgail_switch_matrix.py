"""`charctl eval RUN --switch-matrix`: the locomotion rule of `performed_after_switch` by hand-built motion, the
last-second speed by hand values, the batched rollout of every pair against one rollout per pair, and the matrix on
the shipped three-skill policy beside the single `--switch` study it extends (a longer window)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from conftest import REPO

RUN = REPO / "pretrained/cgail-3skill-fidelity"


def test_last_second_speed_is_the_path_length_over_the_last_second():
    from charctl.experiments.cgail.metrics import last_second_speed

    hz, t = 4.0, np.arange(9) / 4.0  # 2 s at 4 frames a second
    root = np.zeros((9, 2, 3))
    root[:, 0, 0] = 2.0 * t  # trial 0: x at 2 m/s throughout
    root[:, 1, 2] = np.where(t <= 1.0, 3.0 * t, 3.0)  # trial 1: z at 3 m/s, then still for the last second
    root[:, :, 1] = 0.9 + 0.1 * np.sin(8 * t)[:, None]  # height moves: not counted
    np.testing.assert_allclose(last_second_speed(root, hz), [2.0, 0.0], atol=1e-12)


def test_a_walk_is_done_at_its_clip_speed_not_standing_and_not_running():
    """Three trials after a switch to walk: the root at the walk clip's mean speed (done), standing (not), at three
    times that speed (not); the heading-goal rule measures speed, not the feet."""
    from charctl.experiments.cgail.config import SkillConfig
    from charctl.experiments.cgail.fidelity import clip_reference
    from charctl.experiments.cgail.metrics import PERFORM_SPEED_RANGE, performed_after_switch
    from charctl.experiments.cgail.skills import load_skills

    walk = load_skills([SkillConfig("walk", "walk", heading_goal=True)], 30.0)[0]
    ref = clip_reference(walk)
    hz, F = 30.0, 61
    tr = SimpleNamespace(agent=SimpleNamespace(skills=[walk]), cfg=SimpleNamespace(env=SimpleNamespace(control_hz=hz)))
    t = np.arange(F) / hz
    pos = np.repeat(ref.body_pos[:1, None], F, 0).repeat(3, 1)  # (F, 3, 15, 3) the clip's first pose, held
    for trial, v in enumerate((walk.mean_speed, 0.0, 3.0 * walk.mean_speed)):
        pos[:, trial, :, 0] += (v * t)[:, None]  # every body carried along x at v
    rot = np.repeat(ref.body_rot[:1, None], F, 0).repeat(3, 1)
    out = performed_after_switch(tr, 0, pos, rot, np.ones((F + 5, 3), dtype=bool), t_switch=5)
    assert out["rule"] == "speed" and out["clip_speed"] == pytest.approx(walk.mean_speed)
    np.testing.assert_allclose(out["speed"], [walk.mean_speed, 0.0, 3.0 * walk.mean_speed], rtol=1e-9)
    assert PERFORM_SPEED_RANGE[0] < 1.0 < PERFORM_SPEED_RANGE[1] < 3.0 and out["performed"] == 1


def test_the_matrix_extends_the_switch_study_on_the_shipped_policy(tmp_path):
    import json

    from charctl.commands.evaluate import eval_command

    single, matrix = tmp_path / "single", tmp_path / "matrix"
    eval_command([str(RUN)], {"switch": ("walk", "right_kick"), "episodes": 2, "out": single})
    eval_command([str(RUN)], {"switch_matrix": True, "episodes": 2, "out": matrix})
    result = json.loads((matrix / "switch_matrix.json").read_text())
    pairs = {(p["from"], p["to"]): p for p in result["pairs"]}
    assert len(pairs) == 6 and all(0 <= p["performed"] <= p["trials"] == 2 for p in pairs.values())
    assert {p["rule"] for (a, b), p in pairs.items() if b in ("walk", "run")} == {"speed+coverage"}
    # the same switch, judged by the same classifier: the kick's command is taken (P(kick) > 0.5) in both studies
    ramp = json.loads((single / "switch_walk_to_right_kick.json").read_text())["summary"]["ramp"]
    kick = pairs[("walk", "right_kick")]
    assert len(kick["latency_frames"]) == len(ramp["latency_frames"]) == 2
    assert all(x is not None for x in kick["latency_frames"] + ramp["latency_frames"])
    assert (matrix / "switch_matrix.png").stat().st_size > 5_000
    assert "Switch matrix" in (matrix / "report.md").read_text()


def test_the_batched_rollout_of_all_pairs_is_each_pair_rolled_out_alone():
    """`switch_rollout` of four pairs at once (2 trials each, 8 envs) against each pair rolled out alone. With the
    heading-goal offset at 0 the rollouts draw no random number, so they may differ only by float32 sums that the
    policy's batch size orders differently (measured: at most 1.2e-5 m over 5 s)."""
    from charctl.experiments.cgail.rollouts import load_eval_run, switch_rollout

    tr = load_eval_run(RUN, device="cpu")
    tr.cfg.env.goal_max_angle_deg = 0.0
    pairs = np.array([(0, 1), (0, 2), (2, 1), (1, 0)])  # walk -> run, walk -> kick, kick -> run, run -> walk
    frames = dict(ramp=60, t_switch=30, t_end=150, perform_frames=120)
    batched = switch_rollout(tr, pairs[:, 0], pairs[:, 1], 2, *frames.values())
    assert batched.pos_after.shape == (120, 8, 15, 3) and batched.probs.shape == (150, 8, 3)
    for p, (a, b) in enumerate(pairs):
        alone = switch_rollout(tr, a, b, 2, *frames.values())
        pair = batched.pair(p, 2)
        np.testing.assert_allclose(pair.pos_after, alone.pos_after, atol=1e-4)
        np.testing.assert_allclose(pair.probs, alone.probs, atol=1e-4)
        np.testing.assert_array_equal(pair.alive_hist, alone.alive_hist)


def test_an_amp_run_has_no_switch_matrix(tmp_path):
    from charctl.commands.evaluate import eval_command
    from charctl.errors import CharctlError

    out = tmp_path / "amp"
    with pytest.raises(CharctlError, match="--switch-matrix needs a conditional"):
        eval_command([str(REPO / "pretrained/amp-walk")], {"switch_matrix": True, "episodes": 2, "out": out})
    assert not out.exists()


def test_the_matrix_rule_asks_for_the_clips_poses_not_only_the_foot():
    """Three trials after a switch to the kick, judged from frame 0: the clip replayed (coverage 1, done), the clip
    with every foot and ankle body lifted 0.3 m (the foot rule met, no clip frame within 15 cm: not done), the first
    pose held (neither). Without `coverage_from` the lifted foot counts as done: the foot rule alone."""
    from charctl.experiments.cgail.config import SkillConfig
    from charctl.experiments.cgail.fidelity import clip_reference
    from charctl.experiments.cgail.metrics import PERFORM_COVERAGE, performed_after_switch
    from charctl.experiments.cgail.skills import load_skills
    from charctl.motion.skeleton import load_skeleton

    kick = load_skills([SkillConfig("right_kick", "kick")], 30.0)[0]
    ref = clip_reference(kick)
    tr = SimpleNamespace(
        agent=SimpleNamespace(skills=[kick]), cfg=SimpleNamespace(env=SimpleNamespace(control_hz=30.0))
    )
    F = len(ref.body_pos)
    lifted = ref.body_pos.copy()
    feet = [i for i, n in enumerate(load_skeleton().names) if "ankle" in n or "foot" in n]
    lifted[:, feet, 1] += 0.3
    pos = np.stack([ref.body_pos, lifted, np.repeat(ref.body_pos[:1], F, 0)], axis=1)  # (F, 3, 15, 3)
    rot = np.stack([ref.body_rot] * 2 + [np.repeat(ref.body_rot[:1], F, 0)], axis=1)
    alive = np.ones((F + 5, 3), dtype=bool)
    out = performed_after_switch(tr, 0, pos, rot, alive, t_switch=5, coverage_from=0)
    assert out["coverage"][0] == pytest.approx(1.0) and out["coverage"][1] == 0.0
    assert out["coverage"][2] < PERFORM_COVERAGE and out["rule"] == "foot_peak+coverage"
    assert out["performed"] == 1
    assert performed_after_switch(tr, 0, pos, rot, alive, t_switch=5)["performed"] == 2


def test_switch_coverage_judges_each_trial_on_its_own_frames_as_frame_match_does():
    """The clip replayed in three trials, judged from frame `start` = 4 to each trial's length (the whole clip, its
    first half, nothing left): per trial the share of the clip's frames that `frame_match` (the fidelity evaluation's
    per-sequence match) finds within 15 cm over exactly those frames; 0 where none are left."""
    from charctl.eval.fidelity import COVERAGE_TOL, frame_match, heading_positions
    from charctl.experiments.cgail.config import SkillConfig
    from charctl.experiments.cgail.fidelity import clip_reference
    from charctl.experiments.cgail.metrics import switch_coverage
    from charctl.experiments.cgail.skills import load_skills

    kick = load_skills([SkillConfig("right_kick", "kick")], 30.0)[0]
    ref = clip_reference(kick)
    F = len(ref.body_pos)
    pos = np.repeat(ref.body_pos[:, None], 3, axis=1)  # (F, 3, 15, 3)
    rot = np.repeat(ref.body_rot[:, None], 3, axis=1)
    lengths = np.array([F, F // 2, 3])
    got = switch_coverage(kick, pos, rot, 4, lengths)
    rel = heading_positions(ref.body_pos, ref.body_rot[:, 0])
    want = [np.mean(frame_match(rel[4:n], ref.rel)[0] <= COVERAGE_TOL) for n in lengths[:2]]
    assert 0.9 < want[0] <= 1.0 and 0.3 < want[1] < 0.7  # frames 0-3 are left out; half the clip covers half
    np.testing.assert_allclose(got, [*want, 0.0])
