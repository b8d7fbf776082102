"""Clip files written by `charctl data import`: DeepMimic motion files with one more key.

The file is a plain DeepMimic motion file ({"Loop", "Frames"}, 44 numbers a frame; DeepMimic itself
and every charctl loader read it) plus `"charctl_import"`: the clip's name and class label, the source
file and its skeleton map, the scale, and the quality numbers of the import report. The clip library
(charctl.motion.library) applies the name and label when a path to such a file is used as a clip.
Light on purpose: no simulator import.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from charctl.errors import CharctlError
from charctl.motion.clip import Clip

IMPORT_KEY = "charctl_import"


def write_imported_clip(clip: Clip, path: str | Path, meta: dict) -> Path:
    """Write `clip` as a DeepMimic motion file carrying `meta` (atomically: temp file, then rename)."""
    from charctl.motion.deepmimic import encode_frames

    path = Path(path)
    frames = encode_frames(clip)
    body = {
        "Loop": "wrap" if clip.loop else "none",
        "Frames": frames.round(9).tolist(),
        IMPORT_KEY: {"name": clip.name, "label": clip.label, **meta},
    }
    tmp = path.with_name(path.name + ".tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text(json.dumps(body, indent=1, allow_nan=False))
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise CharctlError(f"cannot write {path}: {exc.strerror or exc}") from exc
    return path


def read_import_meta(path: str | Path) -> dict | None:
    """The `charctl_import` block of a clip file, or None (not an imported clip, or unreadable)."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    meta = data.get(IMPORT_KEY) if isinstance(data, dict) else None
    return meta if isinstance(meta, dict) else None


def apply_import_meta(clip: Clip, path: str | Path) -> Clip:
    """`clip` (read from `path`) with the name and label its import block gives, if any."""
    meta = read_import_meta(path)
    if not meta:
        return clip
    return clip.replace(name=str(meta.get("name") or clip.name), label=str(meta.get("label") or clip.label))
