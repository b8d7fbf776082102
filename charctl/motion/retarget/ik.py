"""Retargeting step 4 (docs/motion_import.md): end-effector targets (planted feet, scaled hands) and
two-bone IK of knees and elbows onto the humanoid's hinges (metres, radians, y-up)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from charctl.motion import rotations as R
from charctl.motion.clip import Clip
from charctl.motion.retarget.common import (
    _Y,
    _Z,
    BLEND_S,
    CONTACT_MIN_S,
    PLANT_HEIGHT,
    SIDES,
    STANCE_HEIGHT,
    STANCE_SPEED,
    RetargetHumanoid,
)
from charctl.motion.retarget.orient import unit_and_norm
from charctl.motion.retarget.source import clean_mask, true_runs


# ---------------------------------------------------------------------------- targets and two-bone IK
def _plant_feet(
    ankle: np.ndarray, foot_rot: np.ndarray, hum: RetargetHumanoid, fps: float
) -> tuple[np.ndarray, np.ndarray]:
    """Ankle target (T, 3) that plants the foot: (T,) stance frames and the target.

    The humanoid's foot box is placed at the scaled source ankle with the transferred orientation. A stance
    frame is one whose lowest sole corner is within STANCE_HEIGHT of the ground and moves slower than
    STANCE_SPEED (a swing foot that only grazes the ground moves fast). In a stance phase the lowest corner
    touches the ground and the corners that are on the ground in two consecutive frames do not move (the
    foot pivots about them: flat, heel strike, toe-off alike); the horizontal offset this pinning makes
    fades out over BLEND_S after the phase. Elsewhere the foot is only lifted clear of the ground."""
    T = len(ankle)
    local = np.broadcast_to(hum.foot_corners, (T, 8, 3))
    rel = R.rotate(foot_rot[:, None, :], local)  # (T, 8, 3) corners relative to the ankle
    clear = -rel[..., 1].min(axis=1)
    low = rel[..., 1].argmin(axis=1)
    lowest = ankle + rel[np.arange(T), low]
    speed = np.linalg.norm(np.gradient(lowest[:, [0, 2]], 1.0 / fps, axis=0), axis=-1)
    raw = (lowest[:, 1] < STANCE_HEIGHT) & (speed < STANCE_SPEED)
    stance = clean_mask(raw, max(1, int(round(CONTACT_MIN_S * fps))))

    out = ankle.copy()
    out[:, 1] = np.where(stance, clear, np.maximum(ankle[:, 1], clear))
    offset = np.zeros((T, 2))
    nb = max(1, int(round(BLEND_S * fps)))
    for a, b in true_runs(stance):
        acc = np.zeros(2)
        prev = None
        for t in range(a, b):
            world = out[t] + rel[t]
            world[:, [0, 2]] += acc
            on = world[:, 1] < PLANT_HEIGHT
            if prev is not None:
                both = on & prev[1]
                if both.any():
                    acc = acc + (prev[0][both][:, [0, 2]] - world[both][:, [0, 2]]).mean(axis=0)
                    world[:, [0, 2]] = out[t, [0, 2]] + rel[t][:, [0, 2]] + acc
            offset[t] = acc
            prev = (world, on)
        for k in range(1, nb + 1):  # fade the last offset out over the swing that follows
            t = b - 1 + k
            if t < T and not stance[t]:
                offset[t] = offset[b - 1] * (1.0 - k / (nb + 1))
    out[:, [0, 2]] += offset
    return out, stance


def _two_bone(
    base: np.ndarray,
    target: np.ndarray,
    pole: np.ndarray,
    l1: float,
    l2: float,
    sign: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ball + z-hinge chain from `base` towards `target` (T, 3): (upper world rotation (T, 4), hinge angle
    (T,), reach shortfall (T,) metres). `pole` (T, 3): the wanted world direction of the upper body's z
    axis; `sign` -1 for knees (angle in [-pi, 0]), +1 for elbows ([0, pi])."""
    D = target - base
    dist = np.linalg.norm(D, axis=-1)
    lo, hi = abs(l1 - l2) + 1e-6, l1 + l2 - 1e-6
    d = np.clip(dist, lo, hi)
    cos_inner = np.clip((l1 * l1 + l2 * l2 - d * d) / (2 * l1 * l2), -1.0, 1.0)
    theta = sign * (np.pi - np.arccos(cos_inner))
    v_loc = np.stack([l2 * np.sin(theta), -l1 - l2 * np.cos(theta), np.zeros_like(theta)], axis=-1)
    e1, _ = unit_and_norm(v_loc)
    e2 = np.broadcast_to(_Z, e1.shape)
    f1, _ = unit_and_norm(D)
    p = pole - np.sum(pole * f1, axis=-1, keepdims=True) * f1
    f2, norm = unit_and_norm(p)
    bad = norm < 1e-6
    if np.any(bad):  # pole along the limb: any perpendicular
        alt = np.cross(f1[bad], np.array([1.0, 0.0, 0.0]))
        f2[bad] = unit_and_norm(alt)[0]
    E = np.stack([e1, e2, np.cross(e1, e2)], axis=-1)  # columns
    F = np.stack([f1, f2, np.cross(f1, f2)], axis=-1)
    upper = Rotation.from_matrix(F @ np.swapaxes(E, -1, -2)).as_quat()
    return upper, theta, np.maximum(dist - hi, 0.0)


def _root_drop(root: np.ndarray, rot: np.ndarray, targets: list[np.ndarray], offsets: list, reach: float, fps: float):
    """(T,) how far the root must come down so both ankle targets are within reach (smoothed, >= raw)."""
    need = np.zeros(len(root))
    for tgt, off in zip(targets, offsets):
        hip = root + R.rotate(rot, np.broadcast_to(off, root.shape))
        D = tgt - hip
        dist2 = np.sum(D * D, axis=-1)
        horiz2 = D[:, 0] ** 2 + D[:, 2] ** 2
        r = reach - 1e-4
        out = dist2 > r * r
        delta = np.zeros(len(root))
        ok = out & (horiz2 < r * r)
        delta[ok] = -D[ok, 1] - np.sqrt(r * r - horiz2[ok])
        need = np.maximum(need, np.maximum(delta, 0.0))
    if not need.any():
        return need
    from scipy.ndimage import gaussian_filter1d, maximum_filter1d

    k = max(1, int(round(0.05 * fps)))
    smooth = gaussian_filter1d(maximum_filter1d(need, 2 * k + 1), k)
    return np.maximum(smooth, need)


def solve_clip(src, H, contacts, hum: RetargetHumanoid, arm_scale: float, name: str, label: str, ground: bool = True):
    """The retargeted clip, the end-effector targets (m, world), the scaled source end effectors and
    the stance flags; `H`: the source's world rotations by humanoid joint name."""
    j = src.jmap.joints
    P, T = src.pos, src.num_frames
    skel, idx, off = hum.skel, hum.idx, hum.skel.offsets
    root_pos = 0.5 * (P[:, j["right_hip"]] + P[:, j["left_hip"]])
    root_rot = H["root"]
    scaled, targets, foot_rot, stance = _ankle_targets(src, H, contacts, hum, ground)
    hip_off = [off[idx["right_hip"]], off[idx["left_hip"]]]
    drop = _root_drop(root_pos, root_rot, [targets["right_ankle"], targets["left_ankle"]], hip_off, hum.leg, src.fps)
    root_pos = root_pos - drop[:, None] * _Y

    local = np.tile(R.IDENTITY, (T, skel.num_bodies, 1))
    local[:, idx["root"]] = root_rot
    local[:, idx["chest"]] = R.multiply(R.conjugate(root_rot), H["chest"])
    local[:, idx["neck"]] = R.multiply(R.conjugate(H["chest"]), H["neck"])
    chest_pos = root_pos + R.rotate(root_rot, np.broadcast_to(off[idx["chest"]], root_pos.shape))
    for s in SIDES:
        _solve_leg(s, local, root_pos, root_rot, H, targets[f"{s}_ankle"], foot_rot[s], hum)
        # arms: the source hand relative to its shoulder, scaled to the humanoid's arm, at its shoulder
        sh = chest_pos + R.rotate(H["chest"], np.broadcast_to(off[idx[f"{s}_shoulder"]], root_pos.shape))
        rel = P[:, j[f"{s}_wrist"]] - P[:, j[f"{s}_shoulder"]]
        hand = sh + arm_scale * rel
        scaled[f"{s}_wrist"] = hand
        if ground:  # a hand on the floor: the wrist sphere rests on it
            hand = hand.copy()
            hand[:, 1] = np.maximum(hand[:, 1], hum.hand_radius)
        targets[f"{s}_wrist"] = hand
        _solve_arm(s, local, sh, hand, H, hum)
    clip = Clip(
        name=name,
        fps=src.fps,
        root_pos=root_pos,
        local_rot=R.continuous_sign(R.normalize(local)),
        loop=False,
        label=label,
        source=src.path,
        skeleton=skel,
    )
    return clip, targets, scaled, stance


def _ankle_targets(
    src, H, contacts: np.ndarray, hum: RetargetHumanoid, ground: bool
) -> tuple[dict, dict, dict, np.ndarray]:
    """Per side: the source ankle (m, world), its IK target (planted on the ground when `ground`), the
    foot's world rotation, and the (T, 2) stance flags (recomputed by the planting when `ground`)."""
    j = src.jmap.joints
    P = src.pos
    scaled: dict[str, np.ndarray] = {}
    targets: dict[str, np.ndarray] = {}
    foot_rot: dict[str, np.ndarray] = {}
    stance = contacts.copy()
    for k, s in enumerate(SIDES):
        ankle = P[:, j[f"{s}_ankle"]].copy()
        scaled[f"{s}_ankle"] = ankle
        q = H[f"{s}_ankle"]
        foot_rot[s] = q
        tgt = ankle.copy()
        if ground:
            tgt, stance[:, k] = _plant_feet(ankle, q, hum, src.fps)
        targets[f"{s}_ankle"] = tgt
    return scaled, targets, foot_rot, stance


def _solve_leg(
    s: str,
    local: np.ndarray,
    root_pos: np.ndarray,
    root_rot: np.ndarray,
    H: dict,
    ankle_target: np.ndarray,
    foot_rot: np.ndarray,
    hum: RetargetHumanoid,
) -> None:
    """Side `s`'s hip, knee and ankle local rotations into `local` (T, bodies, 4): two-bone IK from
    the hip to `ankle_target` (bend sign -1, pole from the source hip), the foot keeping
    its source world rotation."""
    idx, off = hum.idx, hum.skel.offsets
    base = root_pos + R.rotate(root_rot, np.broadcast_to(off[idx[f"{s}_hip"]], root_pos.shape))
    pole = R.rotate(H[f"{s}_hip"], np.broadcast_to(_Z, root_pos.shape))
    upper, theta, _ = _two_bone(base, ankle_target, pole, hum.thigh, hum.shin, -1.0)
    local[:, idx[f"{s}_hip"]] = R.multiply(R.conjugate(root_rot), upper)
    local[:, idx[f"{s}_knee"]] = R.from_axis_angle(_Z, theta)
    shin = R.multiply(upper, local[:, idx[f"{s}_knee"]])
    local[:, idx[f"{s}_ankle"]] = R.multiply(R.conjugate(shin), foot_rot)


def _solve_arm(
    s: str, local: np.ndarray, shoulder: np.ndarray, hand: np.ndarray, H: dict, hum: RetargetHumanoid
) -> None:
    """Side `s`'s shoulder and elbow local rotations into `local`: two-bone IK from the shoulder
    position (m, world) to `hand` (bend sign +1, pole from the source shoulder)."""
    idx = hum.idx
    pole = R.rotate(H[f"{s}_shoulder"], np.broadcast_to(_Z, shoulder.shape))
    upper, theta, _ = _two_bone(shoulder, hand, pole, hum.upper_arm, hum.forearm, 1.0)
    local[:, idx[f"{s}_shoulder"]] = R.multiply(R.conjugate(H["chest"]), upper)
    local[:, idx[f"{s}_elbow"]] = R.from_axis_angle(_Z, theta)
