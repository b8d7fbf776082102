"""`charctl data list|show|import`."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from charctl.errors import CharctlError
from charctl.motion.library import MIRROR_SUFFIX, catalogue, load_clip


def list_clips() -> None:
    table = Table(title="Motion clips (pybullet_data/data/motions)")
    for col, just in [
        ("clip", "left"),
        ("frames", "right"),
        ("fps", "right"),
        ("duration s", "right"),
        ("loop", "left"),
        ("class", "left"),
    ]:
        table.add_column(col, justify=just)
    for e in catalogue():
        c = load_clip(e.name)
        table.add_row(
            e.name, str(c.num_frames), f"{c.fps:.1f}", f"{c.duration:.2f}", "wrap" if c.loop else "none", e.label
        )
    Console().print(table)
    Console().print(
        "Append ':mirror' to any name for the left/right mirrored clip; "
        "a path loads your own DeepMimic .txt or charctl .bvh file; "
        "`charctl data import FILE.bvh` turns a mocap file of any skeleton into such a clip."
    )


def clip_summary(name: str) -> dict:
    """Facts about one clip (metres, seconds, m/s)."""
    c = load_clip(name)
    root = c.root_pos
    travel = np.linalg.norm((root[-1] - root[0])[[0, 2]])
    path = np.sum(np.linalg.norm(np.diff(root[:, [0, 2]], axis=0), axis=1))
    com_y = c.com()[:, 1]
    return {
        "clip": c.name,
        "source": c.source,
        "class": c.label,
        "frames": c.num_frames,
        "fps": round(c.fps, 3),
        "duration_s": round(c.duration, 3),
        "loop": "wrap" if c.loop else "none",
        "root_travel_m": round(float(travel), 3),
        "root_path_length_m": round(float(path), 3),
        "mean_speed_m_s": round(float(path / max(c.duration, 1e-9)), 3),
        "root_height_range_m": [round(float(root[:, 1].min()), 3), round(float(root[:, 1].max()), 3)],
        "com_height_range_m": [round(float(com_y.min()), 3), round(float(com_y.max()), 3)],
        "heading_change_deg": round(float(np.degrees(np.unwrap(c.heading())[-1] - c.heading()[0])), 1),
        **_import_facts(name),
    }


def _import_facts(spec: str) -> dict:
    """The import block of a `charctl data import` clip file (source, map, scale, quality), else {}."""
    from charctl.motion.imported import read_import_meta

    base = spec[: -len(MIRROR_SUFFIX)] if spec.endswith(MIRROR_SUFFIX) else spec
    path = Path(base).expanduser()
    meta = read_import_meta(path) if path.is_file() else None
    if not meta:
        return {}
    q = meta.get("quality") or {}
    facts = {
        "imported_from": meta.get("source", ""),
        "skeleton_map": meta.get("skeleton", ""),
        "source_up_units": f"{meta.get('up', '?')}, {meta.get('units', '?')}",
        "scale": meta.get("scale"),
    }
    if q:
        facts["ee_error_max_cm"] = max((q.get("ee_error_max_cm") or {0: 0}).values())
        facts["foot_sliding_max_cm_per_frame"] = max((q.get("slide_max_cm") or {0: 0}).values())
        facts["ground_penetration_max_cm"] = q.get("penetration_max_cm")
        facts["pd_tracking_error_rad"] = q.get("tracking_error_rad")
        facts["targets_met"] = ", ".join(
            f"{k} {'yes' if v else 'no' if v is False else '-'}" for k, v in q.get("passes", {}).items()
        )
    facts["report"] = meta.get("report", "")
    return facts


def show_clip(name: str) -> None:
    table = Table(title=f"clip {name}", show_header=False)
    table.add_column("key", style="bold")
    table.add_column("value")
    for k, v in clip_summary(name).items():
        table.add_row(k, str(v))
    Console().print(table)


# ---------------------------------------------------------------------------- import
def import_motion(
    file: Path,
    skeleton: str | None = None,
    name: str | None = None,
    output: Path | None = None,
    fps: float | None = None,
    up: str | None = None,
    units: str | None = None,
    start: float | None = None,
    stop: float | None = None,
    label: str | None = None,
    report: bool = True,
    tracking: bool = True,
    ground: bool = True,
) -> Path:
    """`charctl data import`: retarget FILE onto the humanoid, write the clip and its quality report.

    Everything that can be wrong with the input is found before anything is written."""
    from charctl.motion import import_report as rep
    from charctl.motion.imported import write_imported_clip
    from charctl.motion.retarget import retarget
    from charctl.motion.retarget.common import DEFAULT_FPS
    from charctl.options import check_options

    file = Path(file).expanduser()
    if not file.is_file():
        raise CharctlError(f"motion file not found: {file}")
    if file.suffix.lower() != ".bvh":
        raise CharctlError(f"{file}: charctl data import reads BVH files (.bvh), got {file.suffix or 'no suffix'}")
    name = name or file.stem
    if not name or "/" in name or name.endswith(MIRROR_SUFFIX):
        raise CharctlError(f"--name must be a plain name (no '/', not ending in {MIRROR_SUFFIX}), got {name!r}")
    out = Path(output).expanduser() if output else Path("imported") / f"{name}.txt"
    fps = DEFAULT_FPS if fps is None else fps
    check_options({"fps": fps, "output": out})
    if out.suffix.lower() != ".txt":
        raise CharctlError(f"-o/--output {out}: the clip is a DeepMimic motion file; give a name ending in .txt")
    side = [out.with_suffix(s) for s in (".report.md", ".filmstrip.png", ".quality.json")] if report else []
    for p in side:
        check_options({"output": p})

    t0 = time.perf_counter()
    r = retarget(file, skeleton, up, units, fps, start, stop, name=name, label=label or name, ground=ground)
    q = rep.measure(r)
    seconds = time.perf_counter() - t0
    meta = _import_meta(file, r, out, report, ground)
    meta["quality"] = q.as_dict()
    write_imported_clip(r.clip, out, meta)  # first, so the PD tracking check can load it like any clip
    if tracking:
        err, blowups = rep.track(out)
        q.tracking_error_rad, q.tracking_blowups = round(err, 4), int(blowups)
        q.tracking_reference_rad = rep.DEEPMIMIC_TRACKING_MEDIAN
        meta["quality"] = q.as_dict()
        write_imported_clip(r.clip, out, meta)
    if report:
        film = rep.write_filmstrip(r, side[1])
        rep.write_report(r, q, out, side[0], film, seconds)
        rep.write_quality_json(q, side[2])
    _print_import(r, q, out, side, seconds)
    return out


def _import_meta(file: Path, r, out: Path, report: bool, ground: bool) -> dict:
    import hashlib

    src = r.source
    return {
        "source": str(file.resolve()),
        "source_sha256": hashlib.sha256(file.read_bytes()).hexdigest(),
        "skeleton": src.jmap.name,
        "joints": src.jmap.names,
        "up": src.up,
        "units": src.units,
        "unit_m": src.unit_m,
        "scale": round(r.scale, 6),
        "arm_scale": round(r.arm_scale, 6),
        "file_fps": round(src.file_fps, 6),
        "clip_fps": round(r.clip.fps, 6),
        "frames_in_file": src.frames_in_file,
        "dropped_reference_frames": src.dropped_frames,
        "mink_refined_frames": r.refined_frames,
        "ground_fitted": ground,
        "report": str(out.with_suffix(".report.md")) if report else "",
    }


def _print_import(r, q, out: Path, side: list[Path], seconds: float) -> None:
    from charctl.motion import import_report as rep

    src = r.source
    console = Console()
    console.print(
        f"{src.path}: skeleton {src.jmap.name}, up {src.up}, units {src.units}, {src.frames_in_file} frames "
        f"-> {q.frames} frames at {q.fps:g} fps ({q.duration_s:.2f} s), scale {r.scale:.3f}; {seconds:.2f} s"
    )
    table = Table(title=f"import quality: {out}")
    for col in ("measure", "value", "target", "met"):
        table.add_column(col)
    p = q.passes()
    mark = {True: "yes", False: "NO", None: "-"}
    ratio = q.tracking_ratio
    rows = [
        (
            "end-effector error after IK, max cm",
            f"{max(q.ee_error_max_cm.values()):.2f}",
            f"<= {rep.EE_TARGET_CM:g}",
            p["end_effector"],
        ),
        (
            "foot sliding in contact, max cm/frame",
            f"{max(q.slide_max_cm.values()):.3f}",
            f"<= {rep.SLIDE_TARGET_CM:g}",
            p["foot_sliding"],
        ),
        (
            "ground penetration, max cm",
            f"{q.penetration_max_cm:.2f}",
            f"<= {rep.PENETRATION_TARGET_CM:g}",
            p["ground_penetration"],
        ),
        ("joint-limit violations, frames", str(q.limit_violation_frames), "0", p["joint_limits"]),
        (
            "PD tracking error rad (x DeepMimic median)",
            "-" if q.tracking_error_rad is None else f"{q.tracking_error_rad:.4f} ({ratio:.2f}x)",
            f"<= {rep.TRACKING_RATIO_TARGET:g}x",
            p["pd_tracking"],
        ),
    ]
    for m, v, t, ok in rows:
        table.add_row(m, v, t, mark[ok])
    console.print(table)
    for path in [out, *side]:
        console.print(f"wrote {path}")
    missed = [k for k, v in p.items() if v is False]
    if missed:
        console.print(f"note: target(s) not met: {', '.join(missed)} (see {side[0] if side else out})")
    console.print(
        f"use it as a clip: charctl data show {out}   |   skills=[{{name: {r.clip.name}, clip: {out.resolve()}}}]"
    )
