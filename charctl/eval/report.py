"""Evaluation output shared by the experiments: tables (terminal, Markdown and CSV), JSON, and a report.md
that each evaluation mode appends its table to (or that an evaluation writes whole, `write_report`).

    rows = {"walk": {"error": 0.12, "falls": 0}, "run": {"error": 0.3, "falls": 1}}   # name -> column -> value
    markdown_table(rows, ["error", "falls"])       # | | error | falls |  ...  (cells: fmt_cell)
    markdown_grid(["skill", "error"], [["walk", "0.12"]], align="-r")  # header + rows of cells, |---|---:|
    write_csv(out / "t.csv", rows, ["error", "falls"], index="skill")
    write_json(out / "t.json", {"table": rows})    # numpy values converted, NaN / inf -> null
    append_report(out, "Title", markdown_table(rows, cols), "how it was measured", header="# my report\n")
    write_report(out, "# my report\n\n...")        # out/report.md replaced by the whole text
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

REPORT_HEADER = "# Evaluation report\n\nProduced by charctl.\n"  # an experiment passes its own header


def fmt_cell(v) -> str:
    """A table cell: '-' for None, 3 decimals for floats ('nan' kept), str() otherwise."""
    if v is None:
        return "-"
    if isinstance(v, float):
        return "nan" if np.isnan(v) else f"{v:.3f}"
    return str(v)


def markdown_table(rows: dict, cols: list[str]) -> str:
    """rows: name -> {column: value}; one Markdown row per name, the columns in `cols` order."""
    lines = ["| | " + " | ".join(cols) + " |", markdown_rule(len(cols) + 1)]
    for name, row in rows.items():
        lines.append(f"| {name} | " + " | ".join(fmt_cell(row.get(c)) for c in cols) + " |")
    return "\n".join(lines)


def markdown_row(cells) -> str:
    """One Markdown table row of the cells as str(): | a | b |."""
    return "| " + " | ".join(str(c) for c in cells) + " |"


_ALIGN_RULES = {"-": "---", "l": ":---", "r": "---:", "c": ":---:"}  # markdown_rule's alignment letters


def markdown_rule(columns: int, align: str = "") -> str:
    """The separator row under a Markdown table's header, one `---` per column: |---|---:|.

    `align` gives the columns' alignment, one letter each: '-' none (`---`), 'l' left (`:---`),
    'r' right (`---:`), 'c' centred (`:---:`); columns past its end get none."""
    if len(align) > columns or any(a not in _ALIGN_RULES for a in align):
        raise ValueError(f"align {align!r}: at most {columns} of the letters {''.join(_ALIGN_RULES)}")
    return "|" + "".join(_ALIGN_RULES[a] + "|" for a in align.ljust(columns, "-"))


def markdown_grid(header: Sequence, rows: Iterable[Sequence], align: str = "") -> str:
    """A Markdown table from its header and its rows as lists of cells in column order (no index
    column, unlike `markdown_table`): each line as `markdown_row` writes it (cells as str(), so format
    numbers first), the separator as `markdown_rule(len(header), align)` writes it; no final newline.

        markdown_grid(["clip", "speed"], [["walk", "1.20"]], align="-r")
        # '| clip | speed |\n|---|---:|\n| walk | 1.20 |'
    """
    lines = [markdown_row(header), markdown_rule(len(header), align)]
    lines += [markdown_row(cells) for cells in rows]
    return "\n".join(lines)


def write_csv(path: Path, rows: dict, cols: list[str], index: str = "") -> None:
    """rows (name -> {column: value}) as CSV, written atomically: a header `index, *cols`, then one line
    per name with its cells as `fmt_cell` writes them (csv's own line ends, \\r\\n)."""
    from charctl.files import atomic_write_text

    buf = io.StringIO(newline="")
    w = csv.writer(buf)
    w.writerow([index, *cols])
    for name, row in rows.items():
        w.writerow([name, *[fmt_cell(row.get(c)) for c in cols]])
    atomic_write_text(path, buf.getvalue())


def print_table(title: str, rows: dict, cols: list[str]) -> None:
    """The same table on the terminal (rich)."""
    from rich.console import Console
    from rich.table import Table

    t = Table(title=title)
    t.add_column("")
    for c in cols:
        t.add_column(c, justify="right")
    for name, row in rows.items():
        t.add_row(name, *[fmt_cell(row.get(c)) for c in cols])
    Console().print(t)


def write_json(path: Path, obj) -> None:
    """`obj` as indented JSON (numpy values converted), written atomically."""
    from charctl.files import _jsonable, atomic_write_text

    atomic_write_text(path, json.dumps(_jsonable(obj), indent=2))


def append_report(
    out: Path,
    title: str | None,
    body: str | None,
    note: str | None,
    command: str | None = None,
    header: str = REPORT_HEADER,
) -> None:
    """Append to out/report.md (created with `header`): the command line, then `## title`, the body and
    the note in italics."""
    path = out / "report.md"
    if not path.exists():
        path.write_text(header)
    with open(path, "a") as fh:
        if command:
            fh.write(f"\n`{command}`\n")
        if title:
            fh.write(f"\n## {title}\n\n{body}\n")
            if note:
                fh.write(f"\n_{note}_\n")


def write_report(out: Path, text: str) -> Path:
    """Write out/report.md as exactly `text`, atomically, replacing any earlier report there; returns its path.

    For an evaluation that renders its report in one piece (srb `--push`, com-cnn `--pose-error`), so a
    re-run gives the new report alone. `append_report` is for a report built a section per evaluation
    mode (cgail), where a re-run adds its sections after the earlier ones."""
    from charctl.files import atomic_write_text

    path = Path(out) / "report.md"
    atomic_write_text(path, text)
    return path
