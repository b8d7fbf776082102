"""com-cnn dataset (paper §3.2): clips at 30 fps, start at the origin facing +z, COM from the paper's
mass table, and every frame cut into (history M_t, COM C_t) -> pose m_t samples.

Pose vector m (D = 6 + 3 J numbers, J = non-root joints; 48 for the DeepMimic humanoid, as in the
paper's 15 x 3 angles + root position):
    [0:3]  root position in the reference frame F (metres)
    [3:6]  root rotation in F as an exponential map (radians)
    [6: ]  the J joints' local rotations as exponential maps (radians), skeleton order
The reference frame F of sample t is the heading frame of the root at frame t (`data.frame=root_t`,
paper §3.2) or at t-1 (`root_prev`): origin = the root's ground projection, y up, rotated about y
so that the character's forward axis points along +z. History, COM and target are all in
This module: pose vectors and the training windows; the body model is body.py, the clips sequences.py.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from charctl.experiments.com_cnn.body import BodyModel
from charctl.experiments.com_cnn.sequences import XZ, Sequence, heading_yaw, load_sequences, split_sequences
from charctl.motion import rotations as R


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
