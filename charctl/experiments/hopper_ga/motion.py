"""The running motion of one genome over several cycles, and its BVH / MJCF / video export.

A run alternates the stance leg (right first) and chains identical cycles (the limp test
speeds up the cycles of the limping left leg). Joint rotations follow character.py:
R = Rz(phi_z) @ Rx(phi_x) in the parent's frame; BVH channels are Zrotation Yrotation
Xrotation (Y = 0), degrees, metres, y up, as charctl/motion/bvh.py writes them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.experiments.hopper_ga.body import dof_to_joint_angles, repeat_cycles
from charctl.experiments.hopper_ga.hopper import leg_cycle, leg_lengths
from charctl.experiments.hopper_ga.model import Rollout, finish_rollout
from charctl.experiments.hopper_ga.settings import Settings, decode, describe_invalid
from charctl.motion.bvh import write_bvh_file

# Capsule radii (m) of the rendered bodies (cosmetic; masses live in the config).
_RADIUS = {"pelvis": 0.07, "chest": 0.11, "neck": 0.1, "shoulder": 0.045, "elbow": 0.04, "hip": 0.065, "knee": 0.05}


@dataclass
class Motion:
    """A multi-cycle run of one genome (N = 1 rollout) and its per-frame joint data."""

    rollout: Rollout
    t: np.ndarray  # (K,) s
    root: np.ndarray  # (K, 3) pelvis position, world
    upper: np.ndarray  # (K, J, 2) upper joints (phi_z, phi_x), rad
    legs: np.ndarray  # (K, 4) right hip, right knee, left hip, left knee (rad about +z)
    com: np.ndarray  # (K, 3) whole-body COM
    target: np.ndarray  # (K, 2) eq 7 target COM (x, z)
    support: np.ndarray  # (K,) 0 right, 1 left, -1 flight
    cycle_xdot: list[float]


def run_motion(genome: np.ndarray, s: Settings, cycles: int, limp_factor: float | None = None) -> Motion:
    """Chain `cycles` cycles of `genome`; with `limp_factor`, cycles on the left leg run at
    speed * limp_factor (shorter stance on the limping leg, paper Fig 3.13)."""
    p = decode(np.asarray(genome, dtype=float)[None], s)
    normal = leg_cycle(p, s)
    limp = leg_cycle(p, s, xdot=s.speed * limp_factor) if limp_factor else normal
    for c, what in ((normal, f"{s.speed:g} m/s"), (limp, f"{s.speed * (limp_factor or 1):g} m/s (limp)")):
        if c.code[0]:
            raise CharctlError(
                f"the genome's cycle at {what} is physically impossible: {describe_invalid(int(c.code[0]))}"
            )
    seq = [normal if i % 2 == 0 else limp for i in range(cycles)]
    tl = repeat_cycles(seq, p, s)
    r = finish_rollout(p, tl, np.zeros(1, dtype=np.int64), s)
    root = np.concatenate([tl.hip[0], np.zeros((tl.hip.shape[1], 1))], -1)
    return Motion(
        rollout=r,
        t=tl.t[0],
        root=root,
        upper=dof_to_joint_angles(r.balance.angles[0], s.body),
        legs=r.theta[0, :, :4],
        com=r.balance.com[0],
        target=tl.target[0],
        support=tl.support[0],
        cycle_xdot=[float(c.xdot[0]) for c in seq],
    )


def cycles_for(seconds: float, cycle_time: float) -> int:
    """Whole cycles covering `seconds` (at least 2, so both legs take a stance)."""
    return max(2, int(np.ceil(seconds / max(cycle_time, 1e-6))))


def resample(m: Motion, fps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Uniform frames (linear interpolation in time): t (T,), root (T,3), upper (T,J,2), legs (T,4)."""
    t = np.arange(0.0, m.t[-1] + 1e-9, 1.0 / fps)

    def lerp(v: np.ndarray) -> np.ndarray:
        cols = [np.interp(t, m.t, col) for col in v.reshape(len(m.t), -1).T]
        return np.stack(cols, -1).reshape((len(t),) + v.shape[1:])

    return t, lerp(m.root), lerp(m.upper), lerp(m.legs)


# ---------------------------------------------------------------------------- skeleton description
def skeleton(s: Settings, l: float) -> list[dict]:
    """Joints in depth-first order: name, parent, offset (parent frame, m), end site, axes.
    Legs hang from the pelvis at +-hip_half_width with thigh a and shank b (a + b = l)."""
    body = s.body
    a, b = (float(v[0]) for v in leg_lengths(np.array([float(l)]), s))
    w = body.hip_half_width
    joints = [{"name": "root", "parent": None, "offset": np.zeros(3), "end": None, "kind": "pelvis"}]
    children = {n: [] for n in body.names}
    for j in range(len(body.names)):
        if body.parent[j] >= 0:
            children[body.names[body.parent[j]]].append(j)

    def add_upper(j: int, parent: str) -> None:
        name = body.names[j]
        leaf = not children[name]
        joints.append(
            {
                "name": name,
                "parent": parent,
                "offset": body.offset[j].copy(),
                "end": body.direction[j] * body.length[j] if leaf else None,
                "kind": "upper",
                "index": j,
                "segment": body.direction[j] * body.length[j],
            }
        )
        for c in children[name]:
            add_upper(c, name)

    for j in np.flatnonzero(body.parent < 0):
        add_upper(int(j), "root")
    for side, z in (("right", w), ("left", -w)):
        joints.append(
            {
                "name": f"{side}_hip",
                "parent": "root",
                "offset": np.array([0.0, 0.0, z]),
                "end": None,
                "kind": "hip",
                "segment": np.array([0.0, -a, 0.0]),
            }
        )
        joints.append(
            {
                "name": f"{side}_knee",
                "parent": f"{side}_hip",
                "offset": np.array([0.0, -a, 0.0]),
                "end": np.array([0.0, -b, 0.0]),
                "kind": "knee",
                "segment": np.array([0.0, -b, 0.0]),
            }
        )
    return joints


def joint_euler(joints: list[dict], upper: np.ndarray, legs: np.ndarray) -> np.ndarray:
    """(T, J, 2) (phi_z, phi_x) per skeleton joint (root: zeros) in `joints` order."""
    leg_col = {"right_hip": 0, "right_knee": 1, "left_hip": 2, "left_knee": 3}
    T = upper.shape[0]
    out = np.zeros((T, len(joints), 2))
    for i, j in enumerate(joints):  # export only, a dozen joints
        if j["kind"] == "upper":
            out[:, i] = upper[:, j["index"]]
        elif j["name"] in leg_col:
            out[:, i, 0] = legs[:, leg_col[j["name"]]]
    return out


# ---------------------------------------------------------------------------- BVH
def write_bvh(
    path: str | Path, s: Settings, l: float, fps: float, root: np.ndarray, upper: np.ndarray, legs: np.ndarray
) -> Path:
    """Write the 11-joint character as BVH (same conventions as charctl.motion.bvh.write_bvh)."""
    joints = skeleton(s, l)
    kids = {j["name"]: [k for k in joints if k["parent"] == j["name"]] for j in joints}
    lines = ["HIERARCHY"]

    def emit(j: dict, depth: int) -> None:
        pad = "\t" * depth
        lines.append(f"{pad}{'ROOT' if j['parent'] is None else 'JOINT'} {j['name']}")
        lines.append(pad + "{")
        o = j["offset"]
        lines.append(f"{pad}\tOFFSET {o[0]:.6f} {o[1]:.6f} {o[2]:.6f}")
        if j["parent"] is None:
            lines.append(f"{pad}\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation")
        else:
            lines.append(f"{pad}\tCHANNELS 3 Zrotation Yrotation Xrotation")
        for k in kids[j["name"]]:
            emit(k, depth + 1)
        if j["end"] is not None:
            e = j["end"]
            lines.extend(
                [f"{pad}\tEnd Site", pad + "\t{", f"{pad}\t\tOFFSET {e[0]:.6f} {e[1]:.6f} {e[2]:.6f}", pad + "\t}"]
            )
        lines.append(pad + "}")

    emit(joints[0], 0)
    ang = np.degrees(joint_euler(joints, upper, legs))  # (T, J, 2)
    T = root.shape[0]
    zyx = np.stack([ang[..., 0], np.zeros_like(ang[..., 0]), ang[..., 1]], -1).reshape(T, -1)
    data = np.concatenate([root, zyx], 1)
    return write_bvh_file(path, lines, data, 1.0 / fps)


# ---------------------------------------------------------------------------- MJCF + video
def mjcf(s: Settings, l: float) -> tuple[str, list[tuple[str, int, int]]]:
    """An MJCF string of the character's capsule bodies (y up, floor = the xz plane) and the
    hinge list (joint name, skeleton index, 0 = z / 1 = x) in qpos order after the free joint."""
    joints = skeleton(s, l)
    kids = {j["name"]: [k for k in joints if k["parent"] == j["name"]] for j in joints}
    hinges: list[tuple[str, int, int]] = []
    index = {j["name"]: i for i, j in enumerate(joints)}
    root_kids = []
    for k in kids["root"]:
        root_kids += _body_xml(k, 3, kids, index, hinges)
    return _mjcf_document(s.body.hip_half_width, root_kids), hinges


def _body_xml(
    j: dict, depth: int, kids: dict[str, list[dict]], index: dict[str, int], hinges: list[tuple[str, int, int]]
) -> list[str]:
    """Joint `j`'s `<body>` element with its descendants' (offsets in m); appends its hinges (z, then x
    for an upper-body joint) to `hinges` in the order MuJoCo lays them out in qpos."""
    pad = "  " * depth
    o = j["offset"]
    out = [f'{pad}<body name="{j["name"]}" pos="{o[0]:.4f} {o[1]:.4f} {o[2]:.4f}">']
    axes = ("z", "x") if j["kind"] == "upper" else ("z",)
    for ax in axes:
        name = f"{j['name']}_{ax}"
        hinges.append((name, index[j["name"]], 0 if ax == "z" else 1))
        vec = "0 0 1" if ax == "z" else "1 0 0"
        out.append(f'{pad}  <joint name="{name}" type="hinge" axis="{vec}" limited="false" armature="0.01"/>')
    out.append(_segment_geom_xml(j, pad))
    for k in kids[j["name"]]:
        out += _body_xml(k, depth + 1, kids, index, hinges)
    out.append(f"{pad}</body>")
    return out


def _segment_geom_xml(j: dict, pad: str) -> str:
    """The geom of joint `j`'s segment (m, joint frame): a head sphere for the neck, else a capsule
    along the segment (left side orange, right side blue)."""
    seg = j["segment"]
    key = j["name"].split("_")[-1]
    r = _RADIUS.get(key, 0.045)
    rgba = "0.85 0.55 0.4 1" if j["name"].startswith("left") else "0.4 0.6 0.85 1"
    if j["name"] == "neck":
        return (
            f'{pad}  <geom type="sphere" size="{r}" '
            f'pos="{seg[0] * 0.6:.4f} {seg[1] * 0.6:.4f} {seg[2] * 0.6:.4f}" rgba="0.9 0.8 0.7 1"/>'
        )
    return (
        f'{pad}  <geom type="capsule" size="{r}" fromto="0 0 0 {seg[0]:.4f} {seg[1]:.4f} {seg[2]:.4f}" rgba="{rgba}"/>'
    )


def _mjcf_document(w: float, root_kids: list[str]) -> str:
    """The `<mujoco>` document: floor, light, the pelvis (half width `w`, m) on a free joint with a side
    camera, and the bodies hanging from it."""
    return "\n".join(
        [
            '<mujoco model="hopper-ga">',
            '  <visual><headlight ambient="0.45 0.45 0.45" '
            'diffuse="0.6 0.6 0.6"/><global offwidth="1280" offheight="720"/></visual>',
            '  <asset><texture name="grid" type="2d" builtin="checker" '
            'rgb1="0.25 0.3 0.35" rgb2="0.35 0.4 0.45" width="256" height="256"/>',
            '    <material name="grid" texture="grid" texrepeat="40 40"/></asset>',
            "  <worldbody>",
            '    <geom type="plane" size="100 100 0.1" euler="-90 0 0" pos="40 0 0" material="grid"/>',
            '    <light pos="0 6 4" dir="0 -1 -0.6"/>',
            '    <body name="pelvis" pos="0 1 0">',
            "      <freejoint/>",
            '      <camera name="side" mode="trackcom" pos="0.4 0.0 3.2" xyaxes="1 0 0 0 1 0"/>',
            f'      <geom type="capsule" size="{_RADIUS["pelvis"]}" '
            f'fromto="0 0 {-w:.4f} 0 0 {w:.4f}" rgba="0.5 0.5 0.55 1"/>',
            *root_kids,
            "    </body>",
            "  </worldbody>",
            "</mujoco>",
        ]
    )


def qpos_sequence(model, hinges: list[tuple[str, int, int]], root: np.ndarray, euler: np.ndarray) -> np.ndarray:
    """(T, nq): free joint (position, identity quaternion) then every hinge angle."""
    T = root.shape[0]
    q = np.zeros((T, model.nq))
    q[:, :3] = root
    q[:, 3] = 1.0
    for name, j, ax in hinges:
        q[:, model.joint(name).qposadr[0]] = euler[:, j, ax]
    return q


def write_video(
    path: str | Path, s: Settings, l: float, fps: float, root: np.ndarray, upper: np.ndarray, legs: np.ndarray
) -> dict:
    """Render the run with the character's capsule bodies through charctl.viz.video.render_qpos."""
    import mujoco

    from charctl.viz.video import render_qpos

    xml, hinges = mjcf(s, l)
    model = mujoco.MjModel.from_xml_string(xml)
    joints = skeleton(s, l)
    q = qpos_sequence(model, hinges, root, joint_euler(joints, upper, legs))
    return render_qpos(model, q, path, fps, camera="side")
