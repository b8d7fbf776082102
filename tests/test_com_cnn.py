"""com-cnn (docs/com-cnn.md): dataset windows, the paper's COM, network shapes, learning, the COM clamp,
the split, the COM-path parser, BVH folders, and the pipeline end to end at smoke scale."""

from __future__ import annotations

import math

import numpy as np
import pytest

from charctl.errors import CharctlError
from charctl.motion import rotations as R

from conftest import TINY_COM_CNN, assert_one_line, assert_one_line_error

torch = pytest.importorskip("torch")
torch.set_num_threads(1)


def compose(*overrides: str):
    from charctl.config import compose_config
    from charctl.experiments.com_cnn.config import Config

    return compose_config("com-cnn", list(overrides), Config)


def ry(theta: float) -> np.ndarray:
    """Rotation matrix about +y (written out by hand, independent of charctl.motion.rotations)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


# ---------------------------------------------------------------------------- windows
def synthetic_sequence(body, T: int = 12):
    """Root walking along a bent line, pure-yaw root rotations a_k, the chest's exp map = (0.01 k, 0, 0)."""
    from charctl.experiments.com_cnn.sequences import Sequence

    k = np.arange(T, dtype=float)
    yaw = 0.1 * k - 0.3
    root_pos = np.stack([0.05 * k, 0.9 + 0.01 * np.sin(k), 0.03 * k * k], axis=1)
    root_rot = R.heading_quat(yaw)
    joints = np.tile(R.IDENTITY, (T, body.num_joints, 1))
    joints[:, 0] = R.exp_map(np.stack([0.01 * k, np.zeros(T), np.zeros(T)], axis=1))
    seq = Sequence("synthetic", "synthetic", "walk", 30.0, root_pos, root_rot, joints)
    seq.com = body.com(root_pos, root_rot, joints)
    return seq, yaw


@pytest.mark.parametrize("frame", ["root_t", "root_prev"])
def test_windows_target_is_frame_t_history_ends_at_t_minus_1_in_the_reference_root_frame(frame):
    from charctl.experiments.com_cnn.body import humanoid_body
    from charctl.experiments.com_cnn.config import ComConfig
    from charctl.experiments.com_cnn.data import WindowSet

    body = humanoid_body(ComConfig())
    seq, yaw = synthetic_sequence(body)
    i = 4
    w = WindowSet([seq], body, i, frame)
    assert list(w.targets) == list(range(1, 12))  # every frame with an earlier one is a target
    hist, com, target = w.features(np.arange(len(w)))
    assert hist.shape == (11, i, 48) and com.shape == (11, 3) and target.shape == (11, 48)
    for n, t in enumerate(w.targets):
        r = t if frame == "root_t" else t - 1
        # the humanoid faces its +x axis: heading psi = a + pi/2; the frame turns by -psi about y
        inv = ry(-(yaw[r] + math.pi / 2))
        origin = seq.root_pos[r] * np.array([1.0, 0.0, 1.0])
        hist_frames = [max(k, 0) for k in range(t - i, t)]  # edge-padded at the clip start
        for h, k in enumerate(hist_frames):
            np.testing.assert_allclose(hist[n, h, 0:3], inv @ (seq.root_pos[k] - origin), atol=1e-5)
            np.testing.assert_allclose(hist[n, h, 3:6], [0.0, yaw[k] - yaw[r] - math.pi / 2, 0.0], atol=1e-5)
            np.testing.assert_allclose(hist[n, h, 6:9], [0.01 * k, 0.0, 0.0], atol=1e-6)  # chest = frame k's
        np.testing.assert_allclose(target[n, 6:9], [0.01 * t, 0.0, 0.0], atol=1e-6)  # target = frame t
        np.testing.assert_allclose(target[n, 0:3], inv @ (seq.root_pos[t] - origin), atol=1e-5)
        np.testing.assert_allclose(com[n], inv @ (seq.com[t] - origin), atol=1e-5)
    if frame == "root_t":  # in its own heading frame the root sits at x = z = 0, facing +z
        np.testing.assert_allclose(target[:, [0, 2]], 0.0, atol=1e-6)
        np.testing.assert_allclose(target[:, 3:6], np.tile([0.0, -math.pi / 2, 0.0], (11, 1)), atol=1e-5)


def test_looping_clips_are_tiled_without_jumps_and_start_at_the_origin_facing_plus_z():
    from charctl.experiments.com_cnn.sequences import heading_yaw, load_sequences
    from charctl.motion.library import load_clip

    cfg = compose("data.clips=[walker/turn_right0]", "data.test_clips=[]", "data.mirror=false")
    (seq,), body = load_sequences(cfg)
    raw = load_clip("walker/turn_right0").resample(30.0)
    assert (
        seq.cycles == math.ceil(6.0 * 30 / (raw.num_frames - 1))
        and seq.num_frames == seq.cycles * (raw.num_frames - 1) + 1
    )
    np.testing.assert_allclose(seq.root_pos[0, [0, 2]], 0.0, atol=1e-9)
    assert heading_yaw(seq.root_rot[0], body.forward) == pytest.approx(0.0, abs=1e-9)

    def step(p):
        return np.linalg.norm(np.diff(p[:, [0, 2]], axis=0), axis=1).max()

    assert step(seq.root_pos) < 1.2 * step(raw.root_pos)  # the root path continues across the seams

    def joint_step(q):
        return np.degrees(R.angle_between(q[1:], q[:-1])).max()

    # this clip's loop is 53 deg off at the neck; blended over 6 frames the seams stay near the clip's own steps
    assert joint_step(seq.joint_rot) < 1.3 * joint_step(raw.local_rot[:, 1:])
    total_turn = np.unwrap(heading_yaw(seq.root_rot, body.forward))
    one_cycle = np.unwrap(heading_yaw(raw.local_rot[:, 0], np.array([1.0, 0.0, 0.0])))
    assert total_turn[-1] == pytest.approx(
        seq.cycles * (one_cycle[-1] - one_cycle[0]), abs=0.05
    )  # the turn accumulates


# ---------------------------------------------------------------------------- the paper's COM
def test_humanoid_com_from_the_paper_mass_table_matches_a_hand_computation():
    from charctl.experiments.com_cnn.body import humanoid_body
    from charctl.experiments.com_cnn.config import ComConfig

    body = humanoid_body(ComConfig())
    skel = body.skeleton
    assert body.masses.sum() == pytest.approx(62.0)
    assert body.masses[skel.index("chest")] == 20.0 and body.masses[skel.index("root")] == 10.0
    assert body.masses[skel.index("left_knee")] == 4.0 and body.masses[skel.index("right_wrist")] == 0.5
    # zero pose, root at p, turned 90 deg about y: body b sits at p + Ry(90) (sum of offsets to b + its COM offset)
    p = np.array([0.3, 0.9, -1.2])
    turn = ry(math.pi / 2)
    total = np.zeros(3)
    for b in range(skel.num_bodies):
        chain, j = np.zeros(3), b
        while j > 0:
            chain += skel.offsets[j]
            j = skel.parents[j]
        total += body.masses[b] * (p + turn @ (chain + skel.com_local[b]))
    expected = total / 62.0
    joints = np.tile(R.IDENTITY, (body.num_joints, 1))
    got = body.com(p, R.heading_quat(np.array(math.pi / 2)), joints)
    np.testing.assert_allclose(got, expected, atol=1e-9)


BVH_TEXT = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 1 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT Head
    {
      OFFSET 0 0.5 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 0.2 0
      }
    }
  }
  JOINT LeftUpLeg
  {
    OFFSET 0.1 -0.1 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 -0.4 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0333333
1 0 0 0 0 0 0 0 0 0 0 0 0 0 0
1 0 0 0 0 90 0 0 0 0 0 0 0 0 0
"""


def test_bvh_com_puts_each_part_mass_halfway_to_its_child_hand_computed(tmp_path):
    from charctl.experiments.com_cnn.sequences import bvh_body
    from charctl.motion.bvh import read_bvh

    path = tmp_path / "tiny.bvh"
    path.write_text(BVH_TEXT)
    motion = read_bvh(path)
    body = bvh_body(motion, path, compose())
    trans, rot = motion.local_transforms()
    com = body.com(trans[:, 0], rot[:, 0], rot[:, 1:])
    # Hips 10 at (1, .5, 0) (halfway to Spine, its first child); Spine 20 at (1, 1.25, 0);
    # Head 5 at (1, 1.6, 0) (halfway to the end site); LeftUpLeg 5 at joint + half its end site.
    upright = (
        10 * np.array([1, 0.5, 0])
        + 20 * np.array([1, 1.25, 0])
        + 5 * np.array([1, 1.6, 0])
        + 5 * np.array([1.1, -0.3, 0])
    ) / 40
    # frame 2: Hips turned +90 deg about y: the leg offset (0.1, -0.1, 0) becomes (0, -0.1, -0.1)
    turned = (
        10 * np.array([1, 0.5, 0])
        + 20 * np.array([1, 1.25, 0])
        + 5 * np.array([1, 1.6, 0])
        + 5 * np.array([1.0, -0.3, -0.1])
    ) / 40
    np.testing.assert_allclose(com, [upright, turned], atol=1e-6)
    assert body.pose_dim == 6 + 3 * 3


# ---------------------------------------------------------------------------- the network
def test_network_shapes_follow_the_paper_table_2():
    from charctl.experiments.com_cnn.body import humanoid_body
    from charctl.experiments.com_cnn.config import ComConfig
    from charctl.experiments.com_cnn.model import ComCNN

    assert humanoid_body(ComConfig()).pose_dim == 48  # 15 x 3 angles + root position
    net = ComCNN(48, 90, [32, 64, 128], kernel=10)
    x = torch.zeros(5, 48, 90)
    shapes = []
    for layer in net.conv:
        x = layer(x)
        if isinstance(layer, torch.nn.MaxPool1d):
            shapes.append(tuple(x.shape[1:]))
    assert shapes == [(32, 40), (64, 15), (128, 3)]  # Table 2: 40x32, 15x64, 3x128
    assert net.z_dim == 384 and net.fc[0].in_features == 387  # Z, then K = [Z, C_t]
    assert isinstance(net.fc[1], torch.nn.Identity)  # P(K) = W1(W0 K + b0) + b1
    out = net(torch.zeros(5, 90, 48), torch.zeros(5, 3))
    assert out.shape == (5, 48)
    assert ComCNN(48, 90, [32, 64, 128], use_com=False).fc[0].in_features == 384
    assert ComCNN(48, 15, [8, 16, 32], kernel=2).z_dim == 32  # Table 4: 15 -> 14 -> 7 -> 6 -> 3 -> 2 -> 1


def test_too_short_history_for_the_layers_is_a_one_line_config_error():
    with pytest.raises(CharctlError) as exc:
        compose("data.history=15", "model.kernel=10")
    assert_one_line(exc.value, "too short")


# ---------------------------------------------------------------------------- learning
def test_tiny_training_run_lowers_the_loss_and_resumes(tmp_path):
    from charctl.experiments.com_cnn.config import Config
    from charctl.experiments.com_cnn.data import build_windows
    from charctl.experiments.com_cnn.model import build_model
    from charctl.experiments.com_cnn.train import BatchSource, normalizer_stats, teacher_forced, train
    from charctl.runs import new_run, open_run

    cfg = compose(*TINY_COM_CNN, "train.steps=150", f"output_root={tmp_path}")
    run = new_run(cfg)
    metrics = train(cfg, run)
    run.close()
    train_w, _, body = build_windows(cfg)
    source = BatchSource(train_w, "cpu", 512)
    torch.manual_seed(cfg.seed)
    fresh = build_model(cfg, body.pose_dim)  # the weights training started from (same seed)
    fresh.set_normalizer(normalizer_stats(source))
    trained = build_model(cfg, body.pose_dim)
    trained.load_state_dict(run.load_checkpoint()["model"])
    before = teacher_forced(fresh, source)[2]
    after = teacher_forced(trained, source)[2]
    assert after < 0.5 * before, (before, after)
    assert metrics["step"] == 150 and metrics["samples_per_s"] > 0
    # --resume continues from the checkpoint's step
    resumed = open_run(run.dir, Config, ["train.steps=160"])
    assert train(resumed.cfg, resumed)["step"] == 160
    resumed.close()


# ---------------------------------------------------------------------------- the paper's safety clamp
def test_com_clamp_never_moves_more_than_the_limit_and_keeps_the_direction():
    from charctl.experiments.com_cnn.com_path import clamp_com_path

    rng = np.random.default_rng(3)
    path = np.cumsum(rng.normal(0, 0.05, size=(400, 3)), axis=0)
    path[100] += [3.0, -2.0, 1.0]  # a teleport
    path[250:] += 10.0  # a jump that stays
    start = np.array([0.0, 0.9, 0.0])
    limit = 0.07
    out = clamp_com_path(path, start, limit)
    prev = np.concatenate([start[None], out[:-1]])
    steps = out - prev
    assert np.all(np.linalg.norm(steps, axis=1) <= limit + 1e-12)
    wanted = path - prev  # where each input point asked to go from the last clamped point
    cos = np.sum(steps * wanted, axis=1) / (np.linalg.norm(steps, axis=1) * np.linalg.norm(wanted, axis=1))
    np.testing.assert_allclose(cos, 1.0, atol=1e-9)  # same direction
    small = np.linalg.norm(wanted, axis=1) <= limit
    np.testing.assert_allclose(out[small], path[small])  # steps within the limit pass unchanged
    assert small.sum() > 50 and (~small).sum() > 10  # both cases occur


# ---------------------------------------------------------------------------- the split
@pytest.mark.parametrize("test_clips", [None, ["walk", "kick"], ["walker/turn_left0", "run", "spin", "crawl"]])
def test_split_never_puts_a_clip_and_its_mirror_on_both_sides(test_clips):
    from charctl.experiments.com_cnn.sequences import load_sequences, split_sequences

    cfg = compose() if test_clips is None else compose(f"data.test_clips=[{','.join(test_clips)}]")
    seqs, _ = load_sequences(cfg)
    train, test = split_sequences(seqs, cfg.data.test_clips)
    train_names, test_names = {s.name for s in train}, {s.name for s in test}
    assert test and train and not train_names & test_names
    for s in test:
        twin = s.name[:-7] if s.name.endswith(":mirror") else s.name + ":mirror"
        assert twin in test_names and twin not in train_names
    assert {s.base for s in test} == set(cfg.data.test_clips)
    assert len(train) + len(test) == 2 * len(cfg.data.clips)


# ---------------------------------------------------------------------------- COM paths
def test_com_path_csv_problems_are_one_line_errors(tmp_path, capsys):
    from charctl.experiments.com_cnn.com_path import make_com_path

    gen = compose().generate
    start = np.array([0.0, 0.9, 0.0])

    def csv(name: str, text: str) -> str:
        (tmp_path / name).write_text(text)
        return str(tmp_path / name)

    for text, words in [
        ("a,b,c\n1,2,3\n", "header"),
        ("x,y\n0,1\n0,1\n", "header"),
        ("x,y,z\n0,0.9,0\n0,nan,0.1\n", "NaN"),
        ("x,y,z\n0,0.9,0\n0,0.9\n", "line 3"),
        ("x,y,z\n0,0.9,0\n0,abc,0\n", "not a number"),
        ("t,x,y,z\n0,0,0.9,0\n0,0,0.9,0.1\n", "increase"),
    ]:
        with pytest.raises(CharctlError) as exc:
            make_com_path(csv("bad.csv", text), start, 1.0, 30.0, None, gen)
        assert_one_line(exc.value, words)
    jumpy = csv("jump.csv", "x,y,z\n0,0.9,0\n0,0.9,0.03\n0,0.9,1.5\n0,0.9,1.53\n")
    path = make_com_path(jumpy, start, 1.0, 30.0, None, gen)  # clamped, with a one-line note
    note = capsys.readouterr().out.strip().splitlines()
    assert len(note) == 1 and "jump of 1.47 m between frames 1 and 2" in note[0]
    assert np.all(np.linalg.norm(np.diff(path, axis=0), axis=1) <= gen.max_com_step + 1e-12)
    gen.com_clamp = False
    with pytest.raises(CharctlError) as exc:
        make_com_path(jumpy, start, 1.0, 30.0, None, gen)
    assert_one_line(exc.value, "jump")
    timed = make_com_path(csv("t.csv", "t,x,y,z\n0,5,0.9,5\n1,5,0.9,6\n"), start, 1.0, 30.0, None, gen)
    assert timed.shape == (31, 3)  # 1 s at 30 fps, both ends
    np.testing.assert_allclose(timed[0], start)  # moved onto the seed's COM horizontally
    np.testing.assert_allclose(timed[-1], [0.0, 0.9, 1.0])


def test_circle_path_has_the_asked_radius_speed_and_crouch():
    from charctl.experiments.com_cnn.com_path import make_com_path

    gen = compose().generate
    start = np.array([0.2, 0.95, -0.1])
    path = make_com_path("circle:r=2,speed=1.2", start, 5.0, 30.0, 2.0, gen)
    assert path.shape == (150, 3)
    centre = start + np.array([2.0, 0.0, 0.0])  # facing +z, a left turn circles the +x side
    np.testing.assert_allclose(np.linalg.norm((path - centre)[:, [0, 2]], axis=1), 2.0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(np.diff(path[:50, [0, 2]], axis=0), axis=1), 1.2 / 30, rtol=1e-3)
    assert path[59, 1] == pytest.approx(0.95) and path[-1, 1] == pytest.approx(0.95 - gen.crouch_drop)


# ---------------------------------------------------------------------------- a user's BVH folder
def test_bvh_folder_dataset_and_generic_bvh_writer_round_trip(tmp_path):
    from charctl.experiments.com_cnn.config import HUMANOID_BODIES
    from charctl.experiments.com_cnn.data import build_windows
    from charctl.experiments.com_cnn.generate import write_generic_bvh
    from charctl.motion.bvh import read_bvh, write_bvh
    from charctl.motion.library import load_clip

    folder = tmp_path / "mocap"
    for name in ("walk", "run"):
        write_bvh(load_clip(name), folder / f"{name}_01.bvh")
    mapping = ",".join(f"{k}:{v}" for k, v in HUMANOID_BODIES.items())
    cfg = compose(
        f"data.bvh_dir={folder}",
        "data.test_clips=[run_01]",
        f"com.bvh_joints={{{mapping}}}",
        "data.bvh_forward=[1,0,0]",
    )
    train_w, test_w, body = build_windows(cfg)
    assert body.kind == "bvh" and body.pose_dim == 48 and body.masses.sum() == pytest.approx(62.0)
    assert [s.label for s in train_w.seqs] == ["walk"] and [s.label for s in test_w.seqs] == ["run"]
    seq = train_w.seqs[0]
    out = write_generic_bvh(body, seq.root_pos, seq.root_rot, seq.joint_rot, 30.0, tmp_path / "back.bvh")
    trans, rot = read_bvh(out).local_transforms()
    np.testing.assert_allclose(trans[:, 0], seq.root_pos, atol=1e-5)
    assert np.degrees(R.angle_between(rot[:, 1:], seq.joint_rot)).max() < 1e-3
    with pytest.raises(CharctlError) as exc:
        build_windows(compose(f"data.bvh_dir={folder}", "data.test_clips=[run_01]"))  # joints named root, chest, ...
    assert_one_line(exc.value, "com.bvh_joints")
    with pytest.raises(CharctlError) as exc:
        build_windows(compose(f"data.bvh_dir={folder}", f"com.bvh_joints={{{mapping}}}"))  # DeepMimic test clip names
    assert_one_line(exc.value, "data.test_clips")


# ---------------------------------------------------------------------------- end to end
def test_smoke_train_eval_export_end_to_end(tmp_path, smoke_run_copy, charctl_main):
    """`charctl train com-cnn scale=smoke` (the session's run through the console script, conftest.smoke_run:
    it asserts exit 0), then `charctl eval` and `charctl export` on a copy of it, called in this process."""
    run_dir = smoke_run_copy("com-cnn")
    assert (run_dir / "checkpoints" / "last.pt").is_file() and (run_dir / "config.yaml").is_file()
    assert any((run_dir / "tb").iterdir())
    res = charctl_main("eval", str(run_dir), "--pose-error", "--dtw", "-o", str(tmp_path / "eval"))
    assert res.returncode == 0, res.stderr[-2000:]
    report = (tmp_path / "eval" / "report.md").read_text()
    assert "nearest neighbour" in report and "paper Table 5" in report and "DTW" in report
    assert (tmp_path / "eval" / "ar_curve.png").stat().st_size > 1000
    import json

    result = json.loads((tmp_path / "eval" / "pose_error.json").read_text())
    tf = result["teacher_forced"]
    assert all(0.0 < r["all"] < 90.0 for r in tf.values())
    res = charctl_main(
        "export",
        str(run_dir),
        "--com-path",
        "circle:r=1.5,speed=1.0",
        "--seconds",
        "1",
        "--bvh",
        str(tmp_path / "gen.bvh"),
    )
    assert res.returncode == 0, res.stderr[-2000:]
    from charctl.motion.bvh import read_bvh

    motion = read_bvh(tmp_path / "gen.bvh")
    assert motion.num_frames == 90 + 30 and np.all(np.isfinite(motion.frames))
    assert "frames/s" in res.stdout
    bad = charctl_main("export", str(run_dir), "--com-path", str(tmp_path / "missing.csv"))
    assert_one_line_error(bad, "com path")
