"""Joint maps from motion-capture skeletons onto the humanoid's 15 bodies (`charctl data import`).

A map names, for every humanoid body, the source joint whose frame it follows: `root` the pelvis,
`chest` the top of the spine (its rotation carries the whole spine's bend), `neck` the head joint,
`*_hip` / `*_knee` / `*_ankle` the thigh, shin and foot joints (at hip, knee and ankle), `*_shoulder`
/ `*_elbow` / `*_wrist` the upper-arm, forearm and hand joints (at shoulder, elbow and wrist).
Three optional entries improve the fit: `*_toe` (the toe joint; else the foot's End Site gives the
toe direction), `neck_base` (the joint at the base of the neck; else the head joint) and `head_top`
(a joint above the head; else the head's End Site).

Built-in maps cover the common conventions; each lists candidates per body (the first joint the
file has wins) and a signature (joints that tell the convention apart). A user map is a YAML file
of `body: joint` lines, optionally with `up: y|z` and `units: m|cm|mm|in|cmu` (docs/motion_import.md).
Joint names are compared without a namespace prefix (`mixamorig:Hips` is `Hips`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from charctl.errors import CharctlError
from charctl.motion.skeleton import BODY_NAMES

OPTIONAL = ("right_toe", "left_toe", "neck_base", "head_top")
MAP_KEYS = (*BODY_NAMES, *OPTIONAL)
# keys a map file may set besides the joints
SETTINGS = ("up", "units")


def _sides(right: dict[str, list[str]]) -> dict[str, list[str]]:
    """Both sides from the right side's candidates ('Right'/'right_'/'R_'/'_R'/'r' mirrored)."""
    out: dict[str, list[str]] = {}
    swaps = [("Right", "Left"), ("right", "left"), ("R_", "L_"), ("_R", "_L"), (".R", ".L")]
    for key, names in right.items():
        out[key] = names
        left = []
        for n in names:
            for a, b in swaps:
                if a in n:
                    n = n.replace(a, b)
                    break
            else:
                if n.startswith("r") and n[1:2].isupper():  # Daz/Poser: rThigh -> lThigh
                    n = "l" + n[1:]
            left.append(n)
        out[key.replace("right_", "left_")] = left
    return out


@dataclass(frozen=True)
class BuiltinMap:
    name: str
    description: str
    signature: tuple[str, ...]  # all must be present for detection
    joints: dict[str, list[str]] = field(default_factory=dict)  # body -> candidate joint names


def _map(name: str, description: str, signature: tuple[str, ...], centre: dict, right: dict) -> BuiltinMap:
    return BuiltinMap(name, description, signature, {**centre, **_sides(right)})


BUILTIN_MAPS: dict[str, BuiltinMap] = {
    m.name: m
    for m in [
        BuiltinMap(
            "charctl",
            "the humanoid's own joint names (charctl export bvh, DeepMimic bodies)",
            ("root", "right_hip", "left_knee", "right_wrist"),
            {b: [b] for b in BODY_NAMES},
        ),
        _map(
            "cmu",
            "CMU mocap, MotionBuilder-friendly BVH conversion (cgspeed): LHipJoint, LowerBack, Neck1",
            ("LHipJoint", "LowerBack", "LeftUpLeg", "LeftForeArm"),
            {"root": ["Hips"], "chest": ["Spine1", "Spine"], "neck": ["Head"], "neck_base": ["Neck"]},
            {
                "right_hip": ["RightUpLeg"],
                "right_knee": ["RightLeg"],
                "right_ankle": ["RightFoot"],
                "right_toe": ["RightToeBase"],
                "right_shoulder": ["RightArm"],
                "right_elbow": ["RightForeArm"],
                "right_wrist": ["RightHand"],
            },
        ),
        _map(
            "neuron",
            "Perception Neuron / Axis Neuron: Spine..Spine3, six channels on every joint",
            ("Spine3", "LeftUpLeg", "LeftForeArm"),
            {"root": ["Hips"], "chest": ["Spine3", "Spine2"], "neck": ["Head"], "neck_base": ["Neck"]},
            {
                "right_hip": ["RightUpLeg"],
                "right_knee": ["RightLeg"],
                "right_ankle": ["RightFoot"],
                "right_toe": ["RightToeBase", "RightToe"],
                "right_shoulder": ["RightArm"],
                "right_elbow": ["RightForeArm"],
                "right_wrist": ["RightHand"],
            },
        ),
        _map(
            "lafan1",
            "Ubisoft LAFAN1: Hips, Spine..Spine2, LeftToe",
            ("LeftUpLeg", "LeftToe", "Spine2", "LeftForeArm"),
            {"root": ["Hips"], "chest": ["Spine2", "Spine1"], "neck": ["Head"], "neck_base": ["Neck"]},
            {
                "right_hip": ["RightUpLeg"],
                "right_knee": ["RightLeg"],
                "right_ankle": ["RightFoot"],
                "right_toe": ["RightToe"],
                "right_shoulder": ["RightArm"],
                "right_elbow": ["RightForeArm"],
                "right_wrist": ["RightHand"],
            },
        ),
        _map(
            "mixamo",
            "Mixamo rig (mixamorig:Hips, Spine..Spine2, LeftToeBase) and rigs named like it",
            ("LeftUpLeg", "LeftForeArm", "Spine"),
            {
                "root": ["Hips"],
                "chest": ["Spine2", "Spine1", "Spine"],
                "neck": ["Head"],
                "neck_base": ["Neck"],
                "head_top": ["HeadTop_End"],
            },
            {
                "right_hip": ["RightUpLeg"],
                "right_knee": ["RightLeg"],
                "right_ankle": ["RightFoot"],
                "right_toe": ["RightToeBase", "RightToe"],
                "right_shoulder": ["RightArm"],
                "right_elbow": ["RightForeArm"],
                "right_wrist": ["RightHand"],
            },
        ),
        _map(
            "biovision",
            "Biovision naming: CMU 3dsMax-friendly conversion, OptiTrack Arena (LeftHip, LeftShoulder = upper arm)",
            ("LeftHip", "LeftKnee", "LeftAnkle", "LeftElbow", "LeftWrist"),
            {
                "root": ["Hips", "Hip"],
                "chest": ["Chest4", "Chest3", "Chest2", "Chest"],
                "neck": ["Head"],
                "neck_base": ["lowerneck", "Neck"],
            },
            {
                "right_hip": ["RightHip"],
                "right_knee": ["RightKnee"],
                "right_ankle": ["RightAnkle"],
                "right_toe": ["RightToe"],
                "right_shoulder": ["RightShoulder"],
                "right_elbow": ["RightElbow"],
                "right_wrist": ["RightWrist"],
            },
        ),
        _map(
            "unity",
            "Unity-humanoid naming with side suffixes (Bandai-Namco motion dataset): UpperLeg_L, LowerArm_R",
            ("UpperLeg_L", "LowerLeg_L", "UpperArm_L", "LowerArm_L"),
            {
                "root": ["Hips"],
                "chest": ["UpperChest", "Chest", "Spine"],
                "neck": ["Head"],
                "neck_base": ["Neck"],
            },
            {
                "right_hip": ["UpperLeg_R"],
                "right_knee": ["LowerLeg_R"],
                "right_ankle": ["Foot_R"],
                "right_toe": ["Toes_R"],
                "right_shoulder": ["UpperArm_R"],
                "right_elbow": ["LowerArm_R"],
                "right_wrist": ["Hand_R"],
            },
        ),
        _map(
            "daz",
            "Daz/Poser naming (CMU Daz-friendly conversion): hip, abdomen, chest, lThigh, lShin, lShldr",
            ("lThigh", "lShin", "lShldr", "lForeArm"),
            {"root": ["hip"], "chest": ["chest", "abdomen"], "neck": ["head"], "neck_base": ["neck"]},
            {
                "right_hip": ["rThigh"],
                "right_knee": ["rShin"],
                "right_ankle": ["rFoot"],
                "right_toe": ["rToe"],
                "right_shoulder": ["rShldr"],
                "right_elbow": ["rForeArm"],
                "right_wrist": ["rHand"],
            },
        ),
        _map(
            "smpl",
            "SMPL joint names (AMASS/SMPL exports): Pelvis, L_Hip, L_Knee, Spine3, L_Shoulder",
            ("Pelvis", "L_Hip", "L_Knee", "L_Elbow"),
            {"root": ["Pelvis"], "chest": ["Spine3", "Spine2"], "neck": ["Head"], "neck_base": ["Neck"]},
            {
                "right_hip": ["R_Hip"],
                "right_knee": ["R_Knee"],
                "right_ankle": ["R_Ankle"],
                "right_toe": ["R_Foot"],
                "right_shoulder": ["R_Shoulder"],
                "right_elbow": ["R_Elbow"],
                "right_wrist": ["R_Wrist"],
            },
        ),
    ]
}


@dataclass(frozen=True)
class JointMap:
    """A resolved map: humanoid body (and optional key) -> joint index in the source file."""

    name: str  # built-in map name or the map file's path
    joints: dict[str, int]  # every body of BODY_NAMES, plus the optional keys the file has
    names: dict[str, str]  # the same keys -> the joint names as written in the file
    settings: dict[str, str] = field(default_factory=dict)  # up / units from a map file

    def get(self, key: str) -> int | None:
        return self.joints.get(key)


def bare(name: str) -> str:
    """A joint name without a namespace prefix (`mixamorig:Hips` -> `Hips`, `m_avg_Pelvis` -> `Pelvis`)."""
    name = name.rsplit(":", 1)[-1]
    return name[len("m_avg_") :] if name.startswith("m_avg_") else name


def _index(names: list[str]) -> dict[str, int]:
    out: dict[str, int] = {}
    for i, n in enumerate(names):
        out.setdefault(n, i)
        out.setdefault(bare(n), i)
    return out


def _resolve_builtin(m: BuiltinMap, names: list[str]) -> tuple[dict[str, int], list[str]]:
    """(joints found, required bodies missing) of built-in map `m` on the file's joint names."""
    index = _index(names)
    found: dict[str, int] = {}
    missing = []
    for key, candidates in m.joints.items():
        hit = next((index[c] for c in candidates if c in index), None)
        if hit is not None:
            found[key] = hit
        elif key in BODY_NAMES:
            missing.append(key)
    return found, missing


def detect_map(names: list[str], source: str = "") -> str:
    """The built-in map whose signature and required joints the file's joint names have."""
    index = _index(names)
    for m in BUILTIN_MAPS.values():
        if all(s in index for s in m.signature) and not _resolve_builtin(m, names)[1]:
            return m.name
    shown = ", ".join(names[:12]) + (", ..." if len(names) > 12 else "")
    raise CharctlError(
        f"{source}: cannot tell the skeleton convention from its joint names ({shown}); give --skeleton "
        f"{'|'.join(BUILTIN_MAPS)} or --skeleton MAP.yaml (docs/motion_import.md)"
    )


def resolve_map(names: list[str], skeleton: str | None, source: str = "") -> JointMap:
    """Resolve `skeleton` (None = detect, a built-in name, or a YAML map path) on the file's joints."""
    if skeleton is None:
        skeleton = detect_map(names, source)
    if skeleton in BUILTIN_MAPS:
        m = BUILTIN_MAPS[skeleton]
        found, missing = _resolve_builtin(m, names)
        if missing:
            want = [m.joints[k][0] for k in missing]
            raise CharctlError(
                f"{source}: --skeleton {skeleton}: the file has no joint {want[0]!r} ({missing[0]})"
                + (f" nor {', '.join(repr(w) for w in want[1:4])}" if len(want) > 1 else "")
                + "; give --skeleton MAP.yaml to name the joints (docs/motion_import.md)"
            )
        _check_distinct(found, names, skeleton, source)
        return JointMap(skeleton, found, {k: names[v] for k, v in found.items()})
    path = Path(skeleton).expanduser()
    if path.suffix.lower() not in (".yaml", ".yml") and not path.exists():
        raise CharctlError(f"unknown skeleton {skeleton!r}: give one of {', '.join(BUILTIN_MAPS)} or a MAP.yaml file")
    return _resolve_file(path, names, source)


def _resolve_file(path: Path, names: list[str], source: str) -> JointMap:
    from omegaconf import OmegaConf

    if not path.is_file():
        raise CharctlError(f"skeleton map not found: {path}")
    try:
        raw = OmegaConf.to_container(OmegaConf.load(path))
    except Exception as exc:  # noqa: BLE001 - any YAML problem is the user's file
        raise CharctlError(f"{path}: not a YAML map ({str(exc).splitlines()[0]})") from exc
    if not isinstance(raw, dict):
        raise CharctlError(f"{path}: a skeleton map is a YAML mapping of 'body: joint' lines")
    unknown = [k for k in raw if k not in MAP_KEYS and k not in SETTINGS]
    if unknown:
        raise CharctlError(
            f"{path}: unknown key {unknown[0]!r}; keys are the humanoid bodies ({', '.join(BODY_NAMES)}), "
            f"optional {', '.join(OPTIONAL)}, and {', '.join(SETTINGS)}"
        )
    missing = [b for b in BODY_NAMES if b not in raw]
    if missing:
        raise CharctlError(f"{path}: the map names no joint for {', '.join(missing)}")
    index = _index(names)
    found: dict[str, int] = {}
    for key in MAP_KEYS:
        if key not in raw or raw[key] in (None, ""):
            continue
        joint = str(raw[key])
        if joint not in index:
            shown = ", ".join(names[:10]) + (", ..." if len(names) > 10 else "")
            raise CharctlError(f"{path}: {key}: joint {joint!r} is not in {source} (its joints: {shown})")
        found[key] = index[joint]
    _check_distinct(found, names, str(path), source)
    settings = {k: str(raw[k]) for k in SETTINGS if raw.get(k) not in (None, "")}
    return JointMap(str(path), found, {k: names[v] for k, v in found.items()}, settings)


def _check_distinct(found: dict[str, int], names: list[str], what: str, source: str) -> None:
    seen: dict[int, str] = {}
    for key in BODY_NAMES:
        j = found[key]
        if j in seen:
            raise CharctlError(f"{source}: map {what}: {seen[j]} and {key} both name joint {names[j]!r}")
        seen[j] = key
