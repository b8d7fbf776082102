"""The report of `charctl eval RUN --checkpoints` for cgail (`eval_checkpoints`): checkpoints.md (what was
measured, the selection rule, one row per kept checkpoint, the chosen one on fresh starts) and checkpoints.png."""

from __future__ import annotations

from pathlib import Path

from charctl.eval.report import markdown_grid
from charctl.experiments.cgail.signatures import SIGNATURE_WITHIN


def skills_performed(row: dict, min_coverage: float) -> int:
    """How many skills of a checkpoint's row are performed: pose coverage >= `min_coverage` (a share in [0, 1]) and
    the skill's named signatures within 30 % of the clip's (`signatures.signatures_met`: a kick must lift the foot,
    the coverage of the guard around it does not count)."""
    fid = row["fidelity"]
    return sum(c >= min_coverage and fid["signature_met"][s] for s, c in fid["coverage"].items())


def write_report(run_dir: Path, rows: list[dict], chosen: dict | None, confirm: dict | None, a) -> str:
    """checkpoints.md and checkpoints.png in `a.out` (`a`: the settings, a `CgailCheckpoints`); returns the table."""
    from charctl.eval.checkpoints import write_checkpoints_md

    skills = list(rows[0]["no_fall"])
    fid = bool(a.fidelity)
    lines = _report_head(run_dir, skills, a, fid)
    lines += _report_table(rows, skills, a, fid).split("\n")
    lines.append("")
    lines.append("Cells: " + " / ".join(_cell_parts(a.conditional, fid)) + ".")
    if chosen is not None and confirm is not None:
        lines += _chosen_lines(chosen, confirm, fid)
    text = write_checkpoints_md(a.out, lines)
    _plot_checkpoints(run_dir, rows, a, fid, a.out / "checkpoints.png")
    return text


def _cell_parts(conditional: bool, fid: bool) -> list[str]:
    """What a per-skill cell of the table shows: no-fall, the diagonal (a cGAIL run), coverage (with fidelity)."""
    return ["no-fall", *(["diagonal"] if conditional else []), *(["coverage"] if fid else [])]


def _report_head(run_dir: Path, skills: list[str], a, fid: bool) -> list[str]:
    """checkpoints.md's title, what the tests measure (episode lengths in s) and the selection rule."""
    if a.conditional:
        measured = (
            f"no-fall: {a.k} episodes of {a.seconds:g} s per skill; diagonal: Fig 6.8 mean P(commanded skill) over "
            f"{a.confusion_k} episodes (RSI at frame 0, 3 s). Targets: no-fall >= {a.min_no_fall}, diagonal >= "
            f"{a.min_diagonal}. Argmax acc.: the classifier's top class equals the command, on the pairs of the "
            "no-fall test up to each episode's fall (the diagonal of a confusion matrix of predictions), for "
            "comparison. The diagonal runs start at frame 0 with mean actions, so they are the same on every "
            "evaluation."
        )
        rule = f"{_most(a)}, then worst no-fall, then min diagonal." if a.rank == "fidelity" else "margin."
    else:
        measured = (
            f"no-fall: {a.k} episodes of {a.seconds:g} s per skill. Target: no-fall >= {a.min_no_fall}. An AMP "
            "(unconditional) run has no classifier: no Fig 6.8 diagonal, no argmax accuracy."
        )
        rule = f"{_most(a)}, then worst no-fall."
    coverage = (
        f" Coverage: `charctl eval RUN --fidelity -k {a.fidelity_k}` (share of the clip's frames the policy "
        'matches within 0.15 m at every body, docs/cgail.md "Fidelity"); min coverage: the lowest over the '
        "skills."
    )
    title = f"# Kept checkpoints of {run_dir.name}"
    return [title, "", measured + (coverage if fid else ""), "Selection: the largest " + rule, ""]


def _most(a) -> str:
    """The fidelity rule's first keys, in words."""
    return (
        f"number of skills performed (coverage >= {a.min_coverage:g} and the named signature within "
        f"{SIGNATURE_WITHIN:.0%} of the clip's: kick and spinkick foot peak, jump airborne share, spins' yaw rate), "
        "then min coverage"
    )


def _report_table(rows: list[dict], skills: list[str], a, fid: bool) -> str:
    """checkpoints.md's table: one row per checkpoint, one column per skill (min coverage with `fid`)."""
    cond = bool(a.conditional)
    header = ["samples", "worst no-fall", *(["min diagonal", "min argmax acc."] if cond else [])]
    header += [*([f"skills performed (coverage >= {a.min_coverage:g}, signature)", "min coverage"] if fid else [])]
    header += [*(["meets both"] if cond else []), *skills]
    align = "r" * (2 + 2 * cond + 2 * fid) + "-" * (cond + len(skills))
    return markdown_grid(header, [_report_row(r, skills, a, fid) for r in rows], align=align)


def _report_row(r: dict, skills: list[str], a, fid: bool) -> list[str]:
    """One checkpoint's table cells: its summary numbers, whether it meets both targets (a cGAIL run),
    per-skill cells."""
    cond = bool(a.conditional)
    cells = [
        " / ".join(
            [
                f"{r['no_fall'][s]:.2f}",
                *([f"{r['diagonal'][s]:.2f}"] if cond else []),
                *([f"{r['fidelity']['coverage'][s]:.2f}"] if fid else []),
            ]
        )
        for s in skills
    ]
    summary = [f"{r['samples']:,}", f"{r['worst_no_fall']:.3f}"]
    if cond:
        summary += [f"{r['min_diagonal']:.3f}", f"{r['min_class_acc']:.3f}"]
    summary += [str(skills_performed(r, a.min_coverage)), f"{r['min_coverage']:.3f}"] if fid else []
    if cond:
        ok = r["worst_no_fall"] >= a.min_no_fall and r["min_diagonal"] >= a.min_diagonal
        summary.append("yes" if ok else "no")
    return [*summary, *cells]


def _chosen_lines(chosen: dict, confirm: dict, fid: bool) -> list[str]:
    """The chosen checkpoint and its numbers on the confirming fresh starts."""
    numbers = [f"worst no-fall {confirm['worst_no_fall']:.3f}"]
    if confirm.get("min_diagonal") is not None:
        numbers.append(f"min diagonal {confirm['min_diagonal']:.3f}")
    if fid and "min_coverage" in confirm:
        numbers.append(f"min coverage {confirm['min_coverage']:.3f}")
    return [
        "",
        f"Chosen: {chosen['checkpoint']} ({chosen['samples']:,} samples). "
        f"On fresh starts (seed {confirm['seed']}): " + ", ".join(numbers) + ".",
    ]


def _plot_checkpoints(run_dir: Path, rows: list[dict], a, fid: bool, path: Path) -> None:
    """checkpoints.png: the worst no-fall share, lowest diagonal (a cGAIL run) and lowest coverage (with
    fidelity) against samples (millions), with the targets dotted."""
    from charctl.viz.plots import new_figure, save_figure

    fig, ax = new_figure(1, 1, figsize=(7, 3.5))
    x = [r["samples"] / 1e6 for r in rows]
    ax.plot(x, [r["worst_no_fall"] for r in rows], "o-", label="worst skill's no-fall share")
    if a.conditional:
        ax.plot(x, [r["min_diagonal"] for r in rows], "s-", label="lowest Fig 6.8 diagonal")
    if fid:
        ax.plot(x, [r["min_coverage"] for r in rows], "^-", label="lowest pose coverage (fidelity)")
    ax.axhline(a.min_no_fall, color="C0", ls=":", lw=1)
    if a.conditional:
        ax.axhline(a.min_diagonal, color="C1", ls=":", lw=1)
    ax.set_xlabel("samples (millions)")
    ax.set_ylim(0, 1.02)
    ax.legend(loc="lower right")
    ax.set_title(f"{run_dir.name}: kept checkpoints against the targets (dotted)")
    save_figure(fig, path)
