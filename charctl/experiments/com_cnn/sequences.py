"""com-cnn's clips as sequences (paper §3.2): DeepMimic clips or a user BVH folder at 30 fps, looped and
blended, started at the origin facing +z, with their COM path; the train/test split and motion types."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.experiments.com_cnn.body import BodyModel, humanoid_body, map_masses
from charctl.motion import rotations as R
from charctl.motion.skeleton import Skeleton

XZ = np.array([1.0, 0.0, 1.0])


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
    return R.twist_angle(root_rot, 1) + np.arctan2(forward[0], forward[2])


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

    root, files = bvh_files(cfg)
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
        name = bvh_clip_name(rel)
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


def bvh_files(cfg) -> tuple[Path, list[Path]]:
    """`data.bvh_dir` and every .bvh under it (sorted); one-line errors for a folder that is none or holds none."""
    root = Path(cfg.data.bvh_dir).expanduser()
    if not root.is_dir():
        raise CharctlError(f"data.bvh_dir: {root} is not a folder")
    files = sorted(root.rglob("*.bvh"))
    if not files:
        raise CharctlError(f"data.bvh_dir: no .bvh files in {root}")
    return root, files


def bvh_clip_name(rel: Path) -> str:
    """The clip (and split unit) name of a BVH file at `rel` under data.bvh_dir: its path without the suffix."""
    return str(rel.with_suffix(""))


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
    check_split([s.base for s in seqs], test_clips)
    test_set = set(test_clips)
    return [s for s in seqs if s.base not in test_set], [s for s in seqs if s.base in test_set]


def check_split(bases, test_clips) -> None:
    """One-line errors for `data.test_clips` naming a clip that is not among `bases` (the split units), or all."""
    test_set = set(test_clips)
    known = set(bases)
    missing = sorted(test_set - known)
    if missing:
        raise CharctlError(
            f"data.test_clips {missing} are not among the clips "
            f"({', '.join(sorted(known)[:8])}, ...); set data.test_clips=[...]"
        )
    if not known - test_set:
        raise CharctlError("data.test_clips holds every clip: nothing left to train on")


def preflight(cfg) -> None:
    """`charctl train`'s checks before the run directory is made, without building a sequence (`train` loads
    the clips again): every DeepMimic clip loads; a BVH folder holds .bvh files, the first one's skeleton
    matches the mass table (com.bvh_joints) and data.test_clips names its clips. What only reading every BVH
    file finds (a second skeleton, a file of fewer than 2 frames) stays `train`'s."""
    from charctl.motion.library import load_clip

    if not cfg.data.bvh_dir:
        for name in cfg.data.clips:
            load_clip(name)
        return
    from charctl.motion.bvh import read_bvh

    root, files = bvh_files(cfg)
    bvh_body(read_bvh(files[0]), files[0], cfg)
    check_split([bvh_clip_name(f.relative_to(root)) for f in files], cfg.data.test_clips)


def motion_type(label: str, motion_types: dict) -> str:
    """The paper's motion type (walk / crouch_walk / other) of a class label (eval.motion_types)."""
    for kind, labels in motion_types.items():
        if label in labels:
            return str(kind)
    return "other"
