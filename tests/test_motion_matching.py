"""motion-matching: index vs brute force, features, inertialization, root reconstruction, paths,
error metric, CSV errors, and end-to-end smoke runs of the sweep and the export (scale=smoke)."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from charctl.errors import CharctlError
from charctl.motion import rotations as R

from conftest import charctl_in_process

EXP = "motion-matching"


def smoke_cfg(*overrides: str):
    from charctl.config import compose_config
    from charctl.experiments.motion_matching.config import Config

    return compose_config(EXP, ["scale=smoke", *overrides], Config)


@pytest.fixture(scope="module")
def smoke_db():
    from charctl.experiments.motion_matching.database import build_database

    cfg = smoke_cfg()
    return cfg, build_database(cfg)


# ---------------------------------------------------------------------------- search
@pytest.mark.parametrize("kind", ["kdtree", "bbox"])
def test_index_returns_the_brute_force_frame_with_the_same_exclusions(smoke_db, kind):
    from charctl.experiments.motion_matching.search import make_index, search

    cfg, db = smoke_db
    brute = make_index("brute", db)
    index = make_index(kind, db)
    rng = np.random.default_rng(0)
    inside = 0
    for _ in range(150):
        cur = int(rng.choice(db.search_rows))  # a query close to the current frame: its own neighbours win
        q = db.features[cur] + rng.normal(0.0, 0.05, db.layout.dims)
        f_ref, d_ref = search(db, brute, q, cur)
        f_idx, d_idx = search(db, index, q, cur)
        assert f_idx == f_ref
        assert d_idx == pytest.approx(d_ref, rel=1e-9, abs=1e-9)
        assert not db.excluded(np.array([f_ref]), cur)[0]
        unconstrained, _ = search(db, brute, q, None)
        inside += bool(db.excluded(np.array([unconstrained]), cur)[0])
    assert inside > 100  # the window really removes the nearest frames, so the test exercises it


def test_exclusion_window_wraps_around_a_loop(smoke_db):
    cfg, db = smoke_db
    c = 0
    rows = db.search_rows[db.clip_id[db.search_rows] == c]
    first, last = rows[0], rows[-1]  # phases ~0 and ~period-1 of the same cycle
    assert db.clip_period[c] > 0
    k = db.exclude_window
    assert db.excluded(np.array([last]), first)[0]
    assert not db.excluded(np.array([first + k + 1]), first)[0]
    other = db.search_rows[db.clip_id[db.search_rows] == 1][0]
    assert not db.excluded(np.array([other]), first)[0]  # other clips are never excluded


# ---------------------------------------------------------------------------- features
def _straight_source(theta: float, speed: float = 1.2, fps: float = 30.0, T: int = 120):
    """A synthetic clip moving straight along heading theta, with a bobbing root and swinging legs."""
    from charctl.experiments.motion_matching.sources import SourceMotion
    from charctl.motion.clip import Clip

    t = np.arange(T) / fps
    fwd = np.array([np.cos(theta), -np.sin(theta)])
    ground = np.outer(speed * t, fwd)
    root = np.column_stack([ground[:, 0], 0.9 + 0.02 * np.sin(6 * t), ground[:, 1]])
    local = np.tile(R.IDENTITY, (T, 15, 1))
    local[:, 0] = R.heading_quat(np.full(T, theta))
    swing = 0.4 * np.sin(6 * t)
    local[:, 3] = R.from_axis_angle(np.array([0.0, 0.0, 1.0]), swing)
    local[:, 9] = R.from_axis_angle(np.array([0.0, 0.0, 1.0]), -swing)
    clip = Clip("straight", fps, root, local)
    return SourceMotion("straight", fps, root, local, clip.body_pos, 0, T)


def test_features_of_a_straight_line_clip_have_no_lateral_component():
    from charctl.experiments.motion_matching.database import build_database
    from charctl.experiments.motion_matching.sources import SkeletonInfo
    from charctl.motion.skeleton import BODY_NAMES

    cfg = smoke_cfg("features.past_samples=2", "features.direction_weight=0.5")
    info = SkeletonInfo(
        "humanoid",
        list(BODY_NAMES),
        np.array([1.0, 0.0, 0.0]),
        [BODY_NAMES.index("right_ankle"), BODY_NAMES.index("left_ankle")],
    )
    db = build_database(cfg, [_straight_source(0.7)], info)
    rows = db.search_rows
    assert rows.size > 10
    L = db.layout
    fut = db.raw[rows][:, L.blocks["future_pos"]].reshape(rows.size, -1, 2)
    vel = db.raw[rows][:, L.blocks["future_vel"]].reshape(rows.size, -1, 2)
    dirs = db.raw[rows][:, L.blocks["future_dir"]].reshape(rows.size, -1, 2)
    past = db.raw[rows][:, L.blocks["past_pos"]].reshape(rows.size, -1, 2)
    np.testing.assert_allclose(fut[..., 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(vel[..., 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(dirs[..., 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(past[..., 1], 0.0, atol=1e-12)
    # forward components by hand: speed * offset / fps ahead, behind for the past, speed for velocities
    np.testing.assert_allclose(
        fut[..., 0], np.broadcast_to(1.2 * L.future_offsets / db.fps, fut[..., 0].shape), atol=1e-12
    )
    np.testing.assert_allclose(
        past[..., 0], np.broadcast_to(-1.2 * L.past_offsets / db.fps, past[..., 0].shape), atol=1e-12
    )
    np.testing.assert_allclose(vel[..., 0], 1.2, atol=1e-9)
    np.testing.assert_allclose(dirs[..., 0], 1.0, atol=1e-12)
    # the legs swing in the sagittal plane, so the end points have no lateral velocity either
    ev = db.raw[rows][:, L.blocks["end_vel"]].reshape(rows.size, -1, 3)
    np.testing.assert_allclose(ev[..., 2], 0.0, atol=1e-9)


def test_blocks_are_normalised_and_weighted(smoke_db):
    cfg, db = smoke_db
    L = db.layout
    feats = db.features[db.search_rows]
    for cols in L.blocks.values():
        x = feats[:, cols] / L.sqrt_w[cols]
        np.testing.assert_allclose(x.mean(axis=0), 0.0, atol=1e-9)
        assert x.std(axis=0).mean() == pytest.approx(1.0, rel=1e-6)
    fp = L.sqrt_w[L.blocks["future_pos"]] ** 2
    n = cfg.features.future_samples
    expected = np.repeat(cfg.features.position_weight * cfg.features.discount ** np.arange(n), 2)
    np.testing.assert_allclose(fp, expected)  # gamma^(i-1) per sample


# ---------------------------------------------------------------------------- inertialization
def test_spring_decay_is_continuous_and_decays_to_zero():
    from charctl.experiments.motion_matching.inertialization import decay_offsets, inertialize_segment

    x0, v0, hl = np.array([0.3, -1.0]), np.array([2.0, 0.5]), 0.1
    x, v = decay_offsets(x0, v0, hl, np.array([0.0, 1e-5, -1e-5, 10 * hl, 0.05]))
    np.testing.assert_allclose(x[0], x0)
    np.testing.assert_allclose(v[0], v0)
    np.testing.assert_allclose((x[1] - x[2]) / 2e-5, v0, rtol=1e-6)  # v is the derivative of x
    y = 2 * np.log(2) / hl  # critically damped: x'' = -2y x' - y^2 x
    np.testing.assert_allclose((v[1] - v[2]) / 2e-5, -2 * y * v0 - y * y * x0, rtol=1e-5)
    assert np.all(np.abs(x[3]) < 1e-2 * np.abs(x0).max())
    # a jump between two signals: out starts at the source and ends on the destination
    dt = 1 / 120
    tt = np.arange(121) * dt
    src, dst = np.sin(tt), 2.0 + 0.5 * tt
    out, _, _ = inertialize_segment(src[0], 1.0, dst, 0.5, hl, dt)
    assert out[0] == pytest.approx(src[0])
    assert abs(out[1] - out[0]) < 0.02 * abs(src[0] - dst[0])  # the 2.0 jump is spread, not shown
    assert abs(out[-1] - dst[-1]) < 1e-2


def test_rollout_pose_has_no_jump_at_transitions(smoke_db):
    from charctl.experiments.motion_matching.paths import make_path
    from charctl.experiments.motion_matching.runtime import run_path
    from charctl.experiments.motion_matching.search import make_index

    cfg, db = smoke_db
    r = run_path(db, make_index("kdtree", db), make_path("star", cfg.paths), cfg, with_pose=True)
    assert r.jumps > 5

    def step(q):  # largest joint rotation per frame
        return R.angle_between(q[1:], q[:-1]).max(axis=1)

    raw = step(db.pose[r.frames])  # the database frames played, without blending
    out = step(r.pose)
    transitions = np.flatnonzero(np.diff(r.frames) != 1)
    assert raw[transitions].max() > 3 * out[transitions].max()  # the raw jumps are removed
    assert out.max() < 1.2 * raw[np.diff(r.frames) == 1].max()  # no frame moves more than the data itself does
    # after a transition, the output converges to the database pose (half-life 0.1 s)
    settled = R.angle_between(r.pose, db.pose[r.frames]).max(axis=1)
    assert np.median(settled) < np.median(raw[transitions])


def test_root_motion_blend_continues_the_previous_step(smoke_db):
    from charctl.experiments.motion_matching.runtime import PoseBlend

    _, db = smoke_db
    a, b = int(db.search_rows[5]), int(db.search_rows[-40])
    blend = PoseBlend(db, a, halflife=0.1, with_pose=False, root=True)
    steps, dh = blend.segment(a, a, 10)  # no transition: exactly the database's steps
    np.testing.assert_allclose(steps, db.step_local[a : a + 10])
    steps, dh = blend.segment(a + 10, b, 30)  # a jump: the first step is the one that would have come next
    np.testing.assert_allclose(steps[0], db.step_local[a + 10], atol=1e-12)
    assert dh[0] == pytest.approx(db.step_heading[a + 10])
    assert np.abs(steps[-1] - db.step_local[b + 29]).max() < 0.05 * np.abs(steps[0] - db.step_local[b]).max() + 1e-9


def test_root_reconstruction_reproduces_a_played_clip(smoke_db):
    from charctl.experiments.motion_matching.runtime import accumulate_root

    _, db = smoke_db
    a = int(db.search_rows[10])
    n = 40
    g, h = accumulate_root(db.ground[a], db.heading[a], db.step_local[a : a + n], db.step_heading[a : a + n])
    np.testing.assert_allclose(g, db.ground[a + 1 : a + n + 1], atol=1e-9)
    np.testing.assert_allclose(np.cos(h), np.cos(db.heading[a + 1 : a + n + 1]), atol=1e-9)


# ---------------------------------------------------------------------------- paths and errors
@pytest.mark.parametrize("name", ["circle", "square", "star"])
def test_error_is_zero_for_a_path_followed_exactly(name):
    from charctl.experiments.motion_matching.paths import make_path, path_errors

    cfg = smoke_cfg()
    p = make_path(name, cfg.paths)
    dt, speed = 1 / 30, 0.9
    ground = p.point_at(speed * np.arange(int(p.length / speed / dt)) * dt)
    e = path_errors(p, ground, speed, dt)
    assert max(e.values()) < 1e-9
    # a copy shifted sideways by 0.2 m is 0.2 m off in both metrics (away from corners)
    assert path_errors(p, ground + np.array([0.0, 0.2]), speed, dt)["e_time_mean"] == pytest.approx(0.2, rel=1e-6)


def test_error_metrics_differ_in_what_they_reward():
    from charctl.experiments.motion_matching.paths import make_path, path_errors

    p = make_path("circle", smoke_cfg().paths)
    dt, speed = 1 / 30, 0.9
    lagging = p.point_at(0.5 * speed * np.arange(150) * dt)  # on the path, at half the speed
    e = path_errors(p, lagging, speed, dt)
    assert e["e_near_mean"] < 1e-3 < 0.5 < e["e_time_mean"]


def test_path_shapes_and_csv(tmp_path):
    from charctl.experiments.motion_matching.paths import make_path

    cfg = smoke_cfg()
    circle = make_path("circle", cfg.paths)
    assert circle.length == pytest.approx(2 * np.pi * cfg.paths.circle_radius, rel=1e-4)
    assert make_path("square", cfg.paths).length == pytest.approx(4 * cfg.paths.square_side)
    star = make_path("star", cfg.paths)
    assert star.closed and star.points.shape[0] == 2 * cfg.paths.star_points + 2
    f = tmp_path / "zig.csv"
    f.write_text("x,z\n0,0\n1,0\n1,1 # corner\n\n2,1\n")
    p = make_path(str(f), cfg.paths)
    assert not p.closed and p.length == pytest.approx(3.0)
    np.testing.assert_allclose(p.point_at(1.5), [1.0, 0.5])
    np.testing.assert_allclose(p.point_at(10.0), [2.0, 1.0])  # open paths clamp at the end


@pytest.mark.parametrize(
    "text,needle",
    [
        ("x,z\n0,0\n1,zero\n", ":3:"),
        ("0,0\n1,2,3\n", ":2:"),
        ("0,0\n1;\n", ":2:"),
        ("0,0\nnan,1\n", ":2:"),
        ("x,z\n5,5\n", "at least two"),
    ],
)
def test_bad_path_csv_is_a_one_line_error(tmp_path, text, needle):
    from charctl.experiments.motion_matching.paths import read_path_csv

    f = tmp_path / "bad.csv"
    f.write_text(text)
    with pytest.raises(CharctlError) as err:
        read_path_csv(f)
    msg = str(err.value)
    assert needle in msg and "\n" not in msg


def test_bad_path_csv_on_the_command_line(tmp_path):
    """Through charctl.cli.main in this process (test_faults.py runs `export motion-matching` bad input as a
    real process)."""
    f = tmp_path / "bad.csv"
    f.write_text("x,z\n0,0\n1,oops\n")
    res = charctl_in_process("export", EXP, f"path={f}", "scale=smoke", "--bvh", str(tmp_path / "o.bvh"), cwd=tmp_path)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "bad.csv:3" in lines[0] and "Traceback" not in res.stderr


def test_config_errors_are_one_line():
    with pytest.raises(CharctlError, match="runtime.index"):
        smoke_cfg("runtime.index=faiss")
    with pytest.raises(CharctlError, match="discount"):
        smoke_cfg("features.discount=0")


def test_searchable_frames_are_counted_without_building_the_database():
    """check_searchable (the sweep's check before it writes) counts what build_database would search, and
    gives build_database's one-line error for fewer than 2 frames."""
    from charctl.experiments.motion_matching.cases import with_case
    from charctl.experiments.motion_matching.database import build_database
    from charctl.experiments.motion_matching.prechecks import check_searchable
    from charctl.experiments.motion_matching.sources import load_sources

    cfg = smoke_cfg("data.clips=[kick]", "data.mirror=false", "runtime.end_buffer=140")
    sources, info = load_sources(cfg)
    for case in (1, 8):
        ccfg = with_case(cfg, case)
        assert check_searchable(ccfg, sources) == build_database(ccfg, sources, info).num_searchable >= 2
    ccfg = with_case(cfg, 10)  # 2 past samples leave one searchable frame
    with pytest.raises(CharctlError) as built:
        build_database(ccfg, sources, info)
    with pytest.raises(CharctlError) as counted:
        check_searchable(ccfg, sources)
    assert str(counted.value) == str(built.value) and "1 searchable frames" in str(built.value)


def _straight_info():
    from charctl.experiments.motion_matching.sources import SkeletonInfo
    from charctl.motion.skeleton import BODY_NAMES

    ends = [BODY_NAMES.index("right_ankle"), BODY_NAMES.index("left_ankle")]
    return SkeletonInfo("humanoid", list(BODY_NAMES), np.array([1.0, 0.0, 0.0]), ends)


@pytest.mark.parametrize("kind", ["brute", "kdtree", "bbox"])
def test_exclusion_window_holding_every_searchable_frame_is_found_before_the_search(kind):
    """By hand: the 120-frame straight clip at 30 Hz has future offsets 6, 12, 19, 25 (25 paper frames each)
    and end_buffer 20 -> 5 frames, so frames 0..94 (95) are searchable. From the current frame p, all of them
    are inside a window of k frames iff 94 - k < p < k: none for k = 47, frame 47 for k = 48, frames 45..49
    for k = 50 (runtime.exclude_window = 4k paper frames). check_exclusion gives the error that search gives
    from such a frame, and search from the frame next to it finds frame 94, the one frame k away."""
    from charctl.experiments.motion_matching.database import build_database
    from charctl.experiments.motion_matching.prechecks import blocked_frames, check_exclusion, check_searchable
    from charctl.experiments.motion_matching.search import make_index, search

    sources = [_straight_source(0.0)]
    for window, blocked in ((188, []), (192, [47]), (200, [45, 46, 47, 48, 49])):
        cfg = smoke_cfg(f"runtime.exclude_window={window}")
        assert check_searchable(cfg, sources) == 95
        assert blocked_frames(cfg, sources)[0].tolist() == blocked
    check_exclusion(smoke_cfg("runtime.exclude_window=188"), sources)
    cfg = smoke_cfg("runtime.exclude_window=192")
    with pytest.raises(CharctlError) as checked:
        check_exclusion(cfg, sources)
    assert "frame 47 of clip 'straight': all 95 are in that clip, closer than 48 frames" in str(checked.value)
    db = build_database(cfg, sources, _straight_info())
    index = make_index(kind, db)
    with pytest.raises(CharctlError) as searched:
        search(db, index, db.features[47], 47)
    assert str(searched.value) == str(checked.value)
    assert search(db, index, db.features[46], 46)[0] == 94


@pytest.mark.parametrize(
    "overrides",
    [
        ["data.clips=[kick]"],  # not a loop
        ["data.clips=[walk]", "data.loop_cycles_before=0", "features.past_samples=2"],  # part of a loop's cycle
        ["data.clips=[run]", "data.fps=25", "data.loop_cycles_before=0", "features.past_samples=1"],  # period 20.0000..
    ],
)
def test_blocked_frames_are_the_frames_the_search_finds_nothing_from(overrides):
    """blocked_frames (the farthest searchable frame decides) == every frame from the first searchable one to
    the clip's end whose window (Database.excluded, the search's rule) holds every searchable frame."""
    from charctl.experiments.motion_matching.database import build_database, paper_frames
    from charctl.experiments.motion_matching.prechecks import blocked_frames
    from charctl.experiments.motion_matching.sources import load_sources

    cfg = smoke_cfg("data.mirror=false", *overrides)
    sources, info = load_sources(cfg)
    db = build_database(cfg, sources, info)
    rows = db.search_rows
    seen = set()
    for window in range(0, 200, 2):
        db.exclude_window = paper_frames(window, cfg)
        want = [f for f in range(rows[0], db.num_frames) if db.exclude_window > 0 and db.excluded(rows, f).all()]
        windowed = copy.deepcopy(cfg)  # the composed config with this window (composing 100 times took ~20 s)
        windowed.runtime.exclude_window = window
        assert blocked_frames(windowed, sources)[0].tolist() == want, window
        seen.add(len(want))
    assert 0 in seen and len(seen) > 3  # the windows run from none blocked through some to all
    composed = smoke_cfg("data.mirror=false", *overrides, "runtime.exclude_window=120")  # one window composed
    windowed = copy.deepcopy(cfg)
    windowed.runtime.exclude_window = 120
    assert blocked_frames(composed, sources)[0].tolist() == blocked_frames(windowed, sources)[0].tolist()


# ---------------------------------------------------------------------------- Table 1 and end to end
def test_table1_cases():
    from charctl.experiments.motion_matching.cases import TABLE1, describe, with_case

    assert sorted(TABLE1) == list(range(1, 20))
    assert [TABLE1[n]["future_samples"] for n in range(1, 8)] == list(range(1, 8))
    assert describe(9) == "3x33" and describe(18) == "4x25 pos:vel 0.8:0.2 γ0.7"
    assert TABLE1[10]["past_samples"] > 0 and TABLE1[11]["past_samples"] > 0
    cfg = with_case(smoke_cfg(), 18)
    assert (cfg.features.future_samples, cfg.features.future_spacing, cfg.features.discount) == (4, 25, 0.7)


def test_sweep_and_export_smoke(tmp_path):
    from charctl.experiments.motion_matching.evaluate import evaluate
    from charctl.experiments.motion_matching.export import export
    from charctl.motion.bvh import read_bvh_as_clip

    out = tmp_path / "sweep"
    evaluate([EXP], {"sweep": True, "out": out}, ["scale=smoke", "sweep.plots=true", f"output_root={tmp_path}"])
    data = json.loads((out / "sweep.json").read_text())
    assert set(data["cases"]) == {"1", "8", "16"}
    for case in data["cases"].values():
        for p in ("circle", "square", "star"):
            r = case["paths"][p]
            assert 0 < r["e_near_mean"] <= r["e_time_mean"] + 1e-9 and np.isfinite(r["e_time_std"])
            assert r["searches"] > 5
    best = data["best_case"]
    assert f"| {best} ★ |" in (out / "sweep.md").read_text()
    assert (out / "plots" / "case_08.png").stat().st_size > 1000 and (out / "best.png").is_file()
    # the best setting with a multi-sample horizon follows the circle within half a metre
    assert data["cases"]["8"]["paths"]["circle"]["e_time_mean"] < 0.5

    bvh = tmp_path / "star.bvh"
    export(EXP, {"bvh": bvh, "seconds": 4.0}, ["scale=smoke", "path=star", "case=best", f"output_root={tmp_path}"])
    clip = read_bvh_as_clip(bvh)
    assert clip.num_frames == 4 * 30 + 1
    run = sorted((tmp_path / EXP).glob("*/metrics.json"))[-1]
    metrics = json.loads(run.read_text())
    assert metrics["case"] == int(best) and metrics["e_time_mean"] < 1.0
    assert (run.parent / "path.png").is_file()
    np.testing.assert_allclose(clip.root_pos[0, [0, 2]], [0.0, 0.0], atol=1e-5)
    from charctl.experiments.motion_matching.report import write_report

    text = write_report(out).read_text()
    assert "| 8 |" in text and "searches in the sweep ended in a jump" in text and "walker/turn_left0" in text


def test_user_bvh_folder_gives_the_same_features_and_exports_its_skeleton(tmp_path):
    """A BVH folder of the humanoid's own (unrolled) clips: the generic joint-position features
    match the humanoid database frame for frame, and the result is written on the user's skeleton."""
    from charctl.experiments.motion_matching.database import build_database
    from charctl.experiments.motion_matching.export import write_rollout_bvh
    from charctl.experiments.motion_matching.paths import make_path
    from charctl.experiments.motion_matching.runtime import run_path
    from charctl.experiments.motion_matching.search import make_index
    from charctl.experiments.motion_matching.sources import humanoid_sources
    from charctl.motion.bvh import read_bvh, write_bvh
    from charctl.motion.clip import Clip

    base = smoke_cfg("data.clips=[walk,walker/turn_left0]", "data.mirror=false")
    sources, _ = humanoid_sources(base)
    folder = tmp_path / "mocap"
    for s in sources:
        write_bvh(
            Clip(s.name.replace("/", "_"), s.fps, s.root_pos, s.local_rot), folder / f"{s.name.replace('/', '_')}.bvh"
        )
    ref = build_database(base, sources, humanoid_sources(base)[1])
    cfg = smoke_cfg(f"data.bvh_dir={folder}")
    db = build_database(cfg)
    assert db.skeleton.kind == "bvh" and db.skeleton.bvh_scale == 1.0  # metre files (root below 5 units)
    assert [db.skeleton.joint_names[j] for j in db.skeleton.end_joints] in (
        ["right_ankle", "left_ankle"],
        ["left_ankle", "right_ankle"],
    )
    np.testing.assert_allclose(db.skeleton.forward, [1.0, 0.0, 0.0])  # forward axis found from the travel direction
    # files are sorted by name: turn_left0 (walker_turn_left0.bvh) comes after walk.bvh in both
    order = np.argsort([n.replace("/", "_") for n in ref.clip_names])
    for c_bvh, c_ref in enumerate(order):
        a = slice(db.clip_start[c_bvh], db.clip_stop[c_bvh])
        b = slice(ref.clip_start[c_ref], ref.clip_stop[c_ref])
        ends = db.skeleton.end_joints
        swap = db.skeleton.joint_names[ends[0]] != "right_ankle"
        ra, rb = db.raw[a], ref.raw[b]
        if swap:
            e = ref.layout.blocks["end_pos"]
            rb = rb.copy()
            rb[:, e] = np.roll(rb[:, e].reshape(len(rb), 2, 3), 1, axis=1).reshape(len(rb), 6)
            v = ref.layout.blocks["end_vel"]
            rb[:, v] = np.roll(rb[:, v].reshape(len(rb), 2, 3), 1, axis=1).reshape(len(rb), 6)
        np.testing.assert_allclose(ra, rb, atol=2e-3)  # 6-decimal BVH text and Euler round trips
    r = run_path(db, make_index("kdtree", db), make_path("circle", cfg.paths), cfg, seconds=2.0)
    out = write_rollout_bvh(db, r, tmp_path / "out.bvh")
    back = read_bvh(out)
    assert back.names == db.skeleton.joint_names and back.num_frames == r.num_frames
    pos, _ = back.forward_kinematics()
    np.testing.assert_allclose(pos[:, 0, [0, 2]], r.ground, atol=1e-5)
