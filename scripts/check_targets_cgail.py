"""Which of the fidelity issue's written targets (docs/cgail.md, "Fidelity") a cgail run's evaluation meets.

    .venv/bin/python scripts/check_targets_cgail.py RUN/eval [--matrix DIR] [--out targets.md]

Reads what `charctl eval RUN --fidelity`, `--survival 5 -k 32`, `--dtw --confusion --switch walk right_kick` and
(optionally) `--switch-matrix -o DIR` wrote into the folder (`make repro-cgail-*` runs them all) and prints one row per
target: the measured value, the bound, met or missed. The three-skill targets (walk, run, right_kick) or the ten-skill
ones are chosen by the skills the evaluation holds. A file an evaluation did not write gives "not measured" rows.

Three skills: coverage >= 0.6 and body-position error <= 0.15 m per skill; the kicking foot's peak >= 0.8 x the clip's;
the run's speed and airborne share within 25 % of the clip's; DTW e_pose <= the paper's cGAIL value per skill; no-fall
>= 0.9 (32 x 5 s); after walk -> right_kick the kick done without a fall in >= 6 of 8 trials.
Ten skills: coverage >= 0.5 per skill; the named signatures within 30 % of the clip's (the kicks' and the spinkick's
foot peak, the jump's airborne share, the spins' yaw rate); DTW <= paper for >= 7 of 10; no-fall >= 0.8.
The switch matrix is no written target: its row says how many ordered pairs reach 6 of 8 trials (75 %, whatever -k).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from charctl.experiments.cgail.signatures import SIGNATURE_WITHIN, kicking_foot, signature_checks, within

THREE = ("walk", "run", "right_kick")
THREE_BOUNDS = {"coverage": 0.6, "body_error": 0.15, "kick_foot": 0.8, "run_within": 0.25, "no_fall": 0.9}
TEN_BOUNDS = {"coverage": 0.5, "signature_within": SIGNATURE_WITHIN, "dtw_skills": 7, "no_fall": 0.8}
SWITCH_NEEDED = 6  # of 8 trials (issue 24), also the matrix row's bar


def _load(folder: Path, name: str) -> dict | None:
    path = folder / name
    return json.loads(path.read_text()) if path.is_file() else None


def run_label(table: dict) -> str:
    """The evaluated run's column of a dtw/survival table (the entry that is no paper value)."""
    row = next(iter(table.values()))
    labels = [k for k in row if not k.startswith("paper") and not k.endswith(("falls", "class acc"))]
    return labels[0].removesuffix(" no-fall")


def _coverage_row(skill: str, s: dict, bound: float) -> tuple:
    """The row of `skill`'s pose coverage (`s`: its fidelity.json entry) against `bound`."""
    return f"{skill} coverage", s["coverage"], f">= {bound}", s["coverage"] >= bound


def rows_three(fid: dict, surv: dict | None, dtw: dict | None, switch: dict | None) -> list[tuple]:
    """The three-skill rows; `fid` (fidelity.json) is required, the others give "not measured" rows when None."""
    b = THREE_BOUNDS
    rows: list[tuple] = []
    for skill in THREE:
        s = fid["skills"][skill]
        rows.append(_coverage_row(skill, s, b["coverage"]))
        err = s["body_error"]
        rows.append((f"{skill} body error (m)", err, f"<= {b['body_error']}", err <= b["body_error"]))
    p, r = fid["skills"]["right_kick"]["policy"], fid["skills"]["right_kick"]["reference"]
    foot = kicking_foot(r)
    share = p[f"{foot}_foot_peak"] / r[f"{foot}_foot_peak"]
    rows.append(("right_kick foot peak / clip's", share, f">= {b['kick_foot']}", share >= b["kick_foot"]))
    p, r = fid["skills"]["run"]["policy"], fid["skills"]["run"]["reference"]
    for key in ("speed", "airborne"):
        ok = within(p[key], r[key], b["run_within"])
        rows.append((f"run {key} (clip {r[key]:.2f})", p[key], f"within {b['run_within']:.0%}", ok))
    rows += _dtw_rows(dtw, THREE)
    rows += _no_fall_rows(surv, THREE, b["no_fall"])
    for cond in ("ramp", "no_ramp"):
        c = switch["summary"][cond] if switch else None
        text = c and f"{c['performed']} of {c['trials']}"
        rows.append(
            (
                f"walk -> right_kick ({cond.replace('_', ' ')})",
                text,
                f">= {SWITCH_NEEDED} of 8",
                c and c["performed"] >= SWITCH_NEEDED,
            )
        )
    return rows


def _dtw_rows(dtw: dict | None, skills) -> list[tuple]:
    if not dtw:
        return [(f"{k} DTW e_pose", None, "<= paper", None) for k in skills]
    t, label = dtw["table"], run_label(dtw["table"])
    return [
        (f"{k} DTW e_pose", t[k][label], f"<= {t[k]['paper cGAIL']}", t[k][label] <= t[k]["paper cGAIL"])
        for k in skills
    ]


def _no_fall_rows(surv: dict | None, skills, bound: float) -> list[tuple]:
    if not surv:
        return [(f"{k} no-fall", None, f">= {bound}", None) for k in skills]
    t, label = surv["table"], run_label(surv["table"])
    return [
        (f"{k} no-fall", t[k][f"{label} no-fall"], f">= {bound}", t[k][f"{label} no-fall"] >= bound) for k in skills
    ]


def rows_ten(fid: dict, surv: dict | None, dtw: dict | None, skills: list[str]) -> list[tuple]:
    """The ten-skill rows; `fid` (fidelity.json) is required, the others give "not measured" rows when None."""
    b = TEN_BOUNDS
    rows: list[tuple] = []
    for skill in skills:
        s = fid["skills"][skill]
        rows.append(_coverage_row(skill, s, b["coverage"]))
        for label, p, r, ok in signature_checks(s, b["signature_within"]):
            rows.append((f"{skill} {label} (clip {r:.2f})", p, f"within {b['signature_within']:.0%}", ok))
    dtw_rows = _dtw_rows(dtw, skills)
    rows += [(name, v, bound, None) for name, v, bound, _ in dtw_rows]  # one skill above the paper is no miss here
    if dtw:
        n = sum(bool(r[3]) for r in dtw_rows)
        rows.append(
            ("skills with DTW <= paper", f"{n} of {len(skills)}", f">= {b['dtw_skills']}", n >= b["dtw_skills"])
        )
    rows += _no_fall_rows(surv, skills, b["no_fall"])
    return rows


def matrix_row(matrix: dict | None) -> list[tuple]:
    if not matrix:
        return []
    shares = [s for row in matrix["performed_share"] for s in row if s is not None]
    bar = SWITCH_NEEDED / 8
    n = sum(s >= bar - 1e-9 for s in shares)
    label = f"switch matrix pairs performed in >= {bar:.0%} of trials ({SWITCH_NEEDED} of 8; no written target)"
    return [(label, f"{n} of {len(shares)}", "", None)]


def table(rows: list[tuple]) -> str:
    def fmt(v):
        return "not measured" if v is None else f"{v:.3f}" if isinstance(v, float) else str(v)

    def verdict(ok):
        return "" if ok is None else "met" if ok else "**missed**"

    lines = ["| target | measured | bound | |", "|---|---:|---|---|"]
    lines += [f"| {name} | {fmt(v)} | {bound} | {verdict(ok)} |" for name, v, bound, ok in rows]
    return "\n".join(lines)


def check(folder: Path, matrix_dir: Path | None = None) -> str:
    """The markdown table of the targets for the evaluation in `folder` (module docstring)."""
    fid = _load(folder, "fidelity.json")
    if fid is None:
        raise SystemExit(f"error: {folder} has no fidelity.json: run `charctl eval RUN --fidelity` first")
    skills = list(fid["skills"])
    surv, dtw = _load(folder, "survival.json"), _load(folder, "dtw.json")
    matrix = _load(matrix_dir or folder / "matrix", "switch_matrix.json")
    if sorted(skills) == sorted(THREE):
        body = rows_three(fid, surv, dtw, _load(folder, "switch_walk_to_right_kick.json"))
        title = "three-skill targets"
    elif len(skills) == 10:
        body = rows_ten(fid, surv, dtw, skills)
        title = "ten-skill targets"
    else:
        raise SystemExit(
            f"error: {folder} evaluates {', '.join(skills)}: the targets are for walk, run, right_kick or ten skills"
        )
    rows = body + matrix_row(matrix)
    missed = sum(r[3] is False for r in rows)
    unmeasured = sum(r[1] is None for r in rows)
    return f"{title} of {folder}: {missed} missed, {unmeasured} not measured\n\n{table(rows)}\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", type=Path, help="RUN/eval (or the -o folder of the evaluations)")
    ap.add_argument("--matrix", type=Path, help="the --switch-matrix output folder (default: FOLDER/matrix)")
    ap.add_argument("--out", type=Path, help="also write the table to this file")
    args = ap.parse_args(argv)
    if not args.folder.is_dir():
        print(f"error: {args.folder} is not a folder", file=sys.stderr)
        return 2
    text = check(args.folder, args.matrix)
    print(text)
    if args.out:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
