"""Evaluate every kept checkpoint of a cgail run (train.keep_checkpoint_every) and pick one.

    .venv/bin/python scripts/eval_checkpoints.py RUN_DIR [--seconds 5] [-k 64] [--confusion-k 16]
        [--min-no-fall 0.8] [--min-diagonal 0.9] [--confirm-seed 7] [--fidelity [--fidelity-k 4]]
        [--rank margin|fidelity]

For each checkpoints/samples_<n>.pt (and last.pt) it runs what `charctl eval RUN --checkpoint F
--survival SECONDS -k K` and `--confusion -k CK` run, into RUN/eval/<checkpoint>/, then writes

- RUN/eval/checkpoints.json and checkpoints.md: per checkpoint, every skill's no-fall share and
  Fig 6.8 diagonal (mean classifier probability of the commanded skill on the policy's motion),
  the worst of each, and whether both targets hold;
- RUN/eval/checkpoints.png: worst no-fall and lowest diagonal against samples, with the targets.

With `--fidelity` each checkpoint also gets what `charctl eval RUN --checkpoint F --fidelity -k FK`
measures (docs/cgail.md, "Fidelity": pose coverage, DTW body-position error and the signature per
skill, without the filmstrips; the chosen checkpoint's re-evaluation draws them): the table gains
the lowest coverage over the skills and a coverage per skill, the plot a line.

Selection (`--rank margin`, the default): the checkpoint that meets both targets with the largest
margin (the smaller of worst no-fall - min_no_fall and min diagonal - min_diagonal), else the one
closest to meeting them. `--rank fidelity` (implies `--fidelity`): the largest lowest-coverage over
the skills, ties broken by the worst no-fall, then the lowest diagonal. Picking
the best of many noisy estimates favours a lucky one, so the chosen checkpoint is evaluated again on
fresh starts (`--confirm-seed`, a different seed from the selection's); both results are reported.
Each checkpoint's result is kept in RUN/eval/<checkpoint>/row.json: run the script again while the
training goes on and only the new checkpoints are evaluated (last.pt again when it has moved on).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch


def kept_checkpoints(run_dir: Path) -> list[tuple[int, str]]:
    """(samples, file name) of RUN/checkpoints/samples_*.pt and last.pt, by sample count."""
    from charctl.checkpoints import KEPT_CHECKPOINT, load_checkpoint

    found = []
    for p in sorted((run_dir / "checkpoints").glob("samples_*.pt")):
        m = KEPT_CHECKPOINT.fullmatch(p.name)
        if m:
            found.append((int(m.group(1)), p.name))
    last = run_dir / "checkpoints" / "last.pt"
    if last.is_file():
        n = int(load_checkpoint(last, "cgail")["samples"])
        if all(n != s for s, _ in found):
            found.append((n, "last.pt"))
    return sorted(found)


def margin(worst_no_fall: float, min_diagonal: float, min_no_fall: float, min_diag: float) -> float:
    """How far a checkpoint clears both targets (negative: how far it misses the worse one)."""
    return min(worst_no_fall - min_no_fall, min_diagonal - min_diag)


def rank_key(row: dict, rank: str) -> tuple:
    """Sort key of a checkpoint's row (larger is better) under selection rule `rank` (see the module doc)."""
    if rank == "fidelity":
        return (row["min_coverage"], row["worst_no_fall"], row["min_diagonal"])
    return (row["margin"],)


def cached_row(out: Path, name: str, samples: int, seconds: float, k: int, ck: int, seed: int) -> dict | None:
    """The row written by an earlier run of this script with the same settings (re-runs evaluate only
    new checkpoints), or None."""
    path = out / "row.json"
    if not path.is_file():
        return None
    row = json.loads(path.read_text())
    same = row.get("settings") == {"seconds": seconds, "k": k, "confusion_k": ck, "seed": seed}
    # a row written before the argmax accuracy was recorded is evaluated again
    current = same and "class_acc" in row
    return row if current and row.get("checkpoint") == name and row.get("samples") == samples else None


def evaluate_checkpoint(
    run_dir: Path,
    name: str,
    samples: int,
    seconds: float,
    k: int,
    ck: int,
    seed: int,
    out: Path,
    fidelity_k: int = 0,
    filmstrips: bool = False,
) -> dict:
    """No-fall and Fig 6.8 diagonal per skill of one checkpoint, and with `fidelity_k` > 0 its fidelity
    over that many episodes per skill (each part reused from out/row.json when its settings match)."""
    from charctl.experiments.cgail.evaluate import load_eval_run
    from charctl.files import atomic_write_text, strict_json

    row = cached_row(out, name, samples, seconds, k, ck, seed)
    tr = None
    if row is None:
        out.mkdir(parents=True, exist_ok=True)
        tr = load_eval_run(run_dir, "cpu", name)
        row = survival_and_confusion(tr, name, seconds, k, ck, seed, out)
        atomic_write_text(out / "row.json", strict_json(row))
    wanted = {"k": fidelity_k, "seed": seed}
    if fidelity_k > 0 and (row.get("fidelity") or {}).get("settings") != wanted:
        from charctl.experiments.cgail.fidelity import eval_fidelity

        tr = tr or load_eval_run(run_dir, "cpu", name)
        res = eval_fidelity([tr], fidelity_k, out, seed=seed, filmstrips=filmstrips)["skills"]
        peak = {s: max(r["policy"]["right_foot_peak"], r["policy"]["left_foot_peak"]) for s, r in res.items()}
        clip_peak = {
            s: max(r["reference"]["right_foot_peak"], r["reference"]["left_foot_peak"]) for s, r in res.items()
        }
        row["fidelity"] = {
            "settings": wanted,
            "coverage": {s: r["coverage"] for s, r in res.items()},
            "body_error": {s: r["body_error"] for s, r in res.items()},
            "foot_peak": peak,
            "foot_peak_clip": clip_peak,
            "airborne": {s: r["policy"]["airborne"] for s, r in res.items()},
            "no_fall": {s: r["no_fall"] for s, r in res.items()},  # of the fidelity episodes (RSI at frame 0)
        }
        row["min_coverage"] = min(row["fidelity"]["coverage"].values())
        atomic_write_text(out / "row.json", strict_json(row))
    return row


def survival_and_confusion(tr, name: str, seconds: float, k: int, ck: int, seed: int, out: Path) -> dict:
    """The no-fall / diagonal row of one loaded checkpoint."""
    from charctl.experiments.cgail.evaluate import eval_confusion, eval_survival

    surv = eval_survival([tr], k, seconds, out, seed=seed)
    conf = eval_confusion(tr, ck, out, seed=seed + 1)
    no_fall = {s: row[f"{tr.label} no-fall"] for s, row in surv["table"].items()}
    class_acc = {s: row[f"{tr.label} class acc"] for s, row in surv["table"].items()}
    diagonal = dict(zip(conf["skills"], conf["policy_diagonal"]))
    row = {
        "checkpoint": name,
        "samples": int(tr.agent.samples),
        "no_fall": no_fall,
        "diagonal": diagonal,
        "worst_no_fall": min(no_fall.values()),
        "min_diagonal": min(diagonal.values()),
        "class_acc": class_acc,  # argmax == command on the no-fall test's pairs (a confusion matrix's diagonal)
        "min_class_acc": min(class_acc.values()),
        "seed": seed,
        "settings": {"seconds": seconds, "k": k, "confusion_k": ck, "seed": seed},
    }
    return row


def write_report(run_dir: Path, rows: list[dict], chosen: dict | None, confirm: dict | None, a) -> None:
    from charctl.files import atomic_write_text, strict_json
    from charctl.viz.plots import new_figure, save_figure

    out = run_dir / "eval"
    atomic_write_text(out / "checkpoints.json", strict_json({"rows": rows, "chosen": chosen, "confirm": confirm}))
    skills = list(rows[0]["no_fall"])
    fid = bool(a.fidelity)
    lines = [
        f"# Kept checkpoints of {run_dir.name}",
        "",
        f"no-fall: {a.k} episodes of {a.seconds:g} s per skill; diagonal: Fig 6.8 mean P(commanded skill) over "
        f"{a.confusion_k} episodes (RSI at frame 0, 3 s). Targets: no-fall >= {a.min_no_fall}, diagonal >= "
        f"{a.min_diagonal}. Argmax acc.: the classifier's top class equals the command, on the pairs of the no-fall "
        "test up to each episode's fall (the diagonal of a confusion matrix of predictions), for comparison. The "
        "diagonal runs start at frame 0 with mean actions, so they are the same on every evaluation."
        + (
            f" Coverage: `charctl eval RUN --fidelity -k {a.fidelity_k}` (share of the clip's frames the policy "
            'matches within 0.15 m at every body, docs/cgail.md "Fidelity"); min coverage: the lowest over the '
            "skills."
            if fid
            else ""
        ),
        "Selection: the largest "
        + ("min coverage, then worst no-fall, then min diagonal." if a.rank == "fidelity" else "margin."),
        "",
        "| samples | worst no-fall | min diagonal | min argmax acc. | "
        + ("min coverage | " if fid else "")
        + "meets both | "
        + " | ".join(skills)
        + " |",
        "|---:|---:|---:|---:|" + ("---:|" if fid else "") + "---|" + "---|" * len(skills),
    ]
    for r in rows:
        cells = [
            f"{r['no_fall'][s]:.2f} / {r['diagonal'][s]:.2f}"
            + (f" / {r['fidelity']['coverage'][s]:.2f}" if fid else "")
            for s in skills
        ]
        ok = r["worst_no_fall"] >= a.min_no_fall and r["min_diagonal"] >= a.min_diagonal
        lines.append(
            f"| {r['samples']:,} | {r['worst_no_fall']:.3f} | {r['min_diagonal']:.3f} | {r['min_class_acc']:.3f} | "
            + (f"{r['min_coverage']:.3f} | " if fid else "")
            + f"{'yes' if ok else 'no'} | "
            + " | ".join(cells)
            + " |"
        )
    lines.append("")
    lines.append("Cells: no-fall / diagonal" + (" / coverage." if fid else "."))
    if chosen is not None and confirm is not None:
        lines += [
            "",
            f"Chosen: {chosen['checkpoint']} ({chosen['samples']:,} samples). "
            f"On fresh starts (seed {confirm['seed']}): worst no-fall {confirm['worst_no_fall']:.3f}, "
            f"min diagonal {confirm['min_diagonal']:.3f}"
            + (f", min coverage {confirm['min_coverage']:.3f}." if fid and "min_coverage" in confirm else "."),
        ]
    atomic_write_text(out / "checkpoints.md", "\n".join(lines) + "\n")
    fig, ax = new_figure(1, 1, figsize=(7, 3.5))
    x = [r["samples"] / 1e6 for r in rows]
    ax.plot(x, [r["worst_no_fall"] for r in rows], "o-", label="worst skill's no-fall share")
    ax.plot(x, [r["min_diagonal"] for r in rows], "s-", label="lowest Fig 6.8 diagonal")
    if fid:
        ax.plot(x, [r["min_coverage"] for r in rows], "^-", label="lowest pose coverage (fidelity)")
    ax.axhline(a.min_no_fall, color="C0", ls=":", lw=1)
    ax.axhline(a.min_diagonal, color="C1", ls=":", lw=1)
    ax.set_xlabel("samples (millions)")
    ax.set_ylim(0, 1.02)
    ax.legend(loc="lower right")
    ax.set_title(f"{run_dir.name}: kept checkpoints against the targets (dotted)")
    save_figure(fig, out / "checkpoints.png")
    print("\n".join(lines))


def main() -> None:
    from charctl.errors import CharctlError

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--seconds", type=float, default=5.0, help="episode length of the no-fall test (s)")
    ap.add_argument("-k", type=int, default=64, help="episodes per skill for no-fall")
    ap.add_argument("--confusion-k", type=int, default=16, help="episodes per skill for the Fig 6.8 diagonal")
    ap.add_argument("--min-no-fall", type=float, default=0.8)
    ap.add_argument("--min-diagonal", type=float, default=0.9)
    ap.add_argument("--seed", type=int, default=4321, help="starts of the selection evaluation")
    ap.add_argument("--confirm-seed", type=int, default=7, help="fresh starts for the chosen checkpoint")
    ap.add_argument("--after", type=float, default=0.0, help="skip checkpoints before this many samples")
    ap.add_argument(
        "--fidelity", action="store_true", help="also evaluate fidelity (coverage, body error) per checkpoint"
    )
    ap.add_argument("--fidelity-k", type=int, default=4, help="episodes per skill for --fidelity")
    ap.add_argument(
        "--rank",
        choices=("margin", "fidelity"),
        default="margin",
        help="selection rule: margin on no-fall / diagonal, or lowest coverage then no-fall (implies --fidelity)",
    )
    a = ap.parse_args()
    torch.set_num_threads(2)
    try:
        for flag, value in (("-k", a.k), ("--confusion-k", a.confusion_k), ("--fidelity-k", a.fidelity_k)):
            if value < 1:
                raise CharctlError(f"{flag} must be >= 1, got {value}")
        a.fidelity = a.fidelity or a.rank == "fidelity"
        fidelity_k = a.fidelity_k if a.fidelity else 0
        found = [(n, f) for n, f in kept_checkpoints(a.run_dir) if n >= a.after]
        if not found:
            raise CharctlError(f"{a.run_dir}/checkpoints has no checkpoint to evaluate")
        rows = []
        for n, name in found:
            print(f"--- {name} ({n:,} samples)", flush=True)
            row = evaluate_checkpoint(
                a.run_dir,
                name,
                n,
                a.seconds,
                a.k,
                a.confusion_k,
                a.seed,
                a.run_dir / "eval" / Path(name).stem,
                fidelity_k=fidelity_k,
            )
            row["margin"] = margin(row["worst_no_fall"], row["min_diagonal"], a.min_no_fall, a.min_diagonal)
            rows.append(row)
        chosen = max(rows, key=lambda r: rank_key(r, a.rank))  # the first (fewest samples) of equals
        confirm = evaluate_checkpoint(
            a.run_dir,
            chosen["checkpoint"],
            chosen["samples"],
            a.seconds,
            a.k,
            a.confusion_k,
            a.confirm_seed,
            a.run_dir / "eval" / f"{Path(chosen['checkpoint']).stem}_confirm",
            fidelity_k=fidelity_k,
            filmstrips=True,
        )
        write_report(a.run_dir, rows, chosen, confirm, a)
    except CharctlError as exc:
        raise SystemExit(f"error: {exc}") from None


if __name__ == "__main__":
    main()
