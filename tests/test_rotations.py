"""charctl.motion.rotations / rotations_torch helpers against hand-derived values.

Quaternions are x-y-z-w; angles in radians; world y-up. `rotations.twist_angle` (hinge angles of the
DeepMimic / MuJoCo knees and elbows, com-cnn's heading twist about +y) and `rotations_torch.cross`
(the cgail web graph, exported to ONNX); the other helpers are in test_motion.py / test_gpu_path.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from charctl.motion import rotations as R
from charctl.motion import rotations_torch as RT

S45 = math.sqrt(0.5)  # sin 45 deg = cos 45 deg
E = np.eye(3)


# ---------------------------------------------------------------------------- twist_angle
@pytest.mark.parametrize(
    ("q", "axis", "angle"),
    [
        ([0.0, 0.0, 0.0, 1.0], 2, 0.0),  # identity
        ([0.0, 0.0, S45, S45], 2, math.pi / 2),  # 90 deg about +z: (0, 0, sin 45, cos 45)
        ([0.0, 0.0, -S45, S45], 2, -math.pi / 2),
        ([0.0, 0.0, 1.0, 0.0], 2, math.pi),  # 180 deg about +z
        ([0.0, 0.0, 0.5, math.sqrt(3) / 2], 2, math.pi / 3),  # 60 deg: (sin 30, cos 30)
        ([S45, 0.0, 0.0, S45], 0, math.pi / 2),  # 90 deg about +x
        ([0.0, 0.5, 0.0, -math.sqrt(3) / 2], 1, 2 * math.pi - math.pi / 3),  # -q of -60 deg about +y: not wrapped
    ],
)
def test_twist_angle_of_hand_built_hinge_quaternions(q, axis, angle):
    assert R.twist_angle(np.array(q), axis) == pytest.approx(angle, abs=1e-12)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_twist_angle_gives_back_the_angle_of_a_rotation_about_the_axis(axis):
    a = np.linspace(-2 * np.pi, 2 * np.pi, 41)[1:]  # (-2 pi, 2 pi]: half angles in (-pi, pi]
    q = R.from_axis_angle(E[axis], a)
    np.testing.assert_allclose(R.twist_angle(q, axis), a, atol=1e-12)
    # the other two components are zero: no twist about the other axes (0, or +-2 pi where w < 0: not wrapped)
    for other in {0, 1, 2} - {axis}:
        twist = R.twist_angle(q, other)  # 2 atan2(+-0, w): 0 for |a| < pi, +-2 pi (the same rotation) beyond
        np.testing.assert_allclose(np.abs(twist), np.where(np.abs(a) > np.pi, 2 * np.pi, 0.0), atol=1e-12)


def test_twist_angle_ignores_a_swing_about_a_perpendicular_axis():
    """q = Ry(t) * swing or swing * Ry(t), swing about a horizontal axis (|angle| < pi): the twist about
    +y is t, whatever the swing (com-cnn's heading, which stays defined when the pelvis pitches 90 deg)."""
    t = np.array([-2.5, -0.4, 0.0, 0.7, 3.0])
    twist = R.heading_quat(t)
    for axis in (E[0], E[2], np.array([S45, 0.0, S45])):
        for s in (0.3, math.pi / 2, -1.2, 3.0):
            swing = R.from_axis_angle(axis, np.full(t.shape, s))
            np.testing.assert_allclose(R.twist_angle(R.multiply(twist, swing), 1), t, atol=1e-12)
            np.testing.assert_allclose(R.twist_angle(R.multiply(swing, twist), 1), t, atol=1e-12)


def test_twist_angle_is_exactly_the_formula_the_call_sites_had():
    """Bit for bit 2 atan2(q[axis], w), signed zeros included (-0.0 with w < 0 gives -2 pi, +0.0 gives 2 pi),
    over (frames, joints) batches as the DeepMimic writer, humanoid qpos and import report pass them."""
    rng = np.random.default_rng(0)
    q = R.normalize(rng.standard_normal((50, 4, 4)))
    q[0, :, :3] = [[0.0, 0.0, -0.0], [0.0, -0.0, 0.0], [-0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
    q[0, :, 3] = -1.0
    for axis in range(3):
        got, want = R.twist_angle(q, axis), 2.0 * np.arctan2(q[..., axis], q[..., 3])
        assert got.shape == (50, 4)
        assert np.array_equal(got, want) and np.array_equal(np.signbit(got), np.signbit(want))
    assert R.twist_angle(q[0, 0], 2) == -2 * math.pi and R.twist_angle(q[0, 3], 2) == 2 * math.pi


# ---------------------------------------------------------------------------- rotations_torch.cross
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_torch_cross_of_known_vectors(dtype):
    e = torch.eye(3, dtype=dtype)
    got = RT.cross(e, e[[1, 2, 0]])  # x cross y = z, y cross z = x, z cross x = y
    assert got.dtype == dtype
    assert got.tolist() == [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    assert RT.cross(e[1], e[0]).tolist() == [0.0, 0.0, -1.0]
    # (1, 2, 3) x (4, 5, 6) = (2*6 - 3*5, 3*4 - 1*6, 1*5 - 2*4)
    a, b = torch.tensor([1.0, 2.0, 3.0], dtype=dtype), torch.tensor([4.0, 5.0, 6.0], dtype=dtype)
    assert RT.cross(a, b).tolist() == [-3.0, 6.0, -3.0]
    assert RT.cross(a, a).tolist() == [0.0, 0.0, 0.0]


def test_torch_cross_equals_numpy_and_torch_with_broadcasting():
    rng = np.random.default_rng(1)
    a, b = rng.standard_normal((5, 4, 3)), rng.standard_normal((4, 3))
    got = RT.cross(torch.from_numpy(a), torch.from_numpy(b))
    assert got.shape == (5, 4, 3)
    np.testing.assert_allclose(got.numpy(), R.cross(a, b), atol=1e-12)
    ta, tb = torch.broadcast_tensors(torch.from_numpy(a), torch.from_numpy(b))
    np.testing.assert_allclose(got.numpy(), torch.cross(ta, tb, dim=-1).numpy(), atol=1e-12)


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # the TorchScript exporter, as web_graph uses
def test_torch_cross_exports_to_onnx_and_runs_in_onnxruntime(tmp_path):
    """As the web graph uses it: float64, a dynamic batch axis, opset 17, the TorchScript exporter."""
    pytest.importorskip("onnx")
    ort = pytest.importorskip("onnxruntime")

    class Cross(torch.nn.Module):
        def forward(self, a, b):
            return RT.cross(a, b)

    a = torch.tensor([[[1.0, 2.0, 3.0], [1.0, 0.0, 0.0]]], dtype=torch.float64)
    b = torch.tensor([[[4.0, 5.0, 6.0], [0.0, 1.0, 0.0]]], dtype=torch.float64)
    path = tmp_path / "cross.onnx"
    torch.onnx.export(
        Cross(),
        (a, b),
        str(path),
        input_names=["a", "b"],
        output_names=["c"],
        dynamic_axes={n: {0: "batch"} for n in ("a", "b", "c")},
        opset_version=17,
        dynamo=False,
    )
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    (c,) = sess.run(None, {"a": a.numpy(), "b": b.numpy()})
    assert c.tolist() == [[[-3.0, 6.0, -3.0], [0.0, 0.0, 1.0]]]
    rng = np.random.default_rng(2)
    a3, b3 = rng.standard_normal((3, 2, 3)), rng.standard_normal((3, 2, 3))  # another batch size
    (c3,) = sess.run(None, {"a": a3, "b": b3})
    np.testing.assert_allclose(c3, R.cross(a3, b3), atol=1e-12)
