"""Run comparison (`charctl eval RUN... --curves [-o DIR]`) and the reproduction report
(`python -m charctl.experiments.hopper_ga.evaluate RUNS_FOLDER -o OUT [--media]`)."""

from __future__ import annotations

import json
from pathlib import Path

from charctl.errors import CharctlError
from charctl.eval.report import markdown_grid, write_report
from charctl.experiments.hopper_ga.results import load_best, open_hopper_run, run_dirs, write_outputs

# the columns of report.md's gait table and limp table
GAIT_HEADER = [
    "speed (m/s)",
    "beta",
    "E_r",
    "gamma",
    "eval",
    "stride (m)",
    "flight time (s)",
    "stance time (s)",
    "cadence (steps/min)",
    "GA",
    "runtime, wall (s)",
]

LIMP_HEADER = [
    "speed",
    "beta",
    "stance right / left, normal (s)",
    "stance right / left, limp (s)",
    "mean COM z normal (cm)",
    "mean COM z limp (cm)",
    "COM tracking RMS (cm)",
]


def _history(run) -> dict:
    if not run.has_checkpoint():
        raise CharctlError(f"{run.dir} has no checkpoint (checkpoints/last.pt); train first")
    return run.load_checkpoint()["history"]


def evaluate(targets: list[str], options: dict, overrides: list[str]) -> None:
    """`--curves`: re-draw each run's figures and print the comparison table; with `-o DIR` also
    write DIR/report.md with the table and the figures."""
    build_report(run_dirs(targets, overrides), options.get("out"), overrides)


def build_report(dirs: list[Path], out: Path | None, overrides: list[str] | None = None) -> list[dict]:
    """Re-draw every run's figures (into the run, or OUT/<run>/), print the table; with `out`,
    write OUT/report.md (table, GA wall times, figures, brisk-vs-normal comparison)."""
    loaded = []
    for d in dirs:  # every run opened and read before the first figure is written
        run, s = open_hopper_run(d, overrides)
        loaded.append((d, run, s, _history(run), load_best(d)[0]))
    rows = []
    for d, run, s, history, genome in loaded:
        fig_dir = Path(out) / d.name if out else Path(d)
        numbers = write_outputs(fig_dir, history, genome, s, run.cfg)
        metrics = json.loads((Path(d) / "metrics.json").read_text()) if (Path(d) / "metrics.json").is_file() else {}
        rows.append(
            {
                "run": d.name,
                "dir": str(d),
                "figures": str(fig_dir),
                "speed": s.speed,
                "beta": s.beta,
                "generations": len(history["best"]) - 1,
                "population": int(run.cfg.ga.population),
                "runtime": metrics.get("runtime", str(run.cfg.runtime.kind)),
                "wall_s": metrics.get("wall_s", float("nan")),
                **numbers["gait"],
                "limp": numbers["limp"],
                "best_curve": history["best"],
            }
        )
    rows.sort(key=lambda r: (r["speed"], r["beta"]))
    print(_table(rows))
    if out:
        path = write_report(Path(out), _markdown(rows, Path(out)))
        print(f"wrote {path}")
    return rows


def _table(rows: list[dict]) -> str:
    head = (
        f"{'speed':>6} {'beta':>5} {'E_r':>7} {'gamma':>8} {'eval':>7} {'stride m':>8} {'flight s':>8} "
        f"{'stance s':>8} {'cadence':>7}  run"
    )
    lines = [head]
    for r in rows:
        lines.append(
            f"{r['speed']:>6g} {r['beta']:>5g} {r['E_r']:>7.3f} {r['gamma']:>8.4f} {r['eval']:>7.4f} "
            f"{r['stride_length_m']:>8.2f} "
            f"{r['flight_time_s']:>8.3f} {r['stance_time_s']:>8.3f} {r['cadence_spm']:>7.1f}  {r['run']}"
        )
    return "\n".join(lines)


def _markdown(rows: list[dict], out: Path) -> str:
    md = _gait_table_md(rows) + _brisk_vs_normal_md(rows) + _limp_table_md(rows) + _figures_md(rows, out)
    return "\n".join(md) + "\n"


def _gait_table_md(rows: list[dict]) -> list[str]:
    """The report's title, its notes on units, and one gait row per run."""
    md = [
        "# hopper-ga reproduction report",
        "",
        "Kang (1999); method and decisions in docs/hopper-ga.md. One GA run per row (population x generations "
        "as listed); E_r is in units of",
        "`fitness.energy_scale`; one cycle = one step (stance + flight), stride = two steps, cadence in steps/min.",
        "",
    ]
    return md + markdown_grid(GAIT_HEADER, [_gait_cells(r) for r in rows], align="r" * 9 + "--").split("\n")


def _gait_cells(r: dict) -> list[str]:
    """One run's row of the gait table (GAIT_HEADER's columns)."""
    return [
        f"{r['speed']:g}",
        f"{r['beta']:g}",
        f"{r['E_r']:.3f}",
        f"{r['gamma']:.4f}",
        f"{r['eval']:.4f}",
        f"{r['stride_length_m']:.2f}",
        f"{r['flight_time_s']:.3f}",
        f"{r['stance_time_s']:.3f}",
        f"{r['cadence_spm']:.1f}",
        f"{r['population']} x {r['generations']}",
        f"{r['runtime']}, {r['wall_s']:.1f}",
    ]


def _brisk_vs_normal_md(rows: list[dict]) -> list[str]:
    """The beta 0.2 -> 0.7 comparison at 10 m/s, when both runs are there (else nothing)."""
    fast = [r for r in rows if r["speed"] == 10 and r["beta"] in (0.2, 0.7)]
    if len(fast) != 2:
        return []
    n, b = sorted(fast, key=lambda r: r["beta"])
    return [
        "",
        "## Normal (beta = 0.2) vs brisk (beta = 0.7) at 10 m/s",
        "",
        f"E_r {n['E_r']:.3f} -> {b['E_r']:.3f} (targets beta/(1-beta) = 0.25 and 2.33), "
        f"stride {n['stride_length_m']:.2f} -> {b['stride_length_m']:.2f} m, "
        f"flight {n['flight_time_s']:.3f} -> {b['flight_time_s']:.3f} s, "
        f"stance {n['stance_time_s']:.3f} -> {b['stance_time_s']:.3f} s, "
        f"cadence {n['cadence_spm']:.0f} -> {b['cadence_spm']:.0f} steps/min.",
    ]


def _limp_table_md(rows: list[dict]) -> list[str]:
    """The limp test and COM tracking table (stance times in s, COM z in cm), one row per run."""
    md = [
        "",
        "## Limp test (Fig 3.13) and COM tracking (Fig 3.14)",
        "",
        *markdown_grid(LIMP_HEADER, [_limp_cells(r) for r in rows], align="rr--rrr").split("\n"),
    ]
    md += [
        "",
        "Right is +z: with the left (limping) leg's stance shortened, the mean COM moves towards the sound right leg.",
    ]
    return md


def _limp_cells(r: dict) -> list[str]:
    """One run's row of the limp table (LIMP_HEADER's columns); a limp run that was impossible says why
    in the first limp column and leaves the others empty."""
    lp = r["limp"]
    rms = f"{100 * lp['com_tracking_rms_m']:.2f}"
    if "error" in lp:
        return [f"{r['speed']:g}", f"{r['beta']:g}", f"limp run impossible: {lp['error']}", "", "", "", rms]
    return [
        f"{r['speed']:g}",
        f"{r['beta']:g}",
        f"{lp['normal_stance_right_s']:.3f} / {lp['normal_stance_left_s']:.3f}",
        f"{lp['limp_stance_right_s']:.3f} / {lp['limp_stance_left_s']:.3f}",
        f"{100 * lp['normal_mean_com_z_m']:+.2f}",
        f"{100 * lp['limp_mean_com_z_m']:+.2f}",
        rms,
    ]


def _figures_md(rows: list[dict], out: Path) -> list[str]:
    """Each run's figures and media that exist, linked relative to `out` where they lie under it."""
    md = ["", "## Figures", ""]
    for r in rows:
        f = Path(r["figures"])
        md += [f"### speed {r['speed']:g} m/s, beta {r['beta']:g} (`{r['run']}`)", ""]
        for name, caption in (
            ("strip.png", "two steps, side view"),
            ("fitness_curve.png", "best eval per generation (Fig 5.7 normalisation)"),
            ("com_path.png", "target vs actual COM (Fig 3.14)"),
            ("limp.png", "limp test (Fig 3.13)"),
        ):
            if (f / name).is_file():
                md.append(f"![{caption}]({_rel(f / name, out)})")
        for name in ("run.mp4", "run.bvh"):
            if (f / name).is_file():
                md.append(f"[{name}]({_rel(f / name, out)})")
        md.append("")
    return md


def _rel(p, out: Path) -> Path:
    """`p` relative to `out` when it lies under it, else `p` as given."""
    resolved, root = Path(p).resolve(), out.resolve()
    return resolved.relative_to(root) if resolved.is_relative_to(root) else Path(p)


def main(argv: list[str] | None = None) -> None:
    """python -m charctl.experiments.hopper_ga.evaluate RUNS_FOLDER -o OUT [--media]"""
    import argparse

    ap = argparse.ArgumentParser(description=main.__doc__)
    ap.add_argument("runs", type=Path)
    ap.add_argument("-o", "--out", type=Path, required=True)
    ap.add_argument("--media", action="store_true", help="also export run.bvh and run.mp4 of every run")
    args = ap.parse_args(argv)
    from charctl.experiments.hopper_ga.export import export_run

    dirs = run_dirs([str(args.runs)])
    if args.media:
        for d in dirs:
            (args.out / d.name).mkdir(parents=True, exist_ok=True)
            export_run(d, {"bvh": args.out / d.name / "run.bvh", "video": args.out / d.name / "run.mp4"})
    build_report(dirs, args.out)


if __name__ == "__main__":
    try:
        main()
    except CharctlError as exc:
        import sys

        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
