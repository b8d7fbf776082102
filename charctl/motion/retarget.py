"""Retarget a motion-capture file of any skeleton onto the humanoid (`charctl data import`).

Pipeline (docs/motion_import.md states each step with its equations and the decisions taken):

1. `read_source`: world joint trajectories in charctl's frame (y-up, metres), resampled to `fps`;
   scaled by s = humanoid leg length / source leg length (hip -> knee -> ankle), so the root path
   and step lengths scale with the legs. (At the end the clip is turned and moved so frame 0 faces +x
   at the origin, as the DeepMimic clips are.)
2. Planted-flat foot frames from the source (ankle low and slow), which align the feet in step 3.
3. Orientation transfer relative to each skeleton's rest frame: for every humanoid body b with source
   joint j, H_b(t) = Q_j(t) A_b, where the constant A_b (the source joint's frame seen from the
   humanoid body's rest frame) best aligns, over the whole clip, the humanoid's rest-pose directions
   (bone, hinge axis, pelvis/shoulder line, sole normal) with the same directions measured on the source
   (Wahba's problem, one SVD per body). Nothing depends on the file's zero pose, which is a T-pose in
   one convention and a bind pose of arbitrary orientations in another. Then the whole motion is shifted
   vertically so the humanoid's feet touch the ground when planted (root height from the feet).
4. Knees and elbows projected onto the humanoid's hinges (z axis, knee in [-pi, 0], elbow in [0, pi])
   by two-bone IK: the hinge angle from the law of cosines, the thigh/upper arm turned so the ankle /
   wrist lands on its target while the hinge axis stays as close as possible to the transferred one.
   Feet targets: the scaled source ankles, the foot planted in stance (`_plant_feet`: the sole corners on
   the ground do not move) and lifted clear of the ground elsewhere; hands: the source hand relative to
   its shoulder, scaled by the arm-length ratio, at the humanoid's shoulder.
5. Refinement with mink (differential IK on the project's MJCF, joint limits as QP constraints) on
   every frame where an end effector is still off its target by more than `REFINE_TOL` (targets out of
   reach: the root may then move) or a body is under the ground (that body then gets a position task
   at its depth above where it is; the feet and hands keep their targets).

The result is a `Clip` (DeepMimic layout) plus everything the quality report needs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from charctl.errors import CharctlError
from charctl.motion import rotations as R
from charctl.motion.bvh_any import SourceMotion, read_source
from charctl.motion.clip import Clip
from charctl.motion.skeleton import END_EFFECTORS, load_skeleton

DEFAULT_FPS = 60.0
# planted-flat frames (step 2): the ankle this close to the clip's lowest ankle level and this slow
CONTACT_HEIGHT = 0.025  # m
CONTACT_SPEED = 0.15  # m/s (scaled source): the flat part of a stance, not heel strike / toe-off
CONTACT_MIN_S = 0.05  # s: contact or stance runs and gaps shorter than this are dropped / filled
BLEND_S = 0.1  # s: the offset that planting a foot makes fades out over this after the stance
STANCE_HEIGHT = 0.02  # m: lowest sole corner at most this high ...
STANCE_SPEED = 0.5  # m/s ... and slower than this: a stance frame (the foot is planted)
PLANT_HEIGHT = 0.01  # m: sole corners this low in two consecutive stance frames are held still
REFINE_TOL = 0.005  # m: end-effector residual after two-bone IK that sends a frame to mink
GROUND_TOL = 0.005  # m: a body this far under the ground sends a frame to mink
_Y = np.array([0.0, 1.0, 0.0])
_Z = np.array([0.0, 0.0, 1.0])
SIDES = ("right", "left")


@dataclass
class Retargeted:
    """A retargeted clip and the data behind its quality report (all at the clip's rate, metres, y-up)."""

    clip: Clip
    source: SourceMotion  # at the clip's rate, scaled and turned like the clip (pos in humanoid metres)
    scale: float  # humanoid leg / source leg (metres / metres)
    arm_scale: float  # humanoid arm / scaled source arm
    scaled_source: dict[str, np.ndarray]  # end effector -> (T, 3) where the scaled source puts it
    targets: dict[str, np.ndarray]  # end effector -> (T, 3) the IK targets (contacts held, above ground)
    contacts: np.ndarray  # (T, 2) bool, right/left foot planted (stance frames)
    refined_frames: int  # frames mink refined
    refine_iterations: int
    timings: dict[str, float] = field(default_factory=dict)  # seconds per stage
    notes: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class _Humanoid:
    """The humanoid's rest-pose numbers the retargeting uses."""

    skel: object
    idx: dict[str, int]
    thigh: float
    shin: float
    upper_arm: float
    forearm: float
    foot_corners: np.ndarray  # (8, 3) sole box corners in the foot frame
    sole: float  # ankle height over a flat sole
    hand_radius: float  # the wrist's collision sphere

    @property
    def leg(self) -> float:
        return self.thigh + self.shin

    @property
    def arm(self) -> float:
        return self.upper_arm + self.forearm


def humanoid() -> _Humanoid:
    skel = load_skeleton()
    idx = {n: i for i, n in enumerate(skel.names)}
    off = skel.offsets
    g = skel.geoms[idx["right_ankle"]]
    half, centre = np.array(g.size), np.array(g.pos)
    corners = centre + half * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    return _Humanoid(
        skel,
        idx,
        float(np.linalg.norm(off[idx["right_knee"]])),
        float(np.linalg.norm(off[idx["right_ankle"]])),
        float(np.linalg.norm(off[idx["right_elbow"]])),
        float(np.linalg.norm(off[idx["right_wrist"]])),
        corners,
        float(-corners[:, 1].min()),
        float(skel.geoms[idx["right_wrist"]].size[0]),
    )


# ---------------------------------------------------------------------------- entry point
def retarget(
    path: str | Path,
    skeleton: str | None = None,
    up: str | None = None,
    units: str | None = None,
    fps: float = DEFAULT_FPS,
    start: float | None = None,
    stop: float | None = None,
    name: str | None = None,
    label: str = "",
    refine: bool = True,
    ground: bool = True,
) -> Retargeted:
    """Retarget the BVH file `path` onto the humanoid; see the module docstring. `ground=False` keeps the
    source's feet as they are (no contact holding, no height fitting, no ground clearance): for clips that
    are already clean, and to check the geometric core."""
    if not (np.isfinite(fps) and fps > 0):
        raise CharctlError(f"--fps must be a finite number > 0, got {fps}")
    times: dict[str, float] = {}
    t0 = time.perf_counter()
    src = read_source(path, skeleton, up, units, start, stop)
    times["read"] = time.perf_counter() - t0
    hum = humanoid()

    t0 = time.perf_counter()
    src = _resample(src, fps)
    scale = hum.leg / src.leg_length()
    src = _scale(src, scale)
    contacts = _contacts(src)
    H = _transfer_orientations(src, contacts)
    if ground:
        src = _rebase_height(src, contacts, H, hum)
    times["transfer"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    arm_scale = hum.arm / (src.arm_length())
    clip, targets, scaled, contacts = _solve(src, H, contacts, hum, arm_scale, name or Path(path).stem, label, ground)
    times["two_bone_ik"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    refined, iters = 0, 0
    if refine:
        clip, refined, iters = _refine(clip, targets, ground)
    times["mink"] = time.perf_counter() - t0
    return _canonical(Retargeted(clip, src, scale, arm_scale, scaled, targets, contacts, refined, iters, times))


# ---------------------------------------------------------------------------- source preparation
def _resample(src: SourceMotion, fps: float) -> SourceMotion:
    """Resample positions (linear) and world rotations (slerp) to `fps`; duration and ends kept."""
    T = src.num_frames
    duration = (T - 1) / src.fps
    n = max(2, int(round(duration * fps)) + 1)
    x = np.linspace(0.0, T - 1, n)
    i0 = np.clip(np.floor(x).astype(int), 0, T - 2)
    w = (x - i0)[:, None, None]
    pos = (1 - w) * src.pos[i0] + w * src.pos[i0 + 1]
    J = src.rot.shape[1]
    rot = R.slerp(src.rot[i0], src.rot[i0 + 1], np.broadcast_to(w[:, :, 0], (n, J)))
    ends = {j: (1 - w[:, :, 0]) * p[i0] + w[:, :, 0] * p[i0 + 1] for j, p in src.end_pos.items()}
    new_fps = (n - 1) / duration if duration > 0 else fps
    return _replace(src, pos=pos, rot=rot, end_pos=ends, fps=new_fps)


def _replace(src: SourceMotion, **changes) -> SourceMotion:
    import dataclasses

    return dataclasses.replace(src, **changes)


def _scale(src: SourceMotion, scale: float) -> SourceMotion:
    """Positions scaled by the leg-length ratio (about the world origin)."""
    return _replace(src, pos=src.pos * scale, end_pos={k: p * scale for k, p in src.end_pos.items()})


def _turn_and_move(src: SourceMotion, turn: np.ndarray, shift: np.ndarray) -> SourceMotion:
    def move(p: np.ndarray) -> np.ndarray:
        return R.rotate(np.broadcast_to(turn, p.shape[:-1] + (4,)), p - shift)

    rot = R.multiply(np.broadcast_to(turn, src.rot.shape), src.rot)
    return _replace(src, pos=move(src.pos), rot=rot, end_pos={k: move(p) for k, p in src.end_pos.items()})


def _canonical(r: Retargeted) -> Retargeted:
    """Frame 0 at x = z = 0 facing +x (the root's forward axis), as `Clip.canonicalize` puts the
    DeepMimic clips; the source and the targets move with the clip."""
    clip = r.clip
    turn = R.heading_quat(np.array(-clip.heading()[0]))
    shift = clip.root_pos[0] * np.array([1.0, 0.0, 1.0])

    def move(p: np.ndarray) -> np.ndarray:
        return R.rotate(np.broadcast_to(turn, p.shape[:-1] + (4,)), p - shift)

    r.clip = clip.canonicalize(0)
    r.source = _turn_and_move(r.source, turn, shift)
    r.targets = {k: move(v) for k, v in r.targets.items()}
    r.scaled_source = {k: move(v) for k, v in r.scaled_source.items()}
    return r


def _toe(src: SourceMotion, side: str) -> np.ndarray:
    """(T, 3) toe point of a foot: the toe joint, else the foot joint's End Site or child."""
    p = src.point(f"{side}_toe")
    if p is None:
        p = src.end_or_child(src.jmap.joints[f"{side}_ankle"])
    if p is None:
        raise CharctlError(f"{src.path}: the {side} foot has no toe joint nor End Site (map {side}_toe)")
    return p


def _clean(mask: np.ndarray, n: int) -> np.ndarray:
    """Fill gaps shorter than n frames, then drop runs shorter than n frames."""
    out = mask.copy()
    for value in (False, True):  # gaps first (runs of False), then short contacts (runs of True)
        runs = _runs(out == value)
        for a, b in runs:
            if b - a < n and a > 0 and b < len(out):
                out[a:b] = not value
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of every run of True."""
    d = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def _contacts(src: SourceMotion) -> np.ndarray:
    """(T, 2) right/left foot contact: ankle within CONTACT_HEIGHT of the clip's ankle level and slow."""
    j = src.jmap.joints
    ankles = np.stack([src.pos[:, j[f"{s}_ankle"]] for s in SIDES], axis=1)  # (T, 2, 3)
    level = np.percentile(ankles[:, :, 1], 5)
    speed = np.linalg.norm(np.gradient(ankles, 1.0 / src.fps, axis=0), axis=-1)
    raw = (ankles[:, :, 1] - level < CONTACT_HEIGHT) & (speed < CONTACT_SPEED)
    n = max(1, int(round(CONTACT_MIN_S * src.fps)))
    return np.stack([_clean(raw[:, k], n) for k in range(2)], axis=1)


def _clearance(foot_rot: np.ndarray, hum: _Humanoid) -> np.ndarray:
    """(T,) ankle height at which the lowest corner of the foot box, turned by `foot_rot`, touches the ground."""
    T = foot_rot.shape[0]
    corners = R.rotate(foot_rot[:, None, :], np.broadcast_to(hum.foot_corners, (T, 8, 3)))
    return -corners[..., 1].min(axis=1)


def _rebase_height(src: SourceMotion, contacts: np.ndarray, H: dict, hum: _Humanoid) -> SourceMotion:
    """Shift vertically so the humanoid's feet, placed at the source ankles with the transferred foot
    orientations, touch the ground during contact (median over the contact frames): root height from the
    feet. A clip without contact frames is put on the ground at its lowest foot frame."""
    j = src.jmap.joints
    gaps = []
    for k, s in enumerate(SIDES):
        gap = src.pos[:, j[f"{s}_ankle"], 1] - _clearance(H[f"{s}_ankle"], hum)
        gaps.append(gap[contacts[:, k]] if contacts[:, k].any() else gap)
    g = np.concatenate(gaps)
    h = np.median(g) if contacts.any() else np.min(g)
    dy = np.array([0.0, -h, 0.0])
    return _replace(src, pos=src.pos + dy, end_pos={k: p + dy for k, p in src.end_pos.items()})


# ---------------------------------------------------------------------------- orientation transfer
def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-9), n[..., 0]


def _alignment(q: np.ndarray, features: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> np.ndarray:
    """A (xyzw) minimising sum_k,t w_kt |A h_k - Q(t)^-1 d_kt|^2 (Wahba, SVD).

    `features`: (h (3,) humanoid rest direction, d (T, 3) source world direction, w (T,) weights)."""
    M = np.zeros((3, 3))
    qi = R.conjugate(q)
    for h, d, w in features:
        s = R.rotate(qi, _unit(d)[0])
        M += np.einsum("t,ti,j->ij", w, s, h / np.linalg.norm(h))
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return Rotation.from_matrix(U @ D @ Vt).as_quat()


def _hinge(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hinge normal (b - a) x (c - b) per frame and its weight sin(bend)."""
    u, _ = _unit(b - a)
    v, _ = _unit(c - b)
    n = np.cross(u, v)
    return n, np.linalg.norm(n, axis=-1)


def _transfer_orientations(src: SourceMotion, contacts: np.ndarray) -> dict[str, np.ndarray]:
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
        toe = _toe(src, s)
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


# ---------------------------------------------------------------------------- targets and two-bone IK
def _plant_feet(ankle: np.ndarray, foot_rot: np.ndarray, hum: _Humanoid, fps: float) -> tuple[np.ndarray, np.ndarray]:
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
    stance = _clean(raw, max(1, int(round(CONTACT_MIN_S * fps))))

    out = ankle.copy()
    out[:, 1] = np.where(stance, clear, np.maximum(ankle[:, 1], clear))
    offset = np.zeros((T, 2))
    nb = max(1, int(round(BLEND_S * fps)))
    for a, b in _runs(stance):
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
    e1, _ = _unit(v_loc)
    e2 = np.broadcast_to(_Z, e1.shape)
    f1, _ = _unit(D)
    p = pole - np.sum(pole * f1, axis=-1, keepdims=True) * f1
    f2, norm = _unit(p)
    bad = norm < 1e-6
    if np.any(bad):  # pole along the limb: any perpendicular
        alt = np.cross(f1[bad], np.array([1.0, 0.0, 0.0]))
        f2[bad] = _unit(alt)[0]
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


def _solve(src, H, contacts, hum: _Humanoid, arm_scale: float, name: str, label: str, ground: bool = True):
    j = src.jmap.joints
    P, T = src.pos, src.num_frames
    skel, idx, off = hum.skel, hum.idx, hum.skel.offsets
    root_pos = 0.5 * (P[:, j["right_hip"]] + P[:, j["left_hip"]])
    root_rot = H["root"]

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

    hip_off = [off[idx["right_hip"]], off[idx["left_hip"]]]
    drop = _root_drop(root_pos, root_rot, [targets["right_ankle"], targets["left_ankle"]], hip_off, hum.leg, src.fps)
    root_pos = root_pos - drop[:, None] * _Y

    local = np.tile(R.IDENTITY, (T, skel.num_bodies, 1))
    local[:, idx["root"]] = root_rot
    local[:, idx["chest"]] = R.multiply(R.conjugate(root_rot), H["chest"])
    local[:, idx["neck"]] = R.multiply(R.conjugate(H["chest"]), H["neck"])
    chest_pos = root_pos + R.rotate(root_rot, np.broadcast_to(off[idx["chest"]], root_pos.shape))
    for s in SIDES:
        # legs
        base = root_pos + R.rotate(root_rot, np.broadcast_to(off[idx[f"{s}_hip"]], root_pos.shape))
        pole = R.rotate(H[f"{s}_hip"], np.broadcast_to(_Z, root_pos.shape))
        upper, theta, _ = _two_bone(base, targets[f"{s}_ankle"], pole, hum.thigh, hum.shin, -1.0)
        local[:, idx[f"{s}_hip"]] = R.multiply(R.conjugate(root_rot), upper)
        local[:, idx[f"{s}_knee"]] = R.from_axis_angle(_Z, theta)
        shin = R.multiply(upper, local[:, idx[f"{s}_knee"]])
        local[:, idx[f"{s}_ankle"]] = R.multiply(R.conjugate(shin), foot_rot[s])
        # arms: the source hand relative to its shoulder, scaled to the humanoid's arm, at its shoulder
        sh = chest_pos + R.rotate(H["chest"], np.broadcast_to(off[idx[f"{s}_shoulder"]], root_pos.shape))
        rel = P[:, j[f"{s}_wrist"]] - P[:, j[f"{s}_shoulder"]]
        hand = sh + arm_scale * rel
        scaled[f"{s}_wrist"] = hand
        if ground:  # a hand on the floor: the wrist sphere rests on it
            hand = hand.copy()
            hand[:, 1] = np.maximum(hand[:, 1], hum.hand_radius)
        targets[f"{s}_wrist"] = hand
        pole = R.rotate(H[f"{s}_shoulder"], np.broadcast_to(_Z, root_pos.shape))
        upper, theta, _ = _two_bone(sh, hand, pole, hum.upper_arm, hum.forearm, 1.0)
        local[:, idx[f"{s}_shoulder"]] = R.multiply(R.conjugate(H["chest"]), upper)
        local[:, idx[f"{s}_elbow"]] = R.from_axis_angle(_Z, theta)
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


# ---------------------------------------------------------------------------- mink refinement
def lowest_points(clip_or_fk, skel=None) -> np.ndarray:
    """(T, B) lowest world height of each body's collision shape."""
    if isinstance(clip_or_fk, Clip):
        pos, rot = clip_or_fk.fk
        skel = clip_or_fk.skeleton
    else:
        pos, rot = clip_or_fk
    T = pos.shape[0]
    out = np.empty((T, skel.num_bodies))
    for b, g in enumerate(skel.geoms):
        c = np.array(g.pos)
        if g.kind == "sphere":
            pts = c[None]
            r = g.size[0]
        elif g.kind == "capsule":
            r, half = g.size
            pts = np.stack([c + [0, half, 0], c - [0, half, 0]])
        else:
            half = np.array(g.size)
            pts = c + half * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
            r = 0.0
        world = pos[:, b, None, :] + R.rotate(rot[:, b, None, :], np.broadcast_to(pts, (T,) + pts.shape))
        out[:, b] = world[..., 1].min(axis=1) - r
    return out


def _lowest_geom(model, data) -> float:
    """Lowest point (m) of the humanoid's collision geoms in a MuJoCo state (signed distance to the floor)."""
    import mujoco

    floor = model.geom("floor").id
    fromto = np.zeros(6)
    return min(mujoco.mj_geomDistance(model, data, g, floor, 0.5, fromto) for g in range(model.ngeom) if g != floor)


def ee_errors(clip: Clip, targets: dict[str, np.ndarray]) -> np.ndarray:
    """(T, 4) distance (m) of each end effector (END_EFFECTORS order) from its target."""
    pos = clip.body_pos
    sk = clip.skeleton
    return np.stack([np.linalg.norm(pos[:, sk.index(e)] - targets[e], axis=-1) for e in END_EFFECTORS], axis=1)


def _refine(clip: Clip, targets: dict[str, np.ndarray], ground: bool = True, max_iters: int = 30):
    """mink IK on the frames whose end effectors miss their targets or (`ground`) that go under the ground."""
    err = ee_errors(clip, targets).max(axis=1)
    low = lowest_points(clip).min(axis=1)
    frames = np.flatnonzero((err > REFINE_TOL) | (ground & (low < -GROUND_TOL)))
    if frames.size == 0:
        return clip, 0, 0
    import mink

    from charctl.sim.humanoid import layout, load_model, local_rot_to_qpos, qpos_to_local_rot

    model = load_model()
    qpos = local_rot_to_qpos(clip.root_pos, clip.local_rot)
    body_pos, body_rot = clip.fk
    cfg = mink.Configuration(model)
    ee_tasks = {
        e: mink.FrameTask(e, "body", position_cost=1.0, orientation_cost=0.3 if "ankle" in e else 0.0, lm_damping=1e-2)
        for e in END_EFFECTORS
    }
    root_task = mink.FrameTask("root", "body", position_cost=0.1, orientation_cost=0.5, lm_damping=1e-2)
    chest_task = mink.FrameTask("chest", "body", position_cost=0.0, orientation_cost=0.5, lm_damping=1e-2)
    posture = mink.PostureTask(model, cost=1e-2)
    tasks = [*ee_tasks.values(), root_task, chest_task, posture]
    limits = [mink.ConfigurationLimit(model)]
    sk = clip.skeleton
    # a body under the ground gets a position task one depth higher (the feet and hands keep theirs)
    lift_tasks = [mink.FrameTask(b, "body", position_cost=2.0, orientation_cost=0.0, lm_damping=1e-2) for b in sk.names]
    depth = np.maximum(-lowest_points(clip), 0.0) if ground else np.zeros((clip.num_frames, sk.num_bodies))
    iters = 0
    lay = layout()
    out = qpos.copy()
    for t in frames:
        cfg.update(qpos[t])
        for e, task in ee_tasks.items():
            b = sk.index(e)
            rot = R.xyzw_to_wxyz(body_rot[t, b])
            task.set_target(mink.SE3.from_rotation_and_translation(mink.SO3(rot), targets[e][t]))
        for task, b in ((root_task, 0), (chest_task, sk.index("chest"))):
            rot = R.xyzw_to_wxyz(body_rot[t, b])
            task.set_target(mink.SE3.from_rotation_and_translation(mink.SO3(rot), body_pos[t, b]))
        posture.set_target(qpos[t])
        lifts = []
        for b in np.flatnonzero(depth[t] > GROUND_TOL):
            lift = body_pos[t, b] + (depth[t, b] + 0.002) * _Y
            lift_tasks[b].set_target(mink.SE3.from_rotation_and_translation(mink.SO3.identity(), lift))
            lifts.append(lift_tasks[b])
        for _ in range(max_iters):
            v = mink.solve_ik(cfg, tasks + lifts, 1.0, "daqp", damping=1e-4, limits=limits)
            cfg.integrate_inplace(v, 1.0)
            iters += 1
            worst = max(np.linalg.norm(cfg.data.xpos[model.body(e).id] - targets[e][t]) for e in END_EFFECTORS)
            if worst < 0.5 * REFINE_TOL and (not ground or _lowest_geom(model, cfg.data) > -0.5 * GROUND_TOL):
                break
        out[t] = cfg.q
    assert out.shape[1] == lay.nq
    root_pos, local = qpos_to_local_rot(out)
    return clip.replace(root_pos=root_pos, local_rot=R.continuous_sign(local)), int(frames.size), iters
