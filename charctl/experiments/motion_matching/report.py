"""The reproduction report of a motion-matching sweep folder:

    python -m charctl.experiments.motion_matching.report DIR

DIR holds sweep.json/sweep.md (charctl eval --sweep -o DIR), bench.json (scripts/bench_mm.py
--json) and an export run under DIR/motion-matching/*/metrics.json. Every number in the report
is read from those files; the comparisons with the paper's findings are computed here.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.eval.report import markdown_grid
from charctl.eval.report import write_report as write_report_md

# ---------------------------------------------------------------------------- report.md
PAPER_FRAMES, PAPER_HZ = 8171, 120


def _avg(data: dict, case: int, metric: str = "e_time") -> float:
    return float(data[f"avg_{metric}"][str(case)])


def findings(data: dict) -> list[str]:
    """The paper's Table 1 findings (docs/motion-matching.md) checked against this sweep, one line each."""
    have = {int(c) for c in data["cases"]}
    out = []

    def best_of(cases: list[int]) -> int:
        return min(cases, key=lambda c: _avg(data, c))

    if set(range(1, 8)) <= have:
        b = best_of(list(range(1, 8)))
        out.append(
            f"Cases 1-7 (1..7 samples x 20): best here is {b} sample(s) (mean e_time {_avg(data, b):.3f} m); paper: 5."
        )
    if {8, 9} <= have:
        b = best_of([8, 9])
        out.append(
            f"Same horizon, 4x25 vs 3x33: {'4x25' if b == 8 else '3x33'} is better here "
            f"({_avg(data, 8):.3f} vs {_avg(data, 9):.3f} m); paper: 4x25."
        )
    if {5, 10, 8, 11} <= have:
        w10, w11 = _avg(data, 10) > _avg(data, 5), _avg(data, 11) > _avg(data, 8)
        out.append(
            f"+ past trajectory: 5x20 {_avg(data, 5):.3f} -> {_avg(data, 10):.3f} m, 4x25 {_avg(data, 8):.3f} -> "
            f"{_avg(data, 11):.3f} m ({'worse in both' if w10 and w11 else 'not uniformly worse'}); "
            "paper: always worse."
        )
    if set(range(12, 16)) <= have:
        b = best_of(list(range(12, 16)))
        out.append(
            f"Position:velocity weights (cases 12-15): best here is case {b} "
            f"({data['cases'][str(b)]['description']}); paper: 0.8:0.2."
        )
    if set(range(16, 20)) <= have:
        b = best_of(list(range(16, 20)))
        out.append(
            f"Discount (cases 16-19): best here is case {b} ({data['cases'][str(b)]['description']}); paper: 0.7."
        )
    best = int(data["best_case"])
    out.append(
        f"Best overall here: case {best} ({data['cases'][str(best)]['description']}, mean e_time "
        f"{_avg(data, best):.3f} m, e_near {_avg(data, best, 'e_near'):.3f} m); paper: 4x25 + velocity 0.8:0.2 + γ0.7 "
        f"(case 18: {_avg(data, 18):.3f} m here)."
        if 18 in have
        else f"Best overall here: case {best}."
    )
    return out


def bench_lines(bench: dict) -> list[str]:
    """The benchmark's section of report.md: the query latency table (one row per database), the
    machine it ran on and the runtime's speed."""
    header = ["database", "brute (wall / CPU µs)", "kd-tree", "bounding boxes", "same answers"]
    rows = [_latency_row(label, row) for label, row in bench["latency_us"].items()]
    lines = markdown_grid(header, rows, align="-rrrc").split("\n")
    m = bench.get("machine", {})
    lines += [
        "",
        f"Machine: {m.get('cpus', '?')} CPUs, 1-minute load average {m.get('load_1min', float('nan')):.1f} while "
        "measuring (the CPU column is the thread's own CPU time, which leaves out waiting for a core).",
    ]
    for kind, rt in bench.get("runtime", {}).items():
        lines.append(
            f"Runtime with `{kind}`: {rt['frames']} frames in {rt['seconds']:.2f} s = {rt['frames_per_s']:.0f} "
            f"frames/s = **{rt['realtime_factor']:.0f}x real time** at {bench['fps']:.0f} Hz (search, pose "
            "inertialization, root reconstruction)."
        )
    return lines


def _latency_row(label: str, row: dict) -> list[str]:
    """One database's latency cells (wall / CPU µs per query of each search) and whether all agree."""
    cells = [f"{row[k]['us_per_query']:.1f} / {row[k]['cpu_us_per_query']:.1f}" for k in ("brute", "kdtree", "bbox")]
    same = all(v["same_as_brute"] for v in row.values())
    return [label, *cells, "yes" if same else "NO"]


def source_text(folder: Path) -> str:
    """What the database was built from, read from the sweep's config."""
    from omegaconf import OmegaConf

    data = OmegaConf.load(folder / "config.yaml").data
    if data.bvh_dir:
        return f"the BVH files in {data.bvh_dir}"
    mirror = " and their left/right mirrors" if data.mirror else ""
    return (
        f"one gait cycle (the searchable part of each unrolled loop) of the clips {', '.join(data.clips)}{mirror}; "
        "no starts, stops or transitions between gaits, so every path is followed by stitching steady cycles"
    )


def star_tip_turn(folder: Path) -> float:
    """Largest heading change (degrees) at a corner of the configured star."""
    from omegaconf import OmegaConf

    from charctl.experiments.motion_matching.paths import make_path

    star = make_path("star", OmegaConf.load(folder / "config.yaml").paths)
    d = star.dirs
    ang = np.degrees(np.arccos(np.clip(np.sum(d[1:] * d[:-1], axis=1), -1, 1)))
    return float(ang.max())


def clip_table(folder: Path) -> tuple[list[str], dict]:
    """Speed and turning rate of every clip of the database the sweep used (rebuilt from its config)."""
    from omegaconf import OmegaConf

    from charctl.config import validate
    from charctl.experiments.motion_matching.config import Config
    from charctl.experiments.motion_matching.sources import load_sources

    cfg = validate(OmegaConf.load(folder / "config.yaml"), Config, "motion-matching")
    sources, info = load_sources(cfg)
    cells, stats = [], {}
    for s in sources:
        a, b = s.search_start, s.search_stop
        dist = np.linalg.norm(s.root_pos[b, [0, 2]] - s.root_pos[a, [0, 2]])
        from charctl.experiments.motion_matching.sources import heading_of, wrap_angle

        h = heading_of(s.local_rot[[a, b], 0], info.forward)
        secs = (b - a) / s.fps
        speed, rate = dist / secs, float(np.degrees(wrap_angle(h[1] - h[0]))) / secs
        radius = speed / np.radians(abs(rate)) if abs(rate) > 1.0 else float("inf")
        stats[s.name] = (speed, rate, radius)
        cells.append([s.name, f"{speed:.2f}", f"{rate:+.0f}", f"{radius:.1f}"])
    header = ["clip", "speed (m/s)", "turn rate (deg/s)", "turn radius (m)"]
    return markdown_grid(header, cells, align="-rrr").split("\n"), stats


def limits(data: dict, folder: Path) -> list[str]:
    """How the small database shows in the results, from the sweep and the database itself."""
    frames = int(data["database_frames"])
    out = []
    try:
        rows, stats = clip_table(folder)
    except Exception as exc:  # the report is still useful without the clip table
        rows, stats = [f"(clip table unavailable: {str(exc).splitlines()[0][:100]})"], {}
    if stats:
        tightest = min(r for _, _, r in stats.values())
        out += [
            f"- The {frames} searchable frames ({PAPER_FRAMES / frames:.1f}x fewer than the paper's "
            f"{PAPER_FRAMES}) are {len(stats)} steady gait cycles of "
            f"~{frames / len(stats) / data['database_fps']:.1f} s each. They offer only "
            "these speeds and turning rates (one cycle, start to end); the paths must be followed by stitching them:",
            "",
            *rows,
            "",
        ]
        paths = data["paths"]
        if "star" in paths:
            worst = sum(
                max(paths, key=lambda p: c["paths"][p]["e_near_mean"]) == "star" for c in data["cases"].values()
            )
            out.append(
                f"- The tightest turn in the data has a radius of {tightest:.1f} m and the star's tips turn by "
                f"{star_tip_turn(folder):.0f}° at a point, so the tips are always rounded off: the star has the "
                f"largest e_near in {worst} of {len(data['cases'])} cases."
            )
    searches = sum(p["searches"] for c in data["cases"].values() for p in c["paths"].values())
    jumps = sum(p["jumps"] for c in data["cases"].values() for p in c["paths"].values())
    out.append(
        f"- {jumps} of {searches} searches in the sweep ended in a jump to another frame: the paper's setting "
        "never lets the k = 20 frames around the current one be chosen, so the pose blending hides a "
        "transition at every search (runtime.continue_if_best=true lets the current frame win instead; "
        "docs/motion-matching.md compares the two)."
    )
    best17 = (
        min(range(1, 8), key=lambda c: _avg(data, c)) if all(str(c) in data["cases"] for c in range(1, 8)) else None
    )
    if best17 is not None and best17 > 5:
        out.append(
            f"- A longer horizon helps more here than in the paper ({best17} samples vs the paper's 5): without "
            "transition motions the character has to commit to a turn early, and a short horizon sees the "
            "corner too late."
        )
    if all(str(c) in data["cases"] for c in (1, 2)) and _avg(data, 1) > 3 * _avg(data, 2):
        out.append(
            f"- A single sample 20 frames ahead (case 1, mean e_time {_avg(data, 1):.2f} m) loses the path "
            "(plots/case_01.png): 0.17 s of future barely separates the steady cycles, so (we think) the 15 "
            "pose dimensions dominate the match."
        )
    out.append(
        f"- Single rollouts are chaotic (a 2 % change of the target speed moves a case's mean error by "
        f"~0.05 m), so each path is run from {data.get('starts', 1)} start phase(s) and the errors pooled; "
        "differences of a few centimetres between cases are still within that noise."
    )
    return out


def write_report(folder: Path) -> Path:
    folder = Path(folder)
    sweep = folder / "sweep.json"
    if not sweep.is_file():
        raise CharctlError(f"{sweep} not found: run `charctl eval motion-matching --sweep -o {folder}` first")
    data = json.loads(sweep.read_text())
    frames = int(data["database_frames"])
    lines = [
        "# motion-matching: reproduction report",
        "",
        "Feature-vector motion matching following circle / square / star paths and the paper's Table 1 "
        "feature study (method, details and decisions in docs/motion-matching.md).",
        "",
        "## Data",
        "",
        f"Searchable database: **{frames} frames at {data['database_fps']:.0f} Hz** "
        f"({frames / data['database_fps']:.1f} s) — the paper used {PAPER_FRAMES} frames at {PAPER_HZ} Hz "
        f"({PAPER_FRAMES / PAPER_HZ:.0f} s), {PAPER_FRAMES / frames:.1f}x more. Source: {source_text(folder)}.",
        "",
        "## Table 1 sweep",
        "",
        (folder / "sweep.md").read_text().strip(),
        "",
        "![best case](best.png)",
        "",
        "## Against the paper's findings",
        "",
        *[f"- {x}" for x in findings(data)],
        "",
    ]
    runs = sorted((folder / "motion-matching").glob("*/metrics.json"))
    if runs:
        m = json.loads(runs[-1].read_text())
        rel = runs[-1].parent.relative_to(folder)
        lines += [
            "## Export (path=star, best case)",
            "",
            f"{m['setting']}: {m['frames']} frames, e_time {m['e_time_mean']:.3f} ± {m['e_time_std']:.3f} m, "
            f"e_near {m['e_near_mean']:.3f} ± {m['e_near_std']:.3f} m, {m['jumps']} transitions in "
            f"{m['searches']} searches. Files: `star_best.bvh`, `star_best.mp4`, `{rel}/path.png`.",
            "",
        ]
    bench = folder / "bench.json"
    if bench.is_file():
        lines += ["## Benchmark (scripts/bench_mm.py)", "", *bench_lines(json.loads(bench.read_text())), ""]
    lines += ["## How the database size limits the results", "", *limits(data, folder), ""]
    return write_report_md(folder, "\n".join(lines))


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python -m charctl.experiments.motion_matching.report DIR", file=sys.stderr)
        sys.exit(2)
    try:
        print(f"wrote {write_report(Path(argv[0]))}")
    except CharctlError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
