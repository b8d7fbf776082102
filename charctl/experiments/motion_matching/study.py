"""The paper's Table 1 feature study: 19 feature settings x the three target paths.

The paper gives the cases in words (its Table 1 numbers are not in the text we have):
  1-7    future positions only, n = 1..7 samples every 20 frames
  8-9    the same 100-frame horizon as 4 x 25 and 3 x 33
  10-11  + past trajectory (here: 2 past samples at the future spacing) on 5 x 20 and 4 x 25
  12-15  4 x 25, position + velocity with weights 1:0, 0.8:0.2, 0.6:0.4, 0.5:0.5
  16-19  4 x 25, position:velocity 0.8:0.2, discount gamma = 0.9, 0.8, 0.7, 0.6
Every case sets all the trajectory keys, so it does not depend on the features.* defaults
(the pose blocks and the runtime are shared by all cases).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError


def _case(n: int, spacing: int, past: int = 0, pos: float = 1.0, vel: float = 0.0, gamma: float = 1.0) -> dict:
    return {"future_samples": n, "future_spacing": spacing, "past_samples": past, "past_spacing": spacing,
            "position_weight": pos, "velocity_weight": vel, "direction_weight": 0.0, "discount": gamma}


TABLE1: dict[int, dict] = {
    **{n: _case(n, 20) for n in range(1, 8)},
    8: _case(4, 25), 9: _case(3, 33),
    10: _case(5, 20, past=2), 11: _case(4, 25, past=2),
    12: _case(4, 25, pos=1.0, vel=0.0), 13: _case(4, 25, pos=0.8, vel=0.2),
    14: _case(4, 25, pos=0.6, vel=0.4), 15: _case(4, 25, pos=0.5, vel=0.5),
    **{16 + k: _case(4, 25, pos=0.8, vel=0.2, gamma=g) for k, g in enumerate((0.9, 0.8, 0.7, 0.6))},
}


def describe(case: int) -> str:
    """Short text of a Table 1 case, e.g. '4x25 pos:vel 0.8:0.2 γ0.7'."""
    c = TABLE1[case]
    text = f"{c['future_samples']}x{c['future_spacing']}"
    if c["past_samples"]:
        text += f" +past {c['past_samples']}x{c['past_spacing']}"
    if c["velocity_weight"] > 0 or case in (12, 13, 14, 15):
        text += f" pos:vel {c['position_weight']:g}:{c['velocity_weight']:g}"
    if c["discount"] < 1:
        text += f" γ{c['discount']:g}"
    return text


def with_case(cfg, case: int):
    """A copy of cfg with the trajectory feature keys of Table 1 case `case`."""
    from omegaconf import OmegaConf

    if case not in TABLE1:
        raise CharctlError(f"case must be 1..19 (Table 1), got {case}")
    out = OmegaConf.create(OmegaConf.to_container(cfg, resolve=True))
    for k, v in TABLE1[case].items():
        out.features[k] = v
    out.case = str(case)
    return out


def resolve_case(cfg):
    """Apply `cfg.case` ("" | "1".."19" | "best"); returns (cfg, case number or None)."""
    spec = str(cfg.case).strip()
    if not spec:
        return cfg, None
    if spec == "best":
        case = best_case_from_sweeps(cfg.output_root)
    else:
        try:
            case = int(spec)
        except ValueError:
            raise CharctlError(f"case must be empty, 1..19 or 'best', got {spec!r}") from None
    return with_case(cfg, case), case


def best_case_from_sweeps(output_root: str) -> int:
    """The best case recorded by the most recent sweep (sweep.json under output_root)."""
    found = sorted(Path(output_root).glob("**/sweep.json"), key=lambda p: p.stat().st_mtime)
    if not found:
        raise CharctlError(f"case=best: no sweep results (sweep.json) under {output_root}/ — run `charctl eval motion-matching --sweep` first")
    data = json.loads(found[-1].read_text())
    return int(data["best_case"])


# ---------------------------------------------------------------------------- running the sweep
def run_sweep(cfg, out_dir: Path, progress=None) -> dict:
    """Run the cases of cfg.sweep on its paths; write sweep.json, sweep.md and PNG plots to out_dir."""
    from charctl.experiments.motion_matching.database import build_database
    from charctl.experiments.motion_matching.paths import make_path
    from charctl.experiments.motion_matching.runtime import run_path
    from charctl.experiments.motion_matching.search import make_index
    from charctl.experiments.motion_matching.sources import load_sources

    cases = list(cfg.sweep.cases) or sorted(TABLE1)
    bad = [c for c in cases if c not in TABLE1]
    if bad:
        raise CharctlError(f"sweep.cases: {bad[0]} is not a Table 1 case (1..19)")
    paths = {p: make_path(p, cfg.paths) for p in cfg.sweep.paths}
    starts = int(cfg.sweep.starts)
    tic = time.perf_counter()
    sources, info = load_sources(cfg)
    results: dict[int, dict] = {}
    rollouts: dict[int, dict] = {}
    for case in cases:
        ccfg = with_case(cfg, case)
        db = build_database(ccfg, sources, info)
        index = make_index(ccfg.runtime.index, db)
        results[case] = {"description": describe(case), "paths": {}}
        rollouts[case] = {}
        for name, path in paths.items():
            runs = [run_path(db, index, path, ccfg, with_pose=False, start_shift=k / starts) for k in range(starts)]
            err = pooled_errors(path, [r.ground for r in runs], ccfg.paths.speed, 1.0 / db.fps)
            results[case]["paths"][name] = {**err, "frames": sum(r.num_frames for r in runs),
                                            "searches": sum(r.searches for r in runs), "jumps": sum(r.jumps for r in runs)}
            rollouts[case][name] = runs[0].ground
        if progress is not None:
            progress(case)
    elapsed = time.perf_counter() - tic
    summary = summarise(results)
    out_dir.mkdir(parents=True, exist_ok=True)
    payload = {"cases": results, **summary, "seconds": elapsed, "database_frames": int(db.num_searchable),
               "database_fps": float(db.fps), "paths": list(paths), "speed": float(cfg.paths.speed), "starts": starts}
    payload = json.loads(json.dumps(payload))  # one form (string keys) for the file and the table
    (out_dir / "sweep.json").write_text(json.dumps(payload, indent=2))
    (out_dir / "sweep.md").write_text(sweep_markdown(payload))
    if cfg.sweep.plots:
        plot_sweep(paths, rollouts, results, summary["best_case"], out_dir, starts)
    return payload


def pooled_errors(path, grounds: list[np.ndarray], speed: float, dt: float) -> dict[str, float]:
    """Mean/std of e_time and e_near over the frames of all rollouts together."""
    from charctl.experiments.motion_matching.paths import frame_errors

    per = [frame_errors(path, g, speed, dt) for g in grounds]
    out = {}
    for k in ("e_time", "e_near"):
        v = np.concatenate([p[k] for p in per])
        out[f"{k}_mean"], out[f"{k}_std"] = float(v.mean()), float(v.std())
    return out


def summarise(results: dict[int, dict]) -> dict:
    """Best case overall (lowest mean over paths of e_time_mean) and per path, for both metrics."""
    cases = sorted(results)
    paths = list(results[cases[0]]["paths"])
    out = {}
    for metric in ("e_time", "e_near"):
        avg = {c: float(np.mean([results[c]["paths"][p][f"{metric}_mean"] for p in paths])) for c in cases}
        out[f"best_case_{metric}"] = min(avg, key=avg.get)
        out[f"avg_{metric}"] = avg
        out[f"best_per_path_{metric}"] = {p: min(cases, key=lambda c: results[c]["paths"][p][f"{metric}_mean"]) for p in paths}
    out["best_case"] = out["best_case_e_time"]
    return out


def sweep_markdown(payload: dict) -> str:
    """Two tables (e_time, e_near): mean ± std per path, best per column in bold, best row starred."""
    results = payload["cases"]
    cases = sorted(results, key=int)
    paths = payload["paths"]
    lines = [
        f"Database: {payload['database_frames']} searchable frames at {payload['database_fps']:.0f} Hz; "
        f"target speed {payload['speed']:g} m/s; each path run from {payload['starts']} starting gait phase(s), "
        f"mean ± std over all their frames; {payload['seconds']:.1f} s for the whole sweep.", "",
    ]
    titles = {"e_time": "e_time — distance to the target point at the same time (m)",
              "e_near": "e_near — distance to the nearest point of the path (m)"}
    for metric in ("e_time", "e_near"):
        best_row = str(payload[f"best_case_{metric}"])
        best_col = {p: str(c) for p, c in payload[f"best_per_path_{metric}"].items()}
        lines += [f"**{titles[metric]}**", "", "| case | features | " + " | ".join(paths) + " | mean |",
                  "|---:|---|" + "---:|" * (len(paths) + 1)]
        for c in cases:
            cells = []
            for p in paths:
                r = results[c]["paths"][p]
                cell = f"{r[f'{metric}_mean']:.3f} ± {r[f'{metric}_std']:.3f}"
                cells.append(f"**{cell}**" if best_col[p] == str(c) else cell)
            mark = " ★" if str(c) == best_row else ""
            avg = payload[f"avg_{metric}"][c]
            lines.append(f"| {c}{mark} | {results[c]['description']} | " + " | ".join(cells) + f" | {avg:.3f} |")
        lines += ["", f"★ best row (lowest mean over the paths): case {best_row}; bold: best per path.", ""]
    return "\n".join(lines)


def plot_sweep(paths: dict, rollouts: dict, results: dict, best: int, out_dir: Path, starts: int = 1) -> None:
    """One PNG per case (generated vs target, one panel per path) and best.png."""
    from charctl.viz.plots import new_figure, save_figure

    for case, by_path in rollouts.items():
        fig, axes = new_figure(1, len(paths), figsize=(4.2 * len(paths), 4.2))
        axes = np.atleast_1d(axes)
        for ax, (name, path) in zip(axes, paths.items()):
            draw_paths(ax, path, by_path[name])
            r = results[case]["paths"][name]
            ax.set_title(f"{name}: e_time {r['e_time_mean']:.2f}±{r['e_time_std']:.2f} m", fontsize=9)
        note = f" — first of {starts} starts shown, errors pooled over all" if starts > 1 else ""
        fig.suptitle(f"case {case}: {results[case]['description']}" + (" (best)" if case == best else "") + note, fontsize=10)
        save_figure(fig, out_dir / "plots" / f"case_{case:02d}.png", dpi=90)
        if case == best:
            import shutil

            shutil.copyfile(out_dir / "plots" / f"case_{case:02d}.png", out_dir / "best.png")


def draw_paths(ax, path, ground: np.ndarray) -> None:
    """Target (dashed) and generated root path (solid) seen from above (x right, z down)."""
    ax.plot(path.points[:, 0], path.points[:, 1], "k--", lw=1.0, label="target")
    ax.plot(ground[:, 0], ground[:, 1], "-", color="tab:red", lw=1.2, label="generated")
    ax.plot(ground[:1, 0], ground[:1, 1], "o", color="tab:red", ms=4)
    ax.set_aspect("equal")
    ax.invert_yaxis()
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.legend(fontsize=7, loc="best")
