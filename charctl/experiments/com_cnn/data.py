"""com-cnn dataset (paper §3.2): clips at 30 fps, start at the origin facing +z, COM from the paper's
mass table, and every frame cut into (history M_t, COM C_t) -> pose m_t samples.

Pose vector m (D = 6 + 3 J numbers, J = non-root joints; 48 for the DeepMimic humanoid, as in the
paper's 15 x 3 angles + root position):
    [0:3]  root position in the reference frame F (metres)
    [3:6]  root rotation in F as an exponential map (radians)
    [6: ]  the J joints' local rotations as exponential maps (radians), skeleton order
The reference frame F of sample t is the heading frame of the root at frame t (`data.frame=root_t`,
paper §3.2) or at t-1 (`root_prev`): origin = the root's ground projection, y up, rotated about y
so that the character's forward axis points along +z. History, COM and target are all in F.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.motion import rotations as R
from charctl.motion.fk import center_of_mass, forward_kinematics
from charctl.motion.skeleton import CLIP_JOINTS, HINGE_JOINTS, Skeleton, load_skeleton

XZ = np.array([1.0, 0.0, 1.0])
Z_AXIS = np.array([0.0, 0.0, 1.0])


# ---------------------------------------------------------------------------- body model
@dataclass(frozen=True, eq=False)
class BodyModel:
    """The skeleton behind the pose vector: names, COM masses, joint constraints, forward axis."""

    kind: str  # "humanoid" (DeepMimic) or "bvh"
    skeleton: Skeleton  # body 0 = root; FK and COM go through charctl.motion.fk
    masses: np.ndarray  # (B,) paper mass table mapped onto the bodies (0 for unmapped ones)
    forward: np.ndarray  # (3,) root-local forward axis (humanoid +x, BVH data.bvh_forward)
    hinge: np.ndarray  # (J,) bool: joint turns about its local z only (humanoid knees/elbows)
    fixed: np.ndarray  # (J,) bool: joint never moves (humanoid wrists)
    bvh_header: str = ""  # kind == "bvh": the HIERARCHY text of the first file (for writing)
    bvh_channels: tuple = ()  # kind == "bvh": channel names per joint
    bvh_scale: float = 1.0

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(self.skeleton.names[1:])

    @property
    def num_joints(self) -> int:
        return self.skeleton.num_bodies - 1

    @property
    def pose_dim(self) -> int:
        return 6 + 3 * self.num_joints

    @property
    def error_joints(self) -> np.ndarray:
        """Joint indices (into the J joints) the joint-angle error averages over: the movable ones."""
        return np.flatnonzero(~self.fixed)

    def com(self, root_pos: np.ndarray, root_rot: np.ndarray, joint_rot: np.ndarray) -> np.ndarray:
        """Whole-body COM (..., 3), world frame, metres, from the mass table."""
        local = np.concatenate([root_rot[..., None, :], joint_rot], axis=-2)
        pos, rot = forward_kinematics(self.skeleton, root_pos, local)
        return center_of_mass(self.skeleton, pos, rot, masses=self.masses)


def humanoid_body(com_cfg) -> BodyModel:
    """The DeepMimic humanoid with the paper's Table 1 masses mapped through `com.humanoid_bodies`."""
    skel = load_skeleton()
    masses = map_masses(com_cfg.mass_table, com_cfg.humanoid_bodies, skel.names, "com.humanoid_bodies")
    joints = skel.names[1:]
    return BodyModel(
        kind="humanoid",
        skeleton=skel,
        masses=masses,
        forward=np.array([1.0, 0.0, 0.0]),
        hinge=np.array([n in HINGE_JOINTS for n in joints]),
        fixed=np.array([n not in CLIP_JOINTS for n in joints]),
    )


def map_masses(table: dict, part_to_body: dict, names, key: str) -> np.ndarray:
    """(B,) masses in `names` order: body `part_to_body[part]` (default: the part name) gets table[part]."""
    masses = np.zeros(len(names))
    hits = 0
    for part, m in table.items():
        body = part_to_body.get(part, part)
        if body in names:
            masses[list(names).index(body)] += float(m)
            hits += 1
    if hits == 0 or masses.sum() <= 0:
        raise CharctlError(
            f"no body of the skeleton matches the mass table (parts {', '.join(list(table)[:4])}, "
            f"...; bodies {', '.join(list(names)[:4])}, ...); map them with {key}"
        )
    return masses


# ---------------------------------------------------------------------------- sequences
@dataclass(eq=False)
class Sequence:
    """One clip at the dataset rate, world frame (y up, metres), start at the origin facing +z."""

    name: str  # e.g. "walk:mirror"
    base: str  # the clip without ":mirror": the unit of the train/test split
    label: str  # motion class (evaluation only; never an input)
    fps: float
    root_pos: np.ndarray  # (T, 3)
    root_rot: np.ndarray  # (T, 4) xyzw, world
    joint_rot: np.ndarray  # (T, J, 4) xyzw, local
    com: np.ndarray = field(default=None)  # (T, 3) world
    cycles: int = 1  # loop repetitions it was built from

    @property
    def num_frames(self) -> int:
        return self.root_pos.shape[0]


def heading_yaw(root_rot: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """Heading psi (radians about +y): Ry(psi) maps +z onto the direction the character faces.

    Swing-twist decomposition root_rot = Ry(twist) * swing (swing about a horizontal axis):
    psi = twist + the rest pose's facing angle. Unlike projecting the forward axis on the ground,
    this stays well defined when the pelvis pitches 90 degrees (crawling, getting up, flips).
    """
    twist = 2.0 * np.arctan2(root_rot[..., 1], root_rot[..., 3])
    return twist + np.arctan2(forward[0], forward[2])


def canonical_start(root_pos, root_rot, forward):
    """Move frame 0's root to the origin (ground projection) and turn it to face +z (paper §3.2)."""
    q = R.heading_quat(-heading_yaw(root_rot[0], forward))
    qs = np.broadcast_to(q, root_rot.shape)
    return R.rotate(qs, root_pos - root_pos[0] * XZ), R.multiply(qs, root_rot)


def tile_loop(root_pos, root_rot, joint_rot, cycles: int, blend: int, forward):
    """Repeat a looping clip `cycles` times; each cycle starts where (and facing where) the last ended.

    The clip's last frame is the next cycle's first (DeepMimic "wrap"), so that frame is not
    repeated. DeepMimic loops do not close exactly (up to ~50 deg at a joint): the mismatch at each
    seam is spread over the `blend` frames before it (slerp of the correction).
    """
    ps, rs, js = [root_pos.copy()], [root_rot.copy()], [joint_rot.copy()]
    for _ in range(cycles - 1):
        lp, lr, lj = ps[-1], rs[-1], js[-1]
        turn = R.heading_quat(heading_yaw(lr[-1], forward) - heading_yaw(root_rot[0], forward))
        tq = np.broadcast_to(turn, root_rot.shape)
        new_p = R.rotate(tq, root_pos - root_pos[0] * XZ) + lp[-1] * XZ
        new_r = R.multiply(tq, root_rot)
        _blend_seam(lp, lr, lj, new_p[0], new_r[0], joint_rot[0], blend)
        ps.append(new_p[1:])
        rs.append(new_r[1:])
        js.append(joint_rot[1:].copy())
    return np.concatenate(ps), np.concatenate(rs), np.concatenate(js)


def _blend_seam(p, r, j, p_next, r_next, j_next, blend: int) -> None:
    """In place: bend the last `blend` frames of (p, r, j) so the last one equals the next cycle's first."""
    k = min(blend, p.shape[0] - 1)
    if k <= 0:
        p[-1], r[-1], j[-1] = p_next, r_next, j_next
        return
    w = (np.arange(k) + 1.0) / k  # ..., 1 at the last frame
    d_root = R.multiply(R.conjugate(r[-1]), r_next)
    d_joint = R.multiply(R.conjugate(j[-1]), j_next)
    ident = np.broadcast_to(R.IDENTITY, (k, 4))
    r[-k:] = R.normalize(R.multiply(r[-k:], R.slerp(ident, np.broadcast_to(d_root, (k, 4)), w)))
    J = j.shape[1]
    jw = np.broadcast_to(w[:, None], (k, J))
    j[-k:] = R.normalize(
        R.multiply(j[-k:], R.slerp(np.broadcast_to(R.IDENTITY, (k, J, 4)), np.broadcast_to(d_joint, (k, J, 4)), jw))
    )
    p[-k:, 1] += w * (p_next[1] - p[-1, 1])


def make_sequence(name, base, label, fps, root_pos, root_rot, joint_rot, loop, data_cfg, body: BodyModel) -> Sequence:
    """Tile (looping clips), canonicalise and attach the COM."""
    cycles = 1
    T = root_pos.shape[0]
    if loop and T > 2:
        cycles = max(1, math.ceil((data_cfg.loop_min_seconds * fps) / (T - 1)))
        root_pos, root_rot, joint_rot = tile_loop(
            root_pos, root_rot, joint_rot, cycles, data_cfg.loop_blend_frames, body.forward
        )
    root_pos, root_rot = canonical_start(root_pos, root_rot, body.forward)
    seq = Sequence(name, base, label, fps, root_pos, root_rot, joint_rot, cycles=cycles)
    seq.com = body.com(root_pos, root_rot, joint_rot)
    return seq


def load_deepmimic(cfg, body: BodyModel) -> list[Sequence]:
    """The configured DeepMimic clips (and mirrors) as sequences at `data.fps`."""
    from charctl.motion.library import load_clip

    out = []
    for name in cfg.data.clips:
        variants = [name, name + ":mirror"] if cfg.data.mirror else [name]
        for spec in variants:
            clip = load_clip(spec).resample(cfg.data.fps)
            out.append(
                make_sequence(
                    clip.name,
                    name,
                    clip.label or name,
                    clip.fps,
                    clip.root_pos,
                    clip.local_rot[:, 0],
                    clip.local_rot[:, 1:],
                    clip.loop,
                    cfg.data,
                    body,
                )
            )
    return out


# ---------------------------------------------------------------------------- user BVH folders
def bvh_label(rel: Path) -> str:
    """Motion class of a BVH file: its sub-folder, else its name without trailing digits/separators."""
    if len(rel.parts) > 1:
        return rel.parts[0]
    return re.sub(r"[\d_\-\s.]+$", "", rel.stem) or rel.stem


def load_bvh_dir(cfg) -> tuple[list[Sequence], BodyModel]:
    """Every .bvh under `data.bvh_dir` (one skeleton, y up) as sequences; the body model from the first file."""
    from charctl.motion.bvh import read_bvh
    from charctl.motion.clip import Clip

    root = Path(cfg.data.bvh_dir).expanduser()
    if not root.is_dir():
        raise CharctlError(f"data.bvh_dir: {root} is not a folder")
    files = sorted(root.rglob("*.bvh"))
    if not files:
        raise CharctlError(f"data.bvh_dir: no .bvh files in {root}")
    body, seqs = None, []
    for path in files:
        motion = read_bvh(path)
        if body is None:
            body = bvh_body(motion, path, cfg)
        elif list(motion.names) != list(body.skeleton.names):
            raise CharctlError(
                f"{path}: skeleton differs from {files[0].name} (all files in data.bvh_dir must share one skeleton)"
            )
        trans, rot = motion.local_transforms()
        rel = path.relative_to(root)
        name = str(rel.with_suffix(""))
        clip = Clip(
            name=name, fps=motion.fps, root_pos=trans[:, 0] * cfg.data.bvh_scale, local_rot=rot, skeleton=body.skeleton
        )
        if clip.num_frames < 2:
            raise CharctlError(f"{path}: needs at least 2 frames")
        clip = clip.resample(cfg.data.fps)
        seqs.append(
            make_sequence(
                name,
                name,
                bvh_label(rel),
                clip.fps,
                clip.root_pos,
                clip.local_rot[:, 0],
                clip.local_rot[:, 1:],
                False,
                cfg.data,
                body,
            )
        )
    return seqs, body


def bvh_body(motion, path: Path, cfg) -> BodyModel:
    """A BodyModel for a BVH skeleton: each joint's mass sits halfway to its first child (or end site)."""
    s = cfg.data.bvh_scale
    J = len(motion.names)
    half = np.zeros((J, 3))
    for j in range(J):
        kids = np.flatnonzero(motion.parents == j)
        if kids.size:
            half[j] = 0.5 * motion.offsets[kids[0]] * s
        elif j in motion.end_sites:
            half[j] = 0.5 * motion.end_sites[j] * s
    masses = map_masses(cfg.com.mass_table, dict(cfg.com.bvh_joints), motion.names, "com.bvh_joints")
    skel = Skeleton(
        names=tuple(motion.names),
        parents=np.asarray(motion.parents),
        offsets=motion.offsets * s,
        masses=masses,
        com_local=half,
        source=str(path),
    )
    text = path.read_text()
    header = text[: text.index("MOTION")]
    J1 = J - 1
    return BodyModel(
        kind="bvh",
        skeleton=skel,
        masses=masses,
        forward=np.asarray(cfg.data.bvh_forward, dtype=float),
        hinge=np.zeros(J1, bool),
        fixed=np.zeros(J1, bool),
        bvh_header=header,
        bvh_channels=tuple(tuple(c) for c in motion.channels),
        bvh_scale=s,
    )


def load_sequences(cfg) -> tuple[list[Sequence], BodyModel]:
    """All sequences of the configured data source and the body model behind them."""
    if cfg.data.bvh_dir:
        return load_bvh_dir(cfg)
    body = humanoid_body(cfg.com)
    return load_deepmimic(cfg, body), body


def split_sequences(seqs: list[Sequence], test_clips) -> tuple[list[Sequence], list[Sequence]]:
    """Train/test split by clip: a clip and its mirror share `base`, so they always land together."""
    test_set = set(test_clips)
    known = {s.base for s in seqs}
    missing = sorted(test_set - known)
    if missing:
        raise CharctlError(
            f"data.test_clips {missing} are not among the clips "
            f"({', '.join(sorted(known)[:8])}, ...); set data.test_clips=[...]"
        )
    train = [s for s in seqs if s.base not in test_set]
    test = [s for s in seqs if s.base in test_set]
    if not train:
        raise CharctlError("data.test_clips holds every clip: nothing left to train on")
    return train, test


def motion_type(label: str, motion_types: dict) -> str:
    """The paper's motion type (walk / crouch_walk / other) of a class label (eval.motion_types)."""
    for kind, labels in motion_types.items():
        if label in labels:
            return str(kind)
    return "other"


# ---------------------------------------------------------------------------- pose vectors
def heading_frame(root_pos: np.ndarray, root_rot: np.ndarray, forward) -> tuple[np.ndarray, np.ndarray]:
    """(origin (...,3), rotation (...,4)) of the heading frame: root ground projection, forward -> +z."""
    return root_pos * XZ, R.heading_quat(heading_yaw(root_rot, forward))


def encode_pose(origin, q_frame, root_pos, root_rot, joint_exp) -> np.ndarray:
    """Pose vectors (..., D) of world poses, expressed in the frame (origin, q_frame) (broadcast)."""
    inv = R.conjugate(q_frame)
    p = R.rotate(np.broadcast_to(inv, root_pos.shape[:-1] + (4,)), root_pos - origin)
    r = R.log_map(R.multiply(np.broadcast_to(inv, root_rot.shape), root_rot))
    return np.concatenate([p, r, joint_exp], axis=-1)


def decode_pose(m: np.ndarray, origin, q_frame, body: BodyModel):
    """World (root_pos (...,3), root_rot (...,4), joint_rot (...,J,4)) of pose vectors m (..., D) in a frame.

    Hinge joints keep only their z rotation and fixed joints are identity, so the result is a pose
    the skeleton can take.
    """
    q = np.broadcast_to(q_frame, m.shape[:-1] + (4,))
    root_pos = R.rotate(q, m[..., 0:3]) + origin
    root_rot = R.normalize(R.multiply(q, R.exp_map(m[..., 3:6])))
    jexp = constrain_joint_exp(m[..., 6:].reshape(m.shape[:-1] + (body.num_joints, 3)), body)
    return root_pos, root_rot, R.exp_map(jexp)


def constrain_joint_exp(jexp: np.ndarray, body: BodyModel) -> np.ndarray:
    """(..., J, 3) exponential maps with hinge joints projected on z and fixed joints zeroed."""
    out = np.array(jexp, copy=True)
    out[..., body.hinge, :2] = 0.0
    out[..., body.fixed, :] = 0.0
    return out


# ---------------------------------------------------------------------------- windows
@dataclass(eq=False)
class FrameTable:
    """Per-frame arrays of many sequences, concatenated (index = global frame number)."""

    root_pos: np.ndarray  # (N, 3) world
    root_rot: np.ndarray  # (N, 4) world
    joint_exp: np.ndarray  # (N, 3J) local exp maps
    com: np.ndarray  # (N, 3) world
    origin: np.ndarray  # (N, 3) heading-frame origin of each frame's root
    q_frame: np.ndarray  # (N, 4) heading-frame rotation
    start: np.ndarray  # (N,) global index of the frame's sequence start
    seq_index: np.ndarray  # (N,) which sequence
    offsets: np.ndarray  # (S+1,) sequence boundaries


def frame_table(seqs: list[Sequence], body: BodyModel) -> FrameTable:
    lens = np.array([s.num_frames for s in seqs])
    offsets = np.concatenate([[0], np.cumsum(lens)])
    root_pos = np.concatenate([s.root_pos for s in seqs])
    root_rot = np.concatenate([s.root_rot for s in seqs])
    joints = np.concatenate([s.joint_rot for s in seqs])
    origin, q = heading_frame(root_pos, root_rot, body.forward)
    return FrameTable(
        root_pos=root_pos,
        root_rot=root_rot,
        joint_exp=R.log_map(joints).reshape(len(joints), -1),
        com=np.concatenate([s.com for s in seqs]),
        origin=origin,
        q_frame=q,
        start=np.repeat(offsets[:-1], lens),
        seq_index=np.repeat(np.arange(len(seqs)), lens),
        offsets=offsets,
    )


@dataclass(eq=False)
class WindowSet:
    """All (M_t, C_t) -> m_t samples of a list of sequences.

    Sample t (a global frame index with at least one earlier frame in its sequence): history frames
    t-i .. t-1, where indices before the sequence start repeat its first frame (the character
    stood still before the clip began); target frame t; reference frame at t (root_t) or t-1.
    """

    seqs: list[Sequence]
    body: BodyModel
    history: int
    frame: str
    table: FrameTable = field(init=False)
    targets: np.ndarray = field(init=False)  # (S,) global frame index of each sample's target

    def __post_init__(self) -> None:
        self.table = frame_table(self.seqs, self.body)
        t = np.arange(self.table.root_pos.shape[0])
        self.targets = t[t > self.table.start]

    def __len__(self) -> int:
        return self.targets.shape[0]

    def history_index(self, t: np.ndarray) -> np.ndarray:
        """(B, i) global frame indices of the histories of targets t (clamped at the sequence start)."""
        idx = t[:, None] - self.history + np.arange(self.history)[None, :]
        return np.maximum(idx, self.table.start[t][:, None])

    def reference_index(self, t: np.ndarray) -> np.ndarray:
        return t if self.frame == "root_t" else t - 1

    def features(self, sample_idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """hist (B, i, D), com (B, 3), target (B, D) float32 for samples `sample_idx`, all in frame F."""
        tb = self.table
        t = self.targets[sample_idx]
        h = self.history_index(t)
        ref = self.reference_index(t)
        o, q = tb.origin[ref], tb.q_frame[ref]
        hist = encode_pose(o[:, None], q[:, None], tb.root_pos[h], tb.root_rot[h], tb.joint_exp[h])
        com = R.rotate(R.conjugate(q), tb.com[t] - o)
        target = encode_pose(o, q, tb.root_pos[t], tb.root_rot[t], tb.joint_exp[t])
        return hist.astype(np.float32), com.astype(np.float32), target.astype(np.float32)

    def dense_bytes(self) -> int:
        return len(self) * (self.history + 1) * self.body.pose_dim * 4


def build_windows(cfg) -> tuple[WindowSet, WindowSet, BodyModel]:
    """Train and test window sets of a config (split by clip)."""
    seqs, body = load_sequences(cfg)
    test_clips = cfg.data.test_clips
    train, test = split_sequences(seqs, test_clips)
    return (
        WindowSet(train, body, cfg.data.history, cfg.data.frame),
        WindowSet(test, body, cfg.data.history, cfg.data.frame),
        body,
    )
