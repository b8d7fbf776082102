"""Fidelity evaluation (charctl/eval/fidelity.py, charctl/experiments/cgail/fidelity.py): clips scored
against themselves, against other clips and their mirrors, the signature on hand-built arrays, and
`charctl eval pretrained/cgail-3skill-fidelity --fidelity -k 1` end to end."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from charctl.errors import CharctlError
from charctl.eval.fidelity import (
    body_error_and_coverage,
    foot_sole_heights,
    frame_match,
    heading_positions,
    signature,
    tile_index,
    uncovered_spans,
)
from charctl.motion import rotations as R

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def refs():
    """ClipReference of the skills the tests use, loaded as an agent loads them (30 Hz)."""
    from charctl.experiments.cgail.fidelity import clip_reference
    from charctl.experiments.cgail.skills import load_skills

    specs = [
        SimpleNamespace(name=n, clip=c, heading_goal=False)
        for n, c in [("walk", "walk"), ("run", "run"), ("right_kick", "kick"), ("left_kick", "kick:mirror")]
    ]
    return {s.name: clip_reference(s) for s in load_skills(specs, 30.0)}


@pytest.mark.parametrize("skill", ["walk", "run", "right_kick", "left_kick"])
def test_clip_replayed_in_the_simulator_scores_coverage_one_and_zero_error(refs, skill):
    """The clip's states set in the simulator (what a policy that tracks it perfectly would produce),
    read back as the rollouts read bodies, against the clip: coverage 1, error ~ 0."""
    from charctl.sim.batch import BatchedHumanoid, SimSettings

    ref = refs[skill]
    sim = BatchedHumanoid(len(ref.qpos), SimSettings(physics_hz=150.0, control_hz=30.0, nthread=1))
    sim.set_state(np.arange(len(ref.qpos)), ref.qpos, np.zeros((len(ref.qpos), sim.layout.nv)))
    pos, rot = sim.body_pos_rows(), sim.body_quat_rows()
    err, cov = body_error_and_coverage(heading_positions(pos, rot[:, 0]), ref.rel, ref.loop)
    assert cov == 1.0
    assert err < 1e-6
    assert np.abs(pos - ref.body_pos).max() < 1e-9  # the reference is exactly the simulator's bodies


def test_looping_clip_tiled_over_several_cycles_still_scores_one(refs):
    ref = refs["walk"]
    m = len(ref.rel)
    idx = tile_index(3 * m, m, loop=True)  # played on: the closing frame is dropped between repeats
    assert np.array_equal(idx, np.arange(3 * m) % (m - 1))
    err, cov = body_error_and_coverage(ref.rel[idx], ref.rel, ref.loop)
    assert cov == 1.0 and err < 1e-6
    # a non-looping clip is never tiled: its DTW reference is the clip once
    assert len(tile_index(200, 47, loop=False)) == 47


def test_walk_against_the_kick_clip_scores_near_zero(refs):
    """Measured: walk's frames against the kick clip cover 0 of its 47 frames (error 0.257 m), the
    mirrored kick 0 of the kick's (0.340 m). 15 cm at every body is strict: no walk pose has the kick's
    guard arms and planted, turned stance within it. A character frozen in the kick's first pose for
    5 s covers 8/47 = 0.17: the opening and closing stance frames of the clip, what a policy that stands
    in guard scores; a coverage target of 0.6 cannot be met by standing."""
    walk, kick = refs["walk"], refs["right_kick"]
    err, cov = body_error_and_coverage(walk.rel, kick.rel, kick.loop)
    assert cov <= 0.05
    assert err > 0.2
    frozen = np.repeat(kick.rel[:1], 151, axis=0)
    err0, cov0 = body_error_and_coverage(frozen, kick.rel, kick.loop)
    assert cov0 <= 0.2 and err0 > 0.05


def test_mirrored_kick_scores_one_against_itself_and_swaps_the_feet(refs):
    kick, mirror = refs["right_kick"], refs["left_kick"]
    err, cov = body_error_and_coverage(mirror.rel, mirror.rel, mirror.loop)
    assert cov == 1.0 and err < 1e-6
    err_x, cov_x = body_error_and_coverage(kick.rel, mirror.rel, mirror.loop)
    assert cov_x <= 0.05 and err_x > 0.2  # a right kick is not a left kick
    a, b = kick.signature(), mirror.signature()
    assert a["right_foot_peak"] == pytest.approx(1.28, abs=0.01)  # DeepMimic's kick lifts the right ankle to 1.28 m
    assert a["left_foot_peak"] < 0.15
    for side, other in (("foot", "foot"), ("hand", "hand")):
        assert a[f"right_{side}_peak"] == pytest.approx(b[f"left_{other}_peak"], abs=1e-9)
        assert a[f"left_{side}_peak"] == pytest.approx(b[f"right_{other}_peak"], abs=1e-9)
    for key in ("airborne", "speed", "yaw_rate"):
        assert a[key] == pytest.approx(b[key], abs=1e-9)


def test_frame_match_on_hand_values():
    """Clip of 3 frames, 2 bodies; a sequence of 2 frames. Clip frame 0 is matched exactly by sequence frame 0;
    frame 1 is 0.3 m from either sequence frame at its farthest body (body 1 of seq frame 1, 0.1 m at body 0);
    frame 2's best match is seq frame 1 with body 0 off by 0.2 m (body 1 exact)."""
    clip = np.zeros((3, 2, 3))
    clip[1] = [[0.1, 0, 0], [0, 0.6, 0]]
    clip[2] = [[0.2, 0, 0], [0, 0.3, 0]]
    seq = np.zeros((2, 2, 3))
    seq[1] = [[0.0, 0, 0], [0, 0.3, 0]]
    dist, body = frame_match(seq, clip)
    # seq 0 against clip 1: bodies 0.1 / 0.6 -> 0.6; seq 1: 0.1 / 0.3 -> 0.3 (body 1)
    assert np.allclose(dist, [0.0, 0.3, 0.2])
    assert body[1:].tolist() == [1, 0]
    # its covered share is the coverage of body_error_and_coverage, at any tolerance
    for tol in (0.15, 0.25, 0.35):
        assert np.mean(dist <= tol) == body_error_and_coverage(seq, clip, tol=tol)[1]


def test_uncovered_spans_by_hand():
    assert uncovered_spans(np.array([True, False, False, True, False])) == [(1, 2), (4, 4)]
    assert uncovered_spans(np.ones(4, dtype=bool)) == []
    assert uncovered_spans(np.zeros(3, dtype=bool)) == [(0, 2)]


def test_frame_report_of_a_frozen_guard_against_the_kick(refs):
    """A character frozen in the kick's first pose covers the clip's frames within 0.15 m of that pose and
    nothing else (distances checked against the direct body distances); the clip replayed covers every frame."""
    from charctl.eval.fidelity import body_distances
    from charctl.experiments.cgail.fidelity import frame_report, uncovered_cell

    kick = refs["right_kick"]
    frozen = np.repeat(kick.rel[:1], 20, axis=0)
    rep = frame_report(*(x[None] for x in frame_match(frozen, kick.rel)), kick.dt)
    direct = body_distances(kick.rel[:1], kick.rel)[0].max(axis=-1)  # (m,)
    assert np.allclose(rep["distance"][0], direct, atol=1e-4)
    covered = direct <= 0.15
    assert rep["covered_share"] == covered.astype(float).tolist()
    assert [(s["first"], s["last"]) for s in rep["uncovered"]] == uncovered_spans(covered)
    first = rep["uncovered"][0]
    assert first["t0"] == pytest.approx(first["first"] / 30.0) and first["peak_m"] > 0.15
    from charctl.motion.skeleton import load_skeleton

    span_bodies = body_distances(kick.rel[:1], kick.rel[first["first"] : first["last"] + 1])[0].argmax(axis=-1)
    assert first["body"] == load_skeleton().names[np.bincount(span_bodies).argmax()]
    assert first["peak_m"] == pytest.approx(direct[first["first"] : first["last"] + 1].max(), abs=1e-4)
    assert uncovered_cell(rep["uncovered"]).startswith(f"{first['t0']:.2f}-{first['t1']:.2f} s {first['body']}")
    assert frame_report(*(x[None] for x in frame_match(kick.rel, kick.rel)), kick.dt)["uncovered"] == []


def test_uncovered_cell_keeps_the_longest_spans_in_clip_order():
    from charctl.experiments.cgail.fidelity import uncovered_cell

    spans = [
        {"first": f, "last": l, "t0": f / 10, "t1": l / 10, "body": b, "peak_m": p}
        for f, l, b, p in [
            (0, 0, "neck", 0.2),
            (3, 9, "left_wrist", 0.354),
            (12, 14, "right_ankle", 0.25),
            (20, 21, "chest", 0.16),
        ]
    ]
    assert uncovered_cell(spans, most=2) == "0.30-0.90 s left_wrist 0.35 m; 1.20-1.40 s right_ankle 0.25 m; +2 more"
    assert uncovered_cell(spans[:1]) == "0.00 s neck 0.20 m"
    assert uncovered_cell([]) == "-"


def _hand_built(T: int = 40, dt: float = 0.1, v: float = 2.0, omega: float = 0.5):
    """A character gliding along +x at v m/s while turning at omega rad/s about +y, every body level
    (rotation = the heading only), with scripted foot and hand heights."""
    t = np.arange(T) * dt
    yaw = omega * t
    q = R.heading_quat(yaw)  # (T, 4)
    rot = np.broadcast_to(q[:, None], (T, 15, 4)).copy()
    offsets = np.random.default_rng(0).uniform(-0.5, 0.5, size=(15, 3))
    offsets[0] = 0.0
    root = np.stack([v * t, np.full(T, 1.0), np.zeros(T)], axis=1)
    pos = root[:, None] + R.rotate(rot, np.broadcast_to(offsets, (T, 15, 3)))
    right_ankle, left_ankle, right_wrist, left_wrist = 5, 11, 8, 14
    pos[:, [right_ankle, left_ankle], 1] = 0.05  # standing: the sole (ankle - 0.05 m) on the floor
    pos[10:20, right_ankle, 1] = np.linspace(0.2, 0.65, 10)  # right foot up, peak 0.65 m
    pos[12:16, left_ankle, 1] = 0.2  # left foot up too in frames 12..15: 4 airborne frames
    pos[:, [right_wrist, left_wrist], 1] = [1.0, 0.9]
    pos[7, right_wrist, 1] = 1.5
    return pos, rot, dt, offsets


def test_signature_on_a_hand_built_trajectory():
    pos, rot, dt, offsets = _hand_built()
    assert np.allclose(foot_sole_heights(pos, rot)[:, 1][[0, 11, 16]], 0.0, atol=1e-12)  # level feet on the floor
    s = signature(pos, rot, dt, ground=0.0)
    assert s["right_foot_peak"] == pytest.approx(0.65)
    assert s["left_foot_peak"] == pytest.approx(0.2)
    assert s["right_hand_peak"] == pytest.approx(1.5)
    assert s["left_hand_peak"] == pytest.approx(0.9)
    assert s["airborne"] == pytest.approx(4 / 40)  # both soles > 5 cm above the floor only in frames 12..15
    assert s["speed"] == pytest.approx(2.0)
    assert s["yaw_rate"] == pytest.approx(0.5)
    # the airborne threshold is relative to the standing sole height: a clip standing 0.1 m higher never flies
    assert signature(pos, rot, dt, ground=0.1)["airborne"] == 0.0
    # heading frame: the yaw is removed, so the bodies sit at their constant offsets
    rel = heading_positions(pos, rot[:, 0])
    assert np.allclose(rel[:, 3], offsets[3], atol=1e-12)
    # padded batch: a sequence cut after 10 frames scores as that prefix alone
    batch = signature(np.stack([pos, pos]), np.stack([rot, rot]), dt, 0.0, lengths=np.array([40, 10]))
    short = signature(pos[:10], rot[:10], dt, 0.0)
    for key, value in short.items():
        assert batch[key][1] == pytest.approx(value)
        assert batch[key][0] == pytest.approx(s[key])


def test_bad_episode_count_is_one_line_error_before_anything_is_written(tmp_path):
    from charctl.commands.evaluate import eval_command

    out = tmp_path / "fid"
    with pytest.raises(CharctlError, match="-k"):
        eval_command(
            [str(REPO / "pretrained" / "cgail-3skill-fidelity")], {"fidelity": True, "episodes": 0, "out": out}
        )
    assert not out.exists()


def test_shipped_policy_end_to_end(tmp_path, monkeypatch):
    """`charctl eval pretrained/cgail-3skill-fidelity --fidelity -k 1 -o DIR` (in process; 2 filmstrip columns
    instead of 8 to keep the test short), then `training_fidelity` on the same loaded agent."""
    import json

    import charctl.experiments.cgail.evaluate as ev
    import charctl.experiments.cgail.fidelity as fid
    from charctl.commands.evaluate import eval_command

    monkeypatch.setattr(fid, "FILMSTRIP_FRAMES", 2)
    loaded = []
    real_load = ev.load_eval_run
    monkeypatch.setattr(ev, "load_eval_run", lambda *a, **k: loaded.append(real_load(*a, **k)) or loaded[-1])
    out = tmp_path / "fid"
    eval_command([str(REPO / "pretrained" / "cgail-3skill-fidelity")], {"fidelity": True, "episodes": 1, "out": out})
    skills = ("walk", "run", "right_kick")
    for s in skills:
        assert (out / f"fidelity_{s}.png").stat().st_size > 10_000
    result = json.loads((out / "fidelity.json").read_text())
    assert set(result["skills"]) == set(skills)
    report = (out / "report.md").read_text()
    assert "## Fidelity" in report and "| right_kick |" in report
    assert (out / "fidelity_frames.png").stat().st_size > 10_000 and "(fidelity_frames.png)" in report
    assert "not covered (clip s, farthest body, m)" in report
    kick = result["skills"]["right_kick"]
    assert kick["reference"]["right_foot_peak"] == pytest.approx(1.28, abs=0.01)
    # the fidelity policy kicks (its eval/report.md: 1.27 m over 4 episodes); the old cgail-3skill reached 0.17 m
    assert 0.8 * 1.28 <= kick["policy"]["right_foot_peak"] < 2.0
    for s in skills:
        assert 0.0 <= result["skills"][s]["coverage"] <= 1.0 and result["skills"][s]["body_error"] > 0.0
        frames = result["skills"][s]["frames"]  # one episode: its covered frames' share is its coverage
        assert np.mean(frames["covered_share"]) == pytest.approx(result["skills"][s]["coverage"])

    scalars = fid.training_fidelity(loaded[0].agent, num_envs=1)
    expected = {
        f"fidelity/{s}/{m}" for s in skills for m in ("coverage", "body_error", "foot_peak", "airborne", "yaw_rate")
    }
    assert set(scalars) == expected | {"fidelity/min_coverage"}
    assert scalars["fidelity/min_coverage"] == min(scalars[f"fidelity/{s}/coverage"] for s in skills)
    assert scalars["fidelity/right_kick/coverage"] == pytest.approx(kick["coverage"])  # same deterministic rollout
