"""Retargeting step 3 (docs/motion_import.md): orientation transfer relative to each skeleton's rest frame
(Wahba's problem, one SVD per body)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from charctl.motion import rotations as R
from charctl.motion.bvh_any import SourceMotion
from charctl.motion.retarget.common import _Y, _Z, SIDES
from charctl.motion.retarget.source import toe_points


# ---------------------------------------------------------------------------- orientation transfer
def unit_and_norm(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-9), n[..., 0]


def _alignment(q: np.ndarray, features: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> np.ndarray:
    """A (xyzw) minimising sum_k,t w_kt |A h_k - Q(t)^-1 d_kt|^2 (Wahba, SVD).

    `features`: (h (3,) humanoid rest direction, d (T, 3) source world direction, w (T,) weights)."""
    M = np.zeros((3, 3))
    qi = R.conjugate(q)
    for h, d, w in features:
        s = R.rotate(qi, unit_and_norm(d)[0])
        M += np.einsum("t,ti,j->ij", w, s, h / np.linalg.norm(h))
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return Rotation.from_matrix(U @ D @ Vt).as_quat()


def _hinge(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hinge normal (b - a) x (c - b) per frame and its weight sin(bend)."""
    u, _ = unit_and_norm(b - a)
    v, _ = unit_and_norm(c - b)
    n = np.cross(u, v)
    return n, np.linalg.norm(n, axis=-1)


def transfer_orientations(src: SourceMotion, contacts: np.ndarray) -> dict[str, np.ndarray]:
    """World rotation (T, 4) of every humanoid body but the wrists: H_b = Q_j A_b."""
    j = src.jmap.joints
    P, Q, T = src.pos, src.rot, src.num_frames
    ones = np.ones(T)
    up = np.broadcast_to(_Y, (T, 3))
    hips = {s: P[:, j[f"{s}_hip"]] for s in SIDES}
    pelvis_right = hips["right"] - hips["left"]
    shoulder_right = P[:, j["right_shoulder"]] - P[:, j["left_shoulder"]]
    mid_hips = 0.5 * (hips["right"] + hips["left"])
    spine = _spine_point(src)
    neck_base = src.point("neck_base")
    head = P[:, j["neck"]]
    chest = P[:, j["chest"]]
    chest_up = (neck_base if neck_base is not None else head) - chest
    if np.median(np.linalg.norm(chest_up, axis=-1)) < 0.03:
        chest_up = head - chest
    # the head's up: along the neck (base of the neck -> head joint); End Sites point anywhere (Bandai-Namco's
    # head End Site points forward), so the head top serves only when the file has no neck joint
    top = src.point("head_top")
    if top is None:
        top = src.end_pos.get(j["neck"])
    if neck_base is not None and np.median(np.linalg.norm(head - neck_base, axis=-1)) >= 0.03:
        head_up = head - neck_base
    elif top is not None:
        head_up = top - head
    else:
        head_up = head - chest

    H: dict[str, np.ndarray] = {}

    def put(body: str, feats) -> None:
        q = Q[:, j[body]]
        H[body] = R.normalize(R.multiply(q, np.broadcast_to(_alignment(q, feats), q.shape)))

    put("root", [(_Z, pelvis_right, ones), (_Y, spine - mid_hips, ones)])
    put("chest", [(_Z, shoulder_right, ones), (_Y, chest_up, ones)])
    put("neck", [(_Y, head_up, ones), (_Z, shoulder_right, 0.5 * ones)])
    for k, s in enumerate(SIDES):
        hip, knee, ankle = (P[:, j[f"{s}_{b}"]] for b in ("hip", "knee", "ankle"))
        n, w = _hinge(hip, knee, ankle)
        weak = 0.05 * ones
        put(f"{s}_hip", [(-_Y, knee - hip, ones), (-_Z, n, w), (_Z, pelvis_right, weak)])
        put(f"{s}_knee", [(-_Y, ankle - knee, ones), (-_Z, n, w), (_Z, pelvis_right, weak)])
        toe = toe_points(src, s)
        fwd = toe - ankle
        flat = contacts[:, k].astype(float)
        if flat.sum() < 2:  # never in contact: the frames with the lowest toe stand in for flat ones
            flat = (toe[:, 1] <= np.percentile(toe[:, 1], 20)).astype(float)
        fwd_h = fwd * np.array([1.0, 0.0, 1.0])
        put(f"{s}_ankle", [(_Y, up, flat), (np.array([1.0, 0.0, 0.0]), fwd_h, flat), (-_Z, n, 0.05 * w)])
        sh, el, wr = (P[:, j[f"{s}_{b}"]] for b in ("shoulder", "elbow", "wrist"))
        n, w = _hinge(sh, el, wr)
        put(f"{s}_shoulder", [(-_Y, el - sh, ones), (_Z, n, w), (_Z, shoulder_right, weak)])
        put(f"{s}_elbow", [(-_Y, wr - el, ones), (_Z, n, w), (_Z, shoulder_right, weak)])
    return H


def _spine_point(src: SourceMotion) -> np.ndarray:
    """(T, 3) the first joint on the path from the root to the chest joint that is >= 5 cm above it."""
    j = src.jmap.joints
    path, k = [], j["chest"]
    while k >= 0 and k != j["root"]:
        path.append(k)
        k = int(src.parents[k])
    for k in reversed(path):
        if np.median(np.linalg.norm(src.pos[:, k] - src.pos[:, j["root"]], axis=-1)) >= 0.05:
            return src.pos[:, k]
    return src.pos[:, j["chest"]]
