"""The clip catalogue: DeepMimic clips shipped in the installed `pybullet` package.

Clips are addressed by short names (`walk`, `run`, `walker/turn_left0`, ...), by a path to a
user's DeepMimic `.txt` file (such as the clips `charctl data import` writes from any mocap skeleton)
or a charctl `.bvh` file, and any of them with the suffix `:mirror` for
the left/right mirrored copy (e.g. `kick:mirror` is a left kick). Nothing is downloaded: the
files are read from `pybullet_data` at run time.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from pathlib import Path

from charctl.errors import CharctlError
from charctl.motion.clip import Clip
from charctl.motion.skeleton import pybullet_data_path


@dataclass(frozen=True)
class ClipEntry:
    name: str
    file: str  # relative to pybullet_data/data/motions
    label: str  # motion class (for evaluation and conditioning)


# name -> (file, class label). The humanoid3d clips keep DeepMimic's names; the walker clips
# (short turns and a forward walk) are prefixed with "walker/".
_CATALOGUE = {
    "backflip": ("humanoid3d_backflip.txt", "backflip"),
    "cartwheel": ("humanoid3d_cartwheel.txt", "cartwheel"),
    "crawl": ("humanoid3d_crawl.txt", "crawl"),
    "dance_a": ("humanoid3d_dance_a.txt", "dance"),
    "dance_b": ("humanoid3d_dance_b.txt", "dance"),
    "getup_facedown": ("humanoid3d_getup_facedown.txt", "getup"),
    "getup_faceup": ("humanoid3d_getup_faceup.txt", "getup"),
    "jump": ("humanoid3d_jump.txt", "jump"),
    "kick": ("humanoid3d_kick.txt", "kick"),
    "punch": ("humanoid3d_punch.txt", "punch"),
    "roll": ("humanoid3d_roll.txt", "roll"),
    "run": ("humanoid3d_run.txt", "run"),
    "spin": ("humanoid3d_spin.txt", "spin"),
    "spinkick": ("humanoid3d_spinkick.txt", "spinkick"),
    "walk": ("humanoid3d_walk.txt", "walk"),
    "walker/walk_forward": ("walker/0walk_forward.txt", "walk"),
    "walker/turn_left0": ("walker/turn_left0.txt", "turn"),
    "walker/turn_left1": ("walker/turn_left1.txt", "turn"),
    "walker/turn_right0": ("walker/turn_right0.txt", "turn"),
    "walker/turn_right1": ("walker/turn_right1.txt", "turn"),
}
MIRROR_SUFFIX = ":mirror"


def motions_dir() -> Path:
    return pybullet_data_path() / "data" / "motions"


def catalogue() -> list[ClipEntry]:
    """Every shipped humanoid clip, in name order."""
    return [ClipEntry(n, f, l) for n, (f, l) in sorted(_CATALOGUE.items())]


def clip_names() -> list[str]:
    return sorted(_CATALOGUE)


def load_clip(spec: str) -> Clip:
    """Load a clip by catalogue name or file path; a `:mirror` suffix mirrors it.

    Raises a one-line `CharctlError` for an unknown name (with close matches) or a bad file.
    """
    mirror = spec.endswith(MIRROR_SUFFIX)
    base = spec[: -len(MIRROR_SUFFIX)] if mirror else spec
    clip = _load_base(base)
    return clip.mirror() if mirror else clip


def canonical_name(spec: str) -> str:
    """The catalogue name of `spec`, accepting DeepMimic's own file stems as aliases:
    `humanoid3d_walk` (or `humanoid3d_walk.txt`) -> `walk`, `walker/0walk_forward` -> `walker/walk_forward`."""
    if spec in _CATALOGUE:
        return spec
    stem = spec[: -len(".txt")] if spec.endswith(".txt") else spec
    for name, (file, _) in _CATALOGUE.items():
        if stem == file[: -len(".txt")]:
            return name
    return spec


def _load_base(spec: str) -> Clip:
    from charctl.motion.deepmimic import read_deepmimic

    if spec.startswith("~"):
        spec = str(Path(spec).expanduser())
    if not Path(spec).exists():
        spec = canonical_name(spec)
    if spec in _CATALOGUE:
        file, label = _CATALOGUE[spec]
        return read_deepmimic(motions_dir() / file, name=spec, label=label)
    path = Path(spec)
    if path.suffix.lower() == ".bvh":
        from charctl.motion.bvh import read_bvh_as_clip

        return read_bvh_as_clip(path)
    if path.suffix or "/" in spec or path.exists():
        from charctl.motion.imported import apply_import_meta

        return apply_import_meta(read_deepmimic(path), path)  # `charctl data import` files: their name and label
    stems = {file[: -len(".txt")]: name for name, (file, _) in _CATALOGUE.items()}
    close = difflib.get_close_matches(spec, clip_names() + list(stems), n=3)
    close = list(dict.fromkeys(stems.get(c, c) for c in close))
    hint = f" (did you mean {', '.join(close)}?)" if close else ""
    raise CharctlError(f"unknown clip {spec!r}{hint}; known clips: {', '.join(clip_names())}")
