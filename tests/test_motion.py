"""Motion library: skeleton, FK, COM, DeepMimic I/O, mirror, resample, canonicalize, velocities.

Independent references: pybullet's own loader/FK of `humanoid.urdf` (joint positions, link
orientations, link centres of mass, masses), scipy's Slerp/Rotation, and hand arithmetic on the
URDF's numbers. Quaternions are xyzw; world is y-up, +x forward, +z right.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from charctl.errors import CharctlError
from charctl.motion import rotations as R
from charctl.motion.clip import Clip
from charctl.motion.deepmimic import FRAME_SIZE, LAYOUT, decode_frames, encode_frames
from charctl.motion.library import catalogue, clip_names, load_clip
from charctl.motion.skeleton import BODY_NAMES, CLIP_JOINTS, HINGE_JOINTS, humanoid_urdf_path, load_skeleton

from conftest import assert_one_line

FK_CLIPS = ["walk", "kick:mirror", "backflip", "walker/turn_left0", "roll"]


# ---------------------------------------------------------------------------- pybullet reference
@pytest.fixture(scope="module")
def bullet():
    """pybullet's humanoid (DIRECT mode, loaded once): (client, body id, {link name: joint index})."""
    pb = pytest.importorskip("pybullet")
    cid = pb.connect(pb.DIRECT)
    body = pb.loadURDF(
        str(humanoid_urdf_path()), globalScaling=0.25, flags=pb.URDF_MAINTAIN_LINK_ORDER, physicsClientId=cid
    )
    links = {
        pb.getJointInfo(body, j, physicsClientId=cid)[12].decode(): j
        for j in range(pb.getNumJoints(body, physicsClientId=cid))
    }
    yield pb, cid, body, links
    pb.disconnect(cid)


def bullet_pose(bullet, clip: Clip, frame: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Set one clip frame on pybullet's humanoid; return link frame positions (B,3), orientations
    (B,4 xyzw) and link COM positions (B,3), in BODY_NAMES order."""
    pb, cid, body, links = bullet
    pb.resetBasePositionAndOrientation(
        body, clip.root_pos[frame].tolist(), clip.local_rot[frame, 0].tolist(), physicsClientId=cid
    )
    for b, name in enumerate(BODY_NAMES[1:], start=1):
        q = clip.local_rot[frame, b]
        if name in HINGE_JOINTS:
            pb.resetJointState(body, links[name], 2.0 * math.atan2(q[2], q[3]), physicsClientId=cid)
        elif name in CLIP_JOINTS:  # spherical
            pb.resetJointStateMultiDof(body, links[name], q.tolist(), physicsClientId=cid)
    states = [pb.getLinkState(body, links[n], computeForwardKinematics=True, physicsClientId=cid) for n in BODY_NAMES]
    return (np.array([s[4] for s in states]), np.array([s[5] for s in states]), np.array([s[0] for s in states]))


@pytest.mark.parametrize("spec", FK_CLIPS)
def test_fk_matches_pybullet(bullet, spec):
    clip = load_clip(spec)
    frames = range(clip.num_frames)
    ref = [bullet_pose(bullet, clip, f) for f in frames]
    ref_pos = np.stack([r[0] for r in ref])
    ref_rot = np.stack([r[1] for r in ref])
    err = np.linalg.norm(ref_pos - clip.body_pos, axis=-1)
    assert err.mean() < 0.01, f"{spec}: mean joint position error {err.mean():.3g} m"
    assert err.max() < 1e-4, f"{spec}: max joint position error {err.max():.3g} m"
    # world orientations of every body frame agree too (up to quaternion sign)
    # (|q1 -+ q2| is ~half the rotation angle between them and, unlike arccos, accurate near zero)
    dq = np.minimum(np.linalg.norm(ref_rot - clip.body_rot, axis=-1), np.linalg.norm(ref_rot + clip.body_rot, axis=-1))
    assert dq.max() < 1e-5, f"{spec}: max body orientation error {2 * dq.max():.3g} rad"
    # and the clip actually moves (the comparison is not on a static pose)
    assert np.ptp(clip.body_pos[:, BODY_NAMES.index("right_ankle")], axis=0).max() > 0.1


def test_skeleton_matches_pybullet_masses_and_com(bullet):
    pb, cid, body, links = bullet
    skel = load_skeleton()
    assert skel.names == BODY_NAMES and skel.num_bodies == 15
    masses = np.array([pb.getDynamicsInfo(body, links[n], physicsClientId=cid)[0] for n in BODY_NAMES])
    np.testing.assert_allclose(skel.masses, masses)
    assert skel.masses.sum() == pytest.approx(45.0)
    # parents precede children and the root has none
    assert skel.parents[0] == -1 and all(0 <= skel.parents[b] < b for b in range(1, 15))


@pytest.mark.parametrize("spec", ["walk", "spinkick", "kick:mirror"])
def test_com_matches_pybullet_link_coms(bullet, spec):
    pb, cid, body, links = bullet
    clip = load_clip(spec)
    masses = np.array([pb.getDynamicsInfo(body, links[n], physicsClientId=cid)[0] for n in BODY_NAMES])
    frames = np.linspace(0, clip.num_frames - 1, 8).astype(int)
    ref = np.stack([bullet_pose(bullet, clip, f)[2] for f in frames])  # (F, B, 3) link COMs
    ref_com = np.einsum("fbi,b->fi", ref, masses) / masses.sum()
    np.testing.assert_allclose(clip.com()[frames], ref_com, atol=1e-5)


# ---------------------------------------------------------------------------- COM by hand
def _rest_clip(root_pos=(0.0, 0.0, 0.0), root_rot=R.IDENTITY, frames: int = 2) -> Clip:
    rot = np.tile(R.IDENTITY, (frames, 15, 1))
    rot[:, 0] = root_rot
    return Clip(name="rest", fps=30.0, root_pos=np.tile(np.asarray(root_pos, float), (frames, 1)), local_rot=rot)


# Rest-pose body COM heights and masses written out from the URDF's numbers (URDF units = 4 m).
_CHEST_Y = 0.944604
_SHOULDER = (-0.0962, _CHEST_Y + 0.974)
_ELBOW_Y = _SHOULDER[1] - 1.099152
_KNEE_Y = -1.686184
_ANKLE_Y = _KNEE_Y - 1.639480
_REST_BODIES = [  # (mass kg, com x, com y) per body, left and right listed separately; z cancels
    (6.0, 0.0, 0.28),
    (14.0, 0.0, _CHEST_Y + 0.48),
    (2.0, 0.0, _CHEST_Y + 0.895576 + 0.7),
] + 2 * [
    (4.5, 0.0, -0.84),
    (3.0, 0.0, _KNEE_Y - 0.8),
    (1.0, 0.18, _ANKLE_Y - 0.09),
    (1.5, _SHOULDER[0], _SHOULDER[1] - 0.56),
    (1.0, _SHOULDER[0], _ELBOW_Y - 0.48),
    (0.5, _SHOULDER[0], _ELBOW_Y - 1.035788),
]


def _hand_rest_com() -> np.ndarray:
    m = np.array([b[0] for b in _REST_BODIES])
    x = np.array([b[1] for b in _REST_BODIES])
    y = np.array([b[2] for b in _REST_BODIES])
    return 0.25 * np.array([m @ x / m.sum(), m @ y / m.sum(), 0.0])


def test_com_rest_pose_by_hand():
    hand = _hand_rest_com()
    assert hand[1] == pytest.approx(0.0107487, abs=1e-6)  # 1.934764 / 45 * 0.25
    clip = _rest_clip()
    np.testing.assert_allclose(clip.com(), np.tile(hand, (2, 1)), atol=1e-9)
    # moved to (1, 0.9, -2) and turned 180 degrees about +y: x and z flip, then translate
    moved = _rest_clip(root_pos=(1.0, 0.9, -2.0), root_rot=R.heading_quat(np.array(np.pi)))
    expect = np.array([1.0 - hand[0], 0.9 + hand[1], -2.0 - hand[2]])
    np.testing.assert_allclose(moved.com()[0], expect, atol=1e-9)


def test_com_user_mass_table():
    clip = load_clip("walk")
    skel = clip.skeleton
    chest = skel.index("chest")
    # all mass in the chest: COM = the chest's COM (joint + com_local rotated)
    only_chest = np.zeros(15)
    only_chest[chest] = 3.0
    chest_com = clip.body_pos[:, chest] + R.rotate(
        clip.body_rot[:, chest], np.broadcast_to(skel.com_local[chest], (clip.num_frames, 3))
    )
    np.testing.assert_allclose(clip.com(only_chest), chest_com, atol=1e-12)
    # an extra 6 kg on the root: weighted average of the old COM and the root's COM
    heavier = skel.masses.copy()
    heavier[0] += 6.0
    root_com = clip.body_pos[:, 0] + R.rotate(
        clip.local_rot[:, 0], np.broadcast_to(skel.com_local[0], (clip.num_frames, 3))
    )
    np.testing.assert_allclose(clip.com(heavier), (45.0 * clip.com() + 6.0 * root_com) / 51.0, atol=1e-12)
    # scaling every mass by a constant changes nothing; the default is the model masses
    np.testing.assert_allclose(clip.com(2.5 * skel.masses), clip.com(), atol=1e-12)
    np.testing.assert_allclose(clip.com(skel.masses), clip.com(), atol=0)


# ---------------------------------------------------------------------------- library
def test_catalogue_has_twenty_clips_that_load():
    entries = catalogue()
    assert len(entries) == 20 and [e.name for e in entries] == clip_names()
    for e in entries:
        clip = load_clip(e.name)
        assert clip.num_frames >= 20 and clip.local_rot.shape == (clip.num_frames, 15, 4)
        assert clip.label == e.label and np.all(np.isfinite(clip.root_pos))
        np.testing.assert_allclose(np.linalg.norm(clip.local_rot, axis=-1), 1.0, atol=1e-9)
        # wrists are fixed joints: always identity
        wrists = [BODY_NAMES.index("right_wrist"), BODY_NAMES.index("left_wrist")]
        np.testing.assert_allclose(np.abs(clip.local_rot[:, wrists, 3]), 1.0, atol=1e-12)


def test_unknown_clip_is_one_line_error_with_suggestion():
    with pytest.raises(CharctlError) as exc:
        load_clip("wlak")
    assert_one_line(exc.value, "'wlak'", "walk")


def test_walk_decodes_the_raw_file(walk_raw_frames):
    clip = load_clip("walk")
    raw = walk_raw_frames
    assert clip.num_frames == raw.shape[0] and clip.loop
    assert clip.fps == pytest.approx(1.0 / raw[0, 0])
    np.testing.assert_allclose(clip.root_pos, raw[:, 1:4], atol=0)
    # root rotation: file is w-x-y-z, clip is x-y-z-w
    np.testing.assert_allclose(
        R.angle_between(clip.local_rot[:, 0], Rotation.from_quat(raw[:, [5, 6, 7, 4]]).as_quat()), 0.0, atol=1e-6
    )
    # hinge joints: the knee angle is a rotation about +z
    col = dict((j, c) for j, c, _ in LAYOUT)["right_knee"]
    knee = clip.local_rot[:, BODY_NAMES.index("right_knee")]
    np.testing.assert_allclose(knee, Rotation.from_rotvec(np.outer(raw[:, col], [0, 0, 1])).as_quat(), atol=1e-12)


# ---------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("spec", ["walk", "backflip", "kick:mirror", "roll"])
def test_deepmimic_round_trip(spec):
    clip = load_clip(spec)
    frames = encode_frames(clip)
    assert frames.shape == (clip.num_frames, FRAME_SIZE)
    back = decode_frames(frames, clip.name, loop=clip.loop)
    assert back.num_frames == clip.num_frames and back.fps == pytest.approx(clip.fps)
    np.testing.assert_allclose(back.root_pos, clip.root_pos, atol=1e-12)
    assert R.angle_between(back.local_rot, clip.local_rot).max() < 1e-7
    np.testing.assert_allclose(back.body_pos, clip.body_pos, atol=1e-9)


def test_deepmimic_file_round_trip(tmp_path):
    from charctl.motion.deepmimic import write_deepmimic

    clip = load_clip("walker/turn_right0")
    path = tmp_path / "turn.txt"
    write_deepmimic(clip, path)
    back = load_clip(str(path))
    assert back.loop == clip.loop and back.num_frames == clip.num_frames
    np.testing.assert_allclose(back.body_pos, clip.body_pos, atol=1e-6)


@pytest.mark.parametrize("spec", ["walk", "cartwheel", "walker/turn_left1"])
def test_mirror_twice_is_identity(spec):
    clip = load_clip(spec)
    twice = clip.mirror().mirror()
    assert twice.name == clip.name
    np.testing.assert_allclose(twice.root_pos, clip.root_pos, atol=1e-12)
    assert R.angle_between(twice.local_rot, clip.local_rot).max() < 1e-7
    np.testing.assert_allclose(twice.body_pos, clip.body_pos, atol=1e-12)


@pytest.mark.parametrize("spec", ["kick", "walker/turn_left0"])
def test_mirror_reflects_every_joint(spec):
    """The mirrored clip's joint world positions are the original's with z negated and left/right swapped."""
    clip = load_clip(spec)
    mir = load_clip(spec + ":mirror")
    assert mir.name == spec + ":mirror"
    perm = clip.skeleton.mirror_perm
    np.testing.assert_allclose(mir.body_pos[:, perm], clip.body_pos * np.array([1.0, 1.0, -1.0]), atol=1e-9)
    np.testing.assert_allclose(mir.com(), clip.com() * np.array([1.0, 1.0, -1.0]), atol=1e-9)
    # heading flips sign (a left turn becomes a right turn)
    wrapped = np.angle(np.exp(1j * (mir.heading() + clip.heading())))
    np.testing.assert_allclose(wrapped, 0.0, atol=1e-9)


def test_mirrored_kick_uses_the_left_foot():
    kick, mir = load_clip("kick"), load_clip("kick:mirror")
    r, l = BODY_NAMES.index("right_ankle"), BODY_NAMES.index("left_ankle")
    assert kick.body_pos[:, r, 1].max() > kick.body_pos[:, l, 1].max() + 0.3
    assert mir.body_pos[:, l, 1].max() > mir.body_pos[:, r, 1].max() + 0.3


@pytest.mark.parametrize("fps", [47.0, 120.0, 10.0])
def test_resample_keeps_duration_and_end_poses(fps):
    clip = load_clip("walk")
    res = clip.resample(fps)
    assert res.num_frames == round(clip.duration * fps) + 1
    assert res.duration == pytest.approx(clip.duration, rel=1e-12)
    assert abs(res.fps - fps) < fps / res.num_frames  # within one frame of the request
    for a, b in [(0, 0), (-1, -1)]:
        np.testing.assert_allclose(res.root_pos[a], clip.root_pos[b], atol=1e-12)
        assert R.angle_between(res.local_rot[a], clip.local_rot[b]).max() < 1e-7


def test_resample_interpolates_like_scipy_slerp():
    clip = load_clip("run")
    res = clip.resample(clip.fps * 3)
    t_src, t_new = clip.times, res.times * (clip.duration / res.duration)
    for b in (0, BODY_NAMES.index("right_hip"), BODY_NAMES.index("left_knee")):
        ref = Slerp(t_src, Rotation.from_quat(clip.local_rot[:, b]))(np.clip(t_new, 0, t_src[-1])).as_quat()
        assert R.angle_between(res.local_rot[:, b], ref).max() < 1e-6
    ref_pos = np.stack([np.interp(t_new, t_src, clip.root_pos[:, i]) for i in range(3)], axis=1)
    np.testing.assert_allclose(res.root_pos, ref_pos, atol=1e-9)


def test_resample_30_120_30_returns_the_original():
    clip = load_clip("walker/walk_forward")  # exactly 30 fps
    back = clip.resample(120).resample(30)
    assert back.num_frames == clip.num_frames
    np.testing.assert_allclose(back.root_pos, clip.root_pos, atol=1e-9)
    assert R.angle_between(back.local_rot, clip.local_rot).max() < 1e-6


# ---------------------------------------------------------------------------- transforms, velocities
@pytest.mark.parametrize("facing,angle", [("+x", 0.0), ("+z", -np.pi / 2)])
def test_canonicalize(facing, angle):
    clip = load_clip("walker/turn_left0")
    k = 10
    can = clip.canonicalize(frame=k, facing=facing)
    assert can.heading()[k] == pytest.approx(angle, abs=1e-9)
    np.testing.assert_allclose(can.root_pos[k], [0.0, clip.root_pos[k, 1], 0.0], atol=1e-12)
    # a rigid motion of the whole clip: pairwise joint distances and heights are unchanged
    d0 = np.linalg.norm(clip.body_pos[:, :, None] - clip.body_pos[:, None], axis=-1)
    d1 = np.linalg.norm(can.body_pos[:, :, None] - can.body_pos[:, None], axis=-1)
    np.testing.assert_allclose(d1, d0, atol=1e-9)
    np.testing.assert_allclose(can.body_pos[..., 1], clip.body_pos[..., 1], atol=1e-9)


def test_cross_matches_numpy_with_broadcasting():
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal((5, 4, 3)), rng.standard_normal((4, 3))
    np.testing.assert_allclose(R.cross(a, b), np.cross(a, b), atol=1e-14)
    assert R.cross(np.array([1.0, 0, 0]), np.array([0, 1.0, 0])).tolist() == [0.0, 0.0, 1.0]


def test_heading_of_known_rotations():
    th = np.array([0.0, 0.3, -1.2, 3.0])
    q = R.heading_quat(th)
    np.testing.assert_allclose(R.yaw_about_y(q), th, atol=1e-12)
    # +90 degrees about +y turns +x into -z
    np.testing.assert_allclose(
        R.rotate(R.heading_quat(np.array(np.pi / 2)), np.array([1.0, 0, 0])), [0, 0, -1], atol=1e-12
    )


def test_velocities_of_a_synthetic_spin_and_drift():
    """Root drifting at (1, 0, 0.5) m/s and spinning at 2 rad/s about +y; chest bending at 0.5 rad/s about +z."""
    fps, T = 60.0, 31
    t = np.arange(T) / fps
    rot = np.tile(R.IDENTITY, (T, 15, 1))
    rot[:, 0] = R.heading_quat(2.0 * t)
    rot[:, 1] = R.from_axis_angle(np.array([0.0, 0.0, 1.0]), 0.5 * t)
    pos = np.stack([1.0 * t, np.full(T, 0.9), 0.5 * t], axis=1)
    clip = Clip(name="synthetic", fps=fps, root_pos=pos, local_rot=rot)
    np.testing.assert_allclose(clip.root_linear_velocity(), np.tile([1.0, 0.0, 0.5], (T, 1)), atol=1e-9)
    np.testing.assert_allclose(clip.body_linear_velocity()[:, 0], np.tile([1.0, 0.0, 0.5], (T, 1)), atol=1e-9)
    w = clip.world_angular_velocity()
    np.testing.assert_allclose(w[:, 0], np.tile([0.0, 2.0, 0.0], (T, 1)), atol=1e-9)
    loc = clip.local_angular_velocity()
    np.testing.assert_allclose(loc[:, 0], np.tile([0.0, 2.0, 0.0], (T, 1)), atol=1e-9)  # y axis is unchanged by a yaw
    np.testing.assert_allclose(loc[:, 1], np.tile([0.0, 0.0, 0.5], (T, 1)), atol=1e-9)
    # chest's world angular velocity = root spin + root-rotated chest bend
    bend_world = R.rotate(rot[:, 0], np.tile([0.0, 0.0, 0.5], (T, 1)))
    np.testing.assert_allclose(w[1:-1, 1], (np.array([0.0, 2.0, 0.0]) + bend_world)[1:-1], atol=2e-3)
    # a point moving on a circle: the chest joint sits on the spin axis, so moves with the root only
    np.testing.assert_allclose(clip.body_linear_velocity()[:, 1], clip.body_linear_velocity()[:, 0], atol=1e-9)


# ---------------------------------------------------------------------------- malformed DeepMimic input
def test_missing_file(tmp_path):
    path = tmp_path / "nope.txt"
    with pytest.raises(CharctlError) as exc:
        load_clip(str(path))
    assert_one_line(exc.value, str(path), "not found")


@pytest.mark.parametrize(
    "content,words",
    [
        ("{not json", ["invalid JSON"]),
        ("", ["invalid JSON"]),
        ("[1, 2, 3]", ["Frames"]),
        ('{"Loop": "wrap"}', ["Frames"]),
        ('{"Loop": "wrap", "Frames": [[0.1, 1, 2], [0.1, 1]]}', ["Frames"]),
        ('{"Loop": "wrap", "Frames": [["a", "b"]]}', ["Frames"]),
    ],
)
def test_invalid_json_and_structure(write_motion, content, words):
    path = write_motion(None, raw=content, name="bad.txt")
    with pytest.raises(CharctlError) as exc:
        load_clip(str(path))
    assert_one_line(exc.value, str(path), *words)


def test_binary_garbage(tmp_path):
    path = tmp_path / "garbage.txt"
    path.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(CharctlError) as exc:
        load_clip(str(path))
    assert_one_line(exc.value, str(path))


def test_wrong_frame_width(write_motion, walk_raw_frames):
    path = write_motion(walk_raw_frames[:, :43])
    with pytest.raises(CharctlError) as exc:
        load_clip(str(path))
    assert_one_line(exc.value, str(path), "44", "43")


def test_nan_frame(write_motion, walk_raw_frames):
    frames = walk_raw_frames.copy()
    frames[7, 12] = float("nan")
    path = write_motion(frames)  # json writes NaN literally
    assert "NaN" in path.read_text()
    with pytest.raises(CharctlError) as exc:
        load_clip(str(path))
    assert_one_line(exc.value, str(path), "frame 7", "NaN")


def test_single_frame(write_motion, walk_raw_frames):
    path = write_motion(walk_raw_frames[:1])
    with pytest.raises(CharctlError) as exc:
        load_clip(str(path))
    assert_one_line(exc.value, str(path), "2 frames")


def test_bad_loop_value(write_motion, walk_raw_frames):
    path = write_motion(walk_raw_frames, loop="forever")
    with pytest.raises(CharctlError) as exc:
        load_clip(str(path))
    assert_one_line(exc.value, str(path), "Loop", "forever")


def test_negative_dt(write_motion, walk_raw_frames):
    frames = walk_raw_frames.copy()
    frames[3, 0] = -0.03
    path = write_motion(frames)
    with pytest.raises(CharctlError) as exc:
        load_clip(str(path))
    assert_one_line(exc.value, str(path), "negative")


def test_all_zero_dt(write_motion, walk_raw_frames):
    frames = walk_raw_frames.copy()
    frames[:, 0] = 0.0
    path = write_motion(frames)
    with pytest.raises(CharctlError) as exc:
        load_clip(str(path))
    assert_one_line(exc.value, str(path))


def test_non_unit_quaternions_are_normalised(write_motion, walk_raw_frames):
    frames = walk_raw_frames.copy()
    quat_cols = [c for _, c, w in LAYOUT if w == 4]
    frames[:, 4:8] *= 3.0
    for c in quat_cols:
        frames[:, c : c + 4] *= np.linspace(0.5, 2.0, frames.shape[0])[:, None]
    clip = load_clip(str(write_motion(frames)))
    ref = load_clip("walk")
    np.testing.assert_allclose(np.linalg.norm(clip.local_rot, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(clip.body_pos, ref.body_pos, atol=1e-9)


def test_final_frame_dt_zero_is_accepted(write_motion, walk_raw_frames):
    frames = walk_raw_frames.copy()
    frames[:, 0] = 1.0 / 30.0
    frames[-1, 0] = 0.0
    clip = load_clip(str(write_motion(frames)))
    assert clip.num_frames == frames.shape[0]
    assert clip.fps == pytest.approx(30.0)
    assert clip.duration == pytest.approx((frames.shape[0] - 1) / 30.0)


def test_non_uniform_dt_is_resampled(write_motion, walk_raw_frames):
    """Frames at irregular times with the root moving at exactly 1 m/s along x: after resampling to a
    uniform grid the root's x must equal the (uniform) frame time."""
    T = 25
    frames = np.tile(walk_raw_frames[0], (T, 1))
    dts = np.where(np.arange(T) % 3 == 0, 1.0 / 15.0, 1.0 / 30.0)  # mixed steps, median 1/30
    dts[-1] = 0.0
    times = np.concatenate([[0.0], np.cumsum(dts[:-1])])
    frames[:, 0] = dts
    frames[:, 1] = times  # x = t
    frames[:, 2] = 0.9
    clip = load_clip(str(write_motion(frames)))
    assert clip.fps == pytest.approx(30.0, rel=0.02)
    assert clip.duration == pytest.approx(times[-1], rel=1e-12)
    assert clip.num_frames == round(times[-1] * 30.0) + 1
    np.testing.assert_allclose(clip.root_pos[:, 0], clip.times, atol=1e-9)
    np.testing.assert_allclose(clip.root_pos[:, 1], 0.9, atol=1e-12)


def test_shipped_roll_clip_is_resampled_onto_a_uniform_grid():
    """humanoid3d_roll has one doubled step (a missing frame): it loads as a uniform clip one frame longer."""
    from charctl.motion.library import motions_dir

    raw = np.array(json.loads((motions_dir() / "humanoid3d_roll.txt").read_text())["Frames"])
    clip = load_clip("roll")
    assert clip.num_frames == raw.shape[0] + 1
    assert clip.duration == pytest.approx(raw[:-1, 0].sum(), rel=1e-9)
    np.testing.assert_allclose(clip.root_pos[-1], raw[-1, 1:4], atol=1e-12)
