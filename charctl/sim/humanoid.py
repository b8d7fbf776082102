"""MJCF of the DeepMimic humanoid3d for MuJoCo, and the clip <-> qpos/qvel mapping.

World frame: y-up (gravity -y), the same as the clips, so no axis conversion happens anywhere.
Bodies, joint offsets and collision shapes come from pybullet's humanoid.urdf (scaled 0.25);
masses from the foundation issue (45 kg total); inertia from the shapes (uniform density).

Actuation (decision, see README "Humanoid model"): each 3-DoF ball joint is a chain of three
hinges (intrinsic Euler order chosen per joint to keep the middle angle far from +-90 deg over
every shipped clip and its mirror), each driven by a MuJoCo position actuator with the PD gains
of DeepMimic (kp, kd = kv) and its torque limit; knees and elbows are single hinges about z.
The `implicitfast` integrator treats the kd term implicitly, which is what keeps PD stable at
low physics rates (the role the paper's stable PD, eq 3.1, plays). Self-collision is off
(as in DeepMimic); bodies collide with the ground plane only.

Solver warm start is off: MuJoCo's Newton solver converges to its tolerance (1e-8) either way, and
from a cold start it needs fewer iterations on this model (2.1 against 2.5 per step), so batched
clip tracking runs 9 % faster with the same tracking error (docs/cgail.md, "Throughput").
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from charctl.motion import rotations as R
from charctl.motion.skeleton import HINGE_JOINTS, Skeleton, load_skeleton
from charctl.sim import JOINT_ARMATURE, PHYSICS_HZ
from charctl.sim.scene import scene_assets, scene_ground

# Intrinsic Euler order of each ball joint's hinge chain (R = R_a1 R_a2 R_a3). Chosen by the
# largest |middle angle| over all 20 clips and their mirrors (scripts/choose_euler_orders.py):
# chest ZYX 25 deg, neck YXZ 38, hips ZYX 55, ankles YXZ 51, shoulders XYZ 80.
EULER_ORDER: dict[str, str] = {
    "chest": "ZYX",
    "neck": "YXZ",
    "right_hip": "ZYX",
    "left_hip": "ZYX",
    "right_ankle": "YXZ",
    "left_ankle": "YXZ",
    "right_shoulder": "XYZ",
    "left_shoulder": "XYZ",
}
# PD gains (kp N m/rad, kd N m s/rad) and torque limits (N m) per joint, from DeepMimic.
PD_GAINS: dict[str, tuple[float, float, float]] = {
    "chest": (1000.0, 100.0, 200.0),
    "neck": (100.0, 10.0, 50.0),
    "hip": (500.0, 50.0, 200.0),
    "knee": (500.0, 50.0, 150.0),
    "ankle": (400.0, 40.0, 90.0),
    "shoulder": (400.0, 40.0, 100.0),
    "elbow": (300.0, 30.0, 60.0),
}
HINGE_LIMITS = {"knee": (-3.14, 0.0), "elbow": (0.0, 3.14)}
_AXES = {"X": np.eye(3)[0], "Y": np.eye(3)[1], "Z": np.eye(3)[2]}
# The frame R0 (xyzw) each shoulder's hinge chain works in, per `shoulder_frame` variant: the joint's rotation
# is R0 E(angles) R0^-1, so its hinge axes are R0's columns and the rest pose is unchanged.
# - "parent" (every policy trained up to 2026-12-04): the parent's axes. There the dance_a clip (the `spindance`
#   skill) swings the right arm 10 deg from the XYZ chain's singular pose (middle angle -80 deg): its first and
#   third hinges turn at 20-25 rad/s and wind a full turn per loop.
# - "rotated": per shoulder, the best of 4,001 frames (identity and 4,000 random, seed 1) at keeping the middle
#   angle away from +-90 deg over the ten paper skills' clips and mirrors: at most 53 (right) and 51 deg (left);
#   dance_a's fastest hinge 11 rad/s. scripts/choose_shoulder_frames.py prints them; docs/cgail.md "Spindance".
SHOULDER_FRAMES: dict[str, dict[str, tuple[float, float, float, float]]] = {
    "parent": {},
    "rotated": {
        "right_shoulder": (0.2506, -0.5063, 0.1964, -0.8014),
        "left_shoulder": (-0.3366, -0.7564, 0.2599, 0.4970),
    },
}


def chain_frames(shoulder_frame: str) -> dict[str, Rotation]:
    """body -> R0 of the hinge chains not in their parent's axes, for a `shoulder_frame` variant."""
    if shoulder_frame not in SHOULDER_FRAMES:
        raise ValueError(f"unknown shoulder_frame {shoulder_frame!r} (one of {', '.join(SHOULDER_FRAMES)})")
    return {b: Rotation.from_quat(q) for b, q in SHOULDER_FRAMES[shoulder_frame].items()}


def _kind(joint: str) -> str:
    return joint.split("_")[-1]


@dataclass(frozen=True)
class HumanoidLayout:
    """Where each body's degrees of freedom live in qpos/qvel/ctrl."""

    joint_bodies: tuple[str, ...]  # actuated bodies in MJCF (depth-first) order, no root/wrists
    qpos_slices: dict[str, slice]
    qvel_slices: dict[str, slice]
    nq: int
    nv: int
    nu: int


@functools.lru_cache(maxsize=1)
def layout() -> HumanoidLayout:
    skel = load_skeleton()
    names = [skel.names[b] for b in skel.dfs_order]  # the MJCF nests bodies depth-first
    bodies = tuple(n for n in names[1:] if not n.endswith("wrist"))
    qp, qv, q, v = {}, {}, 7, 6
    for b in bodies:
        width = 1 if b in HINGE_JOINTS else 3
        qp[b] = slice(q, q + width)
        qv[b] = slice(v, v + width)
        q += width
        v += width
    return HumanoidLayout(bodies, qp, qv, q, v, q - 7)


def build_mjcf(
    physics_hz: float = PHYSICS_HZ,
    friction: float = 1.0,
    armature: float = JOINT_ARMATURE,
    skeleton: Skeleton | None = None,
    floor_size: float = 50.0,
    shoulder_frame: str = "parent",
) -> str:
    """MJCF text of the humanoid on a ground plane. Physics timestep = 1 / physics_hz; `shoulder_frame`: the
    shoulders' hinge-chain frames (SHOULDER_FRAMES)."""
    skel = skeleton or load_skeleton()
    children: dict[int, list[int]] = {b: [] for b in range(skel.num_bodies)}
    for b in range(1, skel.num_bodies):
        children[int(skel.parents[b])].append(b)
    lines: list[str] = []
    actuators: list[str] = []
    _emit_body(skel, children, 0, 0, lines, actuators, chain_frames(shoulder_frame))
    return _mjcf_document("\n".join(lines), "\n    ".join(actuators), physics_hz, friction, armature, floor_size)


def _geom_xml(skel: Skeleton, b: int) -> str:
    """The collision/visual `<geom>` of body `b` (skeleton frame, metres; a capsule's axis along y)."""
    g = skel.geoms[b]
    m = skel.masses[b]
    p = np.array(g.pos)
    common = f'name="{skel.names[b]}" mass="{m}" rgba="{_color(skel.names[b])}"'
    if g.kind == "sphere":
        return f'<geom type="sphere" size="{g.size[0]:.5f}" pos="{p[0]:.5f} {p[1]:.5f} {p[2]:.5f}" {common}/>'
    if g.kind == "capsule":
        r, half = g.size
        a, c = p + [0, half, 0], p - [0, half, 0]
        return (
            f'<geom type="capsule" size="{r:.5f}" '
            f'fromto="{a[0]:.5f} {a[1]:.5f} {a[2]:.5f} {c[0]:.5f} {c[1]:.5f} {c[2]:.5f}" {common}/>'
        )
    h = g.size
    return f'<geom type="box" size="{h[0]:.5f} {h[1]:.5f} {h[2]:.5f}" pos="{p[0]:.5f} {p[1]:.5f} {p[2]:.5f}" {common}/>'


def _root_joint_xml(pad: str) -> list[str]:
    """The root's free joint and the two COM-tracking cameras (side: looking along -z; front: along -x)."""
    return [
        f'{pad}  <freejoint name="root"/>',
        f'{pad}  <camera name="side" mode="trackcom" pos="0 0.35 2.8" xyaxes="1 0 0 0 0.99 -0.14"/>',
        f'{pad}  <camera name="front" mode="trackcom" pos="2.8 0.35 0" xyaxes="0 0 -1 -0.14 0.99 0"/>',
    ]


def _actuated_joint_xml(
    name: str, pad: str, lines: list[str], actuators: list[str], frame: Rotation | None = None
) -> None:
    """Append body `name`'s hinge(s) to `lines` and their PD position actuators to `actuators`:
    one limited hinge about z (radians) for knees/elbows, else a chain of three in EULER_ORDER, about the
    axes of `frame` (R0; None: the parent's axes)."""
    kp, kd, lim = PD_GAINS[_kind(name)]
    if name in HINGE_JOINTS:
        lo, hi = HINGE_LIMITS[_kind(name)]
        lines.append(f'{pad}  <joint name="{name}" type="hinge" axis="0 0 1" range="{lo} {hi}" limited="true"/>')
        actuators.append(_actuator(name, kp, kd, lim))
    else:
        for axis in EULER_ORDER[name]:
            jn = f"{name}_{axis.lower()}"
            v = _AXES[axis] if frame is None else frame.apply(_AXES[axis])
            lines.append(f'{pad}  <joint name="{jn}" type="hinge" axis="{v[0]:.12g} {v[1]:.12g} {v[2]:.12g}"/>')
            actuators.append(_actuator(jn, kp, kd, lim))


def _emit_body(
    skel: Skeleton,
    children: dict[int, list[int]],
    b: int,
    depth: int,
    lines: list[str],
    actuators: list[str],
    frames: dict[str, Rotation],
) -> None:
    """Append body `b`'s `<body>` element and, depth-first, its descendants' to `lines`; the root sits
    0.9 m above the ground, every other body at its skeleton offset (metres) from its parent. `frames`:
    chain_frames' R0 per body."""
    name = skel.names[b]
    pad = "  " * (depth + 2)
    off = skel.offsets[b] if b > 0 else np.array([0.0, 0.9, 0.0])
    lines.append(f'{pad}<body name="{name}" pos="{off[0]:.6f} {off[1]:.6f} {off[2]:.6f}">')
    if b == 0:
        lines.extend(_root_joint_xml(pad))
    elif not name.endswith("wrist"):
        _actuated_joint_xml(name, pad, lines, actuators, frames.get(name))
    lines.append(f"{pad}  {_geom_xml(skel, b)}")
    for c in children[b]:
        _emit_body(skel, children, c, depth + 1, lines, actuators, frames)
    lines.append(f"{pad}</body>")


def _mjcf_document(body: str, acts: str, physics_hz: float, friction: float, armature: float, floor_size: float) -> str:
    """The whole `<mujoco>` document around the body tree and actuator elements (y-up, gravity -y)."""
    return f"""<mujoco model="charctl_humanoid3d">
  <compiler angle="radian" inertiafromgeom="true"/>
  <option timestep="{1.0 / physics_hz:.8f}" gravity="0 -9.81 0" integrator="implicitfast">
    <flag warmstart="disable"/>
  </option>
  <size memory="4M"/>
  <visual><global offwidth="1280" offheight="720"/><quality shadowsize="2048"/></visual>
  <default>
    <joint armature="{armature}" damping="0"/>
    <geom contype="1" conaffinity="0" friction="{friction} 0.005 0.0001" condim="3"/>
  </default>
  <asset>
{scene_assets(floor_size)}
  </asset>
  <worldbody>
{scene_ground(floor_size, collides=True)}
{body}
  </worldbody>
  <actuator>
    {acts}
  </actuator>
</mujoco>
"""


def _actuator(joint: str, kp: float, kd: float, limit: float) -> str:
    return (
        f'<position name="{joint}" joint="{joint}" kp="{kp}" kv="{kd}" '
        f'forcelimited="true" forcerange="{-limit} {limit}"/>'
    )


def _color(name: str) -> str:
    if name.startswith("right_"):
        return "0.85 0.45 0.35 1"
    if name.startswith("left_"):
        return "0.35 0.55 0.85 1"
    return "0.8 0.8 0.78 1"


@functools.lru_cache(maxsize=8)
def load_model(
    physics_hz: float = PHYSICS_HZ,
    friction: float = 1.0,
    armature: float = JOINT_ARMATURE,
    shoulder_frame: str = "parent",
):
    """Compiled MjModel (cached per settings). Heavy import inside."""
    import mujoco

    from charctl.mujoco_log import apply_mujoco_log

    apply_mujoco_log()  # warnings into the run's mujoco.log, never ./MUJOCO_LOG.TXT
    return mujoco.MjModel.from_xml_string(build_mjcf(physics_hz, friction, armature, shoulder_frame=shoulder_frame))


# ---------------------------------------------------------------------------- clip <-> qpos
def local_rot_to_qpos(root_pos: np.ndarray, local_rot: np.ndarray, shoulder_frame: str = "parent") -> np.ndarray:
    """(..., 3) root positions and (..., 15, 4) local rotations -> (..., nq) qpos (hinge angles of the model
    built with `shoulder_frame`)."""
    lay = layout()
    skel = load_skeleton()
    shape = local_rot.shape[:-2]
    qpos = np.zeros(shape + (lay.nq,))
    qpos[..., :3] = root_pos
    qpos[..., 3:7] = R.xyzw_to_wxyz(local_rot[..., 0, :])
    chain_rot = _conjugated(local_rot, chain_frames(shoulder_frame), to_chain=True)  # R0^-1 R R0
    for order, bodies in _bodies_by_order().items():
        idx = [skel.index(b) for b in bodies]
        q = chain_rot[..., idx, :].reshape(-1, 4)
        angles = Rotation.from_quat(q).as_euler(order).reshape(shape + (len(bodies), 3))
        for k, b in enumerate(bodies):
            qpos[..., lay.qpos_slices[b]] = angles[..., k, :]
    for b in HINGE_JOINTS:
        q = local_rot[..., skel.index(b), :]
        qpos[..., lay.qpos_slices[b].start] = R.twist_angle(q, 2)  # the hinge angle about +z
    return qpos


def qpos_to_local_rot(qpos: np.ndarray, shoulder_frame: str = "parent") -> tuple[np.ndarray, np.ndarray]:
    """(..., nq) qpos of the model built with `shoulder_frame` -> root positions (..., 3) and local rotations
    (..., 15, 4) xyzw."""
    lay = layout()
    skel = load_skeleton()
    shape = qpos.shape[:-1]
    rot = np.tile(R.IDENTITY, shape + (skel.num_bodies, 1))
    rot[..., 0, :] = R.normalize(R.wxyz_to_xyzw(qpos[..., 3:7]))
    for order, bodies in _bodies_by_order().items():
        angles = np.stack([qpos[..., lay.qpos_slices[b]] for b in bodies], axis=-2)
        q = Rotation.from_euler(order, angles.reshape(-1, 3)).as_quat().reshape(shape + (len(bodies), 4))
        for k, b in enumerate(bodies):
            rot[..., skel.index(b), :] = q[..., k, :]
    for b in HINGE_JOINTS:
        rot[..., skel.index(b), :] = R.from_axis_angle(np.array([0.0, 0.0, 1.0]), qpos[..., lay.qpos_slices[b].start])
    return qpos[..., :3].copy(), _conjugated(rot, chain_frames(shoulder_frame), to_chain=False)  # R0 E R0^-1


def _conjugated(local_rot: np.ndarray, frames: dict[str, Rotation], to_chain: bool) -> np.ndarray:
    """(..., 15, 4) xyzw local rotations with each `frames` body's R turned into its chain's frame, R0^-1 R R0
    (`to_chain`), or back, R0 R R0^-1; the input itself where no body has a frame."""
    if not frames:
        return local_rot
    skel, out = load_skeleton(), local_rot.copy()
    for b, r0 in frames.items():
        r = Rotation.from_quat(local_rot[..., skel.index(b), :].reshape(-1, 4))
        turned = r0.inv() * r * r0 if to_chain else r0 * r * r0.inv()
        out[..., skel.index(b), :] = turned.as_quat().reshape(local_rot.shape[:-2] + (4,))
    return out


def clip_to_qpos_qvel(clip, shoulder_frame: str = "parent") -> tuple[np.ndarray, np.ndarray]:
    """Per-frame qpos (T, nq) and qvel (T, nv) of a clip (finite-difference velocities), for the model built
    with `shoulder_frame`.

    qvel follows MuJoCo's conventions: free-joint linear velocity in the world frame, angular
    velocity in the root body frame; hinge rates from unwrapped angles.
    """
    qpos = local_rot_to_qpos(clip.root_pos, clip.local_rot, shoulder_frame)
    lay = layout()
    qvel = np.zeros((clip.num_frames, lay.nv))
    qvel[:, :3] = clip.root_linear_velocity()
    qvel[:, 3:6] = clip.local_angular_velocity()[:, 0]
    angles = np.unwrap(qpos[:, 7:], axis=0)
    qvel[:, 6:] = np.gradient(angles, clip.dt, axis=0) if clip.num_frames > 1 else 0.0
    return qpos, qvel


@functools.lru_cache(maxsize=1)
def _bodies_by_order() -> dict[str, tuple[str, ...]]:
    out: dict[str, list[str]] = {}
    for b, order in EULER_ORDER.items():
        out.setdefault(order, []).append(b)
    return {k: tuple(v) for k, v in out.items()}
