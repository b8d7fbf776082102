"""The DeepMimic humanoid3d skeleton, read from pybullet's `humanoid.urdf` at run time.

Frames: world is y-up, the character faces +x in its rest pose and its right side is +z
(DeepMimic's convention). Lengths in metres: the URDF stores them 4x (pybullet loads it with
globalScaling 0.25), so every length read from it is multiplied by `URDF_SCALE`.

Bodies (15) in DeepMimic order; each body's frame sits at the joint that connects it to its
parent. Rotations of the 12 movable joints are stored in clips in `CLIP_JOINTS` order.
"""

from __future__ import annotations

import functools
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError

URDF_SCALE = 0.25

BODY_NAMES: tuple[str, ...] = (
    "root",
    "chest",
    "neck",
    "right_hip",
    "right_knee",
    "right_ankle",
    "right_shoulder",
    "right_elbow",
    "right_wrist",
    "left_hip",
    "left_knee",
    "left_ankle",
    "left_shoulder",
    "left_elbow",
    "left_wrist",
)
# Movable joints in the order of a DeepMimic frame (after dt, root position, root rotation).
CLIP_JOINTS: tuple[str, ...] = (
    "chest",
    "neck",
    "right_hip",
    "right_knee",
    "right_ankle",
    "right_shoulder",
    "right_elbow",
    "left_hip",
    "left_knee",
    "left_ankle",
    "left_shoulder",
    "left_elbow",
)
HINGE_JOINTS: frozenset[str] = frozenset({"right_knee", "right_elbow", "left_knee", "left_elbow"})
END_EFFECTORS: tuple[str, ...] = ("right_ankle", "left_ankle", "right_wrist", "left_wrist")
FEET: tuple[str, ...] = ("right_ankle", "left_ankle")

# Masses (kg) the foundation issue fixes; they equal the URDF's (total 45 kg).
BODY_MASS: dict[str, float] = {
    "root": 6.0,
    "chest": 14.0,
    "neck": 2.0,
    "right_hip": 4.5,
    "right_knee": 3.0,
    "right_ankle": 1.0,
    "right_shoulder": 1.5,
    "right_elbow": 1.0,
    "right_wrist": 0.5,
    "left_hip": 4.5,
    "left_knee": 3.0,
    "left_ankle": 1.0,
    "left_shoulder": 1.5,
    "left_elbow": 1.0,
    "left_wrist": 0.5,
}


def mirror_name(name: str) -> str:
    """right_x <-> left_x; other names unchanged."""
    if name.startswith("right_"):
        return "left_" + name[6:]
    if name.startswith("left_"):
        return "right_" + name[5:]
    return name


@dataclass(frozen=True)
class Geom:
    """A collision shape in its body's frame. size: sphere (r,), capsule (r, half-length), box half-extents."""

    kind: str
    size: tuple[float, ...]
    pos: tuple[float, float, float]
    axis_y: bool = False  # capsules in this model lie along the body's y axis


@dataclass(frozen=True)
class Skeleton:
    """Kinematic tree of the humanoid. Arrays are indexed in `names` order; units metres/kg."""

    names: tuple[str, ...]
    parents: np.ndarray  # (B,) int, -1 for the root
    offsets: np.ndarray  # (B, 3) joint position in the parent body frame
    masses: np.ndarray  # (B,) kg
    com_local: np.ndarray  # (B, 3) body centre of mass in the body frame
    geoms: tuple[Geom, ...] = field(default_factory=tuple)  # one per body
    source: str = ""

    @property
    def num_bodies(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        return self.names.index(name)

    @functools.cached_property
    def depth_levels(self) -> list[np.ndarray]:
        """Body indices grouped by tree depth (root first), for level-wise vectorised FK."""
        depth = np.zeros(self.num_bodies, dtype=int)
        for b in range(1, self.num_bodies):  # parents precede children in `names`
            depth[b] = depth[self.parents[b]] + 1
        return [np.flatnonzero(depth == d) for d in range(depth.max() + 1)]

    @functools.cached_property
    def dfs_order(self) -> tuple[int, ...]:
        """Body indices in depth-first order (children in index order), as MJCF/BVH nest them."""
        children: dict[int, list[int]] = {b: [] for b in range(self.num_bodies)}
        for b in range(1, self.num_bodies):
            children[int(self.parents[b])].append(b)
        out: list[int] = []
        stack = [0]
        while stack:
            b = stack.pop()
            out.append(b)
            stack.extend(reversed(children[b]))
        return tuple(out)

    @functools.cached_property
    def clip_joint_bodies(self) -> np.ndarray:
        """Body index of each of the 12 clip joints."""
        return np.array([self.index(n) for n in CLIP_JOINTS])

    @functools.cached_property
    def mirror_perm(self) -> np.ndarray:
        """Body permutation that swaps left and right."""
        return np.array([self.index(mirror_name(n)) for n in self.names])


# A folder laid out like pybullet_data's clip files (data/motions/..., humanoid/humanoid.urdf), read
# instead of pybullet_data when set: for a machine without pybullet, e.g. an offline GPU node (docs/gpu.md).
CLIP_DIR_ENV = "CHARCTL_CLIP_DIR"


def pybullet_data_path() -> Path:
    """Folder of the clips and URDFs: $CHARCTL_CLIP_DIR when set, else the installed `pybullet_data` package."""
    given = os.environ.get(CLIP_DIR_ENV)
    if given:
        path = Path(given).expanduser()
        if not (path / "humanoid" / "humanoid.urdf").is_file():
            raise CharctlError(
                f"{CLIP_DIR_ENV}={given} has no humanoid/humanoid.urdf: point it at a copy of pybullet_data's "
                "clip files (scripts/node_bundle.py clips DIR; docs/gpu.md)"
            )
        return path
    try:
        import pybullet_data
    except ImportError as exc:
        raise CharctlError(
            f"the 'pybullet' package is not installed: run `make install`, or set {CLIP_DIR_ENV} to a copy of "
            "its clip files (docs/gpu.md)"
        ) from exc
    return Path(pybullet_data.getDataPath())


def humanoid_urdf_path() -> Path:
    return pybullet_data_path() / "humanoid" / "humanoid.urdf"


def _floats(text: str | None) -> np.ndarray:
    return np.array([float(x) for x in (text or "0 0 0").split()])


@functools.lru_cache(maxsize=4)
def load_skeleton(urdf: str | None = None) -> Skeleton:
    """Parse the DeepMimic humanoid URDF (default: pybullet's) into a `Skeleton` in metres."""
    path = Path(urdf) if urdf else humanoid_urdf_path()
    try:
        text = path.read_bytes().replace(b"\x00", b"").decode()  # the file ends in a NUL byte
        root = ET.fromstring(text)
    except (OSError, ET.ParseError) as exc:
        raise CharctlError(f"cannot read humanoid URDF {path}: {exc}") from exc
    links = {l.get("name"): l for l in root.findall("link")}
    joints = {j.find("child").get("link"): j for j in root.findall("joint")}
    parents, offsets, com, geoms = [], [], [], []
    for name in BODY_NAMES:
        link = links[name]
        joint = joints[name]
        parent = joint.find("parent").get("link")
        parents.append(-1 if parent == "base" else BODY_NAMES.index(parent))
        offsets.append(_floats(joint.find("origin").get("xyz")) * URDF_SCALE)
        com.append(_floats(link.find("inertial/origin").get("xyz")) * URDF_SCALE)
        col = link.find("collision")
        gpos = tuple(_floats(col.find("origin").get("xyz")) * URDF_SCALE)
        g = col.find("geometry")[0]
        if g.tag == "sphere":
            geoms.append(Geom("sphere", (float(g.get("radius")) * URDF_SCALE,), gpos))
        elif g.tag == "capsule":
            r = float(g.get("radius")) * URDF_SCALE
            half = 0.5 * float(g.get("length")) * URDF_SCALE
            geoms.append(Geom("capsule", (r, half), gpos, axis_y=True))
        elif g.tag == "box":
            half = tuple(0.5 * _floats(g.get("size")) * URDF_SCALE)
            geoms.append(Geom("box", half, gpos))
        else:  # pragma: no cover - the shipped URDF has only these
            raise CharctlError(f"{path}: unsupported collision geometry {g.tag!r} on {name}")
    return Skeleton(
        names=BODY_NAMES,
        parents=np.array(parents),
        offsets=np.array(offsets),
        masses=np.array([BODY_MASS[n] for n in BODY_NAMES]),
        com_local=np.array(com),
        geoms=tuple(geoms),
        source=str(path),
    )
