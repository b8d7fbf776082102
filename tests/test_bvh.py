"""BVH export and import.

The exported file is re-read by an independent parser (`bvhio`, a separate PyPI project with
its own Euler/hierarchy code) and its joint world positions compared with charctl's FK; the
reader is checked on a small hand-written file whose FK is worked out by hand.
"""

from __future__ import annotations

import numpy as np
import pytest

from charctl.errors import CharctlError
from charctl.motion import rotations as R
from charctl.motion.bvh import read_bvh, read_bvh_as_clip, write_bvh
from charctl.motion.library import load_clip

from conftest import assert_one_line

BVH_CLIPS = ["walk", "kick:mirror", "backflip", "spinkick", "walker/turn_right1"]


def bvhio_world_positions(path, names) -> np.ndarray:
    """World joint positions (T, J, 3) of a BVH file as computed by bvhio, in `names` order."""
    bvhio = pytest.importorskip("bvhio")
    root = bvhio.readAsHierarchy(str(path))
    joints = {j.Name: j for j, _, _ in root.layout()}
    T = len(root.Keyframes)
    out = np.empty((T, len(names), 3))
    for f in range(T):
        root.loadPose(f)
        for b, n in enumerate(names):
            out[f, b] = tuple(joints[n].PositionWorld)
    return out


@pytest.mark.parametrize("spec", BVH_CLIPS)
def test_exported_bvh_read_by_bvhio_matches_fk(tmp_path, spec):
    clip = load_clip(spec)
    path = write_bvh(clip, tmp_path / "clip.bvh")
    pos = bvhio_world_positions(path, clip.skeleton.names)
    assert pos.shape == clip.body_pos.shape
    err = np.linalg.norm(pos - clip.body_pos, axis=-1)
    assert err.mean() < 0.01, f"{spec}: mean joint position error {err.mean():.3g} m"
    assert err.max() < 1e-4, f"{spec}: max joint position error {err.max():.3g} m"


def test_exported_bvh_at_other_fps_read_by_bvhio(tmp_path):
    clip = load_clip("run")
    path = write_bvh(clip, tmp_path / "run60.bvh", fps=60)
    ref = clip.resample(60)
    pos = bvhio_world_positions(path, clip.skeleton.names)
    assert pos.shape[0] == ref.num_frames == round(clip.duration * 60) + 1
    assert np.linalg.norm(pos - ref.body_pos, axis=-1).mean() < 0.01


@pytest.mark.parametrize("spec", ["walk", "cartwheel:mirror", "getup_faceup"])
def test_bvh_round_trip(tmp_path, spec):
    clip = load_clip(spec)
    path = write_bvh(clip, tmp_path / "rt.bvh")
    back = load_clip(str(path))  # the library dispatches .bvh to read_bvh_as_clip
    assert back.num_frames == clip.num_frames
    assert back.fps == pytest.approx(clip.fps, rel=1e-6)
    np.testing.assert_allclose(back.root_pos, clip.root_pos, atol=2e-6)  # 6 decimals in the file
    assert R.angle_between(back.local_rot, clip.local_rot).max() < 1e-4  # degrees with 6 decimals
    np.testing.assert_allclose(back.body_pos, clip.body_pos, atol=1e-4)
    # charctl's own generic reader agrees with the clip's FK
    motion = read_bvh(path)
    pos, _ = motion.forward_kinematics()
    idx = [motion.names.index(n) for n in clip.skeleton.names]
    np.testing.assert_allclose(pos[:, idx], clip.body_pos, atol=1e-4)


def test_bvh_file_layout(tmp_path):
    clip = load_clip("walk")
    path = write_bvh(clip, tmp_path / "sub" / "walk.bvh")
    assert path.exists() and not list(path.parent.glob("*.tmp*"))
    motion = read_bvh(path)
    assert motion.names[0] == "root" and set(motion.names) == set(clip.skeleton.names)
    assert motion.channels[0] == ["Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"]
    assert all(ch == ["Zrotation", "Yrotation", "Xrotation"] for ch in motion.channels[1:])
    assert motion.num_frames == clip.num_frames and motion.frame_time == pytest.approx(clip.dt, abs=1e-8)
    # an end site on each leaf: head, two feet, two hands
    leaves = {motion.names[j] for j in motion.end_sites}
    assert leaves == {"neck", "right_ankle", "left_ankle", "right_wrist", "left_wrist"}


def test_write_bvh_rejects_bad_fps(tmp_path):
    with pytest.raises(CharctlError) as exc:
        write_bvh(load_clip("walk"), tmp_path / "x.bvh", fps=0)
    assert_one_line(exc.value, "fps")


# ---------------------------------------------------------------------------- the generic reader
HAND_BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Xrotation Yrotation Zrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Xrotation Yrotation Zrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
  JOINT Leg
  {
    OFFSET 2 0 0
    CHANNELS 3 Xrotation Yrotation Zrotation
    End Site
    {
      OFFSET 0 -8 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.04
1 2 3 0 0 0   0 0 0   0 0 0
0 100 0 0 90 0   90 0 0   0 0 0
"""


def test_generic_reader_hand_fk(tmp_path):
    path = tmp_path / "hand.bvh"
    path.write_text(HAND_BVH)
    motion = read_bvh(path)
    assert motion.names == ["Hips", "Spine", "Leg"] and list(motion.parents) == [-1, 0, 0]
    assert motion.fps == pytest.approx(25.0) and motion.num_frames == 2
    pos, rot = motion.forward_kinematics()
    # frame 0: pure translation
    np.testing.assert_allclose(pos[0], [[1, 2, 3], [1, 12, 3], [3, 2, 3]], atol=1e-12)
    # frame 1: hips turned +90 deg about y: (2, 0, 0) -> (0, 0, -2); spine offset (0,10,0) unchanged
    np.testing.assert_allclose(pos[1], [[0, 100, 0], [0, 110, 0], [0, 100, -2]], atol=1e-9)
    # spine: Ry(90) then its own Rx(90) -> world rotation Ry(90) Rx(90)
    expect = R.multiply(
        R.from_axis_angle(np.array([0.0, 1, 0]), np.pi / 2), R.from_axis_angle(np.array([1.0, 0, 0]), np.pi / 2)
    )
    assert R.angle_between(rot[1, 1], expect) < 1e-9
    # end sites are kept, keyed by their joint
    np.testing.assert_allclose(motion.end_sites[1], [0, 5, 0])
    np.testing.assert_allclose(motion.end_sites[2], [0, -8, 0])


def test_non_humanoid_bvh_as_clip_is_one_line_error(tmp_path):
    path = tmp_path / "hand.bvh"
    path.write_text(HAND_BVH)
    with pytest.raises(CharctlError) as exc:
        load_clip(str(path))
    assert_one_line(exc.value, str(path), "missing joints")


# ---------------------------------------------------------------------------- malformed BVH
@pytest.fixture
def bvh_text() -> str:
    """A valid BVH (the hand-written one above) to break in different ways; independent of write_bvh."""
    return HAND_BVH


def _expect_bvh_error(path, *words):
    for reader in (read_bvh, read_bvh_as_clip, lambda p: load_clip(str(p))):
        with pytest.raises(CharctlError) as exc:
            reader(path)
        assert_one_line(exc.value, str(path), *words)


def test_bvh_missing_file(tmp_path):
    _expect_bvh_error(tmp_path / "absent.bvh", "not found")


def test_bvh_truncated_motion(tmp_path, bvh_text):
    path = tmp_path / "trunc.bvh"
    lines = bvh_text.splitlines()
    path.write_text("\n".join(lines[:-1]) + "\n" + lines[-1][: len(lines[-1]) // 2] + "\n")
    _expect_bvh_error(path, "malformed BVH")


def test_bvh_missing_hierarchy(tmp_path, bvh_text):
    path = tmp_path / "nohier.bvh"
    assert bvh_text.startswith("HIERARCHY\n")
    path.write_text(bvh_text.replace("HIERARCHY\n", "", 1))
    _expect_bvh_error(path, "HIERARCHY")


def test_bvh_truncated_hierarchy(tmp_path, bvh_text):
    path = tmp_path / "cut.bvh"
    path.write_text(bvh_text[: bvh_text.index("MOTION") // 2])
    _expect_bvh_error(path, "malformed BVH")


@pytest.mark.parametrize("bad", ["Frame Time: 0", "Frame Time: abc", "Frames: x"])
def test_bvh_bad_motion_header(tmp_path, bvh_text, bad):
    import re

    key = bad.split(":")[0]
    text = re.sub(rf"{key}: \S+", bad, bvh_text, count=1)
    path = tmp_path / "hdr.bvh"
    path.write_text(text)
    _expect_bvh_error(path, "malformed BVH")


def test_bvh_nan_value(tmp_path, bvh_text):
    lines = bvh_text.splitlines()
    vals = lines[-1].split()
    vals[4] = "nan"
    lines[-1] = " ".join(vals)
    path = tmp_path / "nan.bvh"
    path.write_text("\n".join(lines) + "\n")
    _expect_bvh_error(path, "malformed BVH")
