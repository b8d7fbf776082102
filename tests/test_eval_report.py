"""charctl.eval.report's Markdown table helpers, exact strings; report.md written whole or appended to."""

from __future__ import annotations

import pytest

from charctl.eval.report import (
    append_report,
    markdown_grid,
    markdown_row,
    markdown_rule,
    markdown_table,
    write_report,
)


def test_markdown_rule_aligns_each_column_and_pads_with_plain_ones():
    assert markdown_rule(3) == "|---|---|---|"
    assert markdown_rule(5, "-lrc") == "|---|:---|---:|:---:|---|"


@pytest.mark.parametrize("align", ["rrrr", "x"])
def test_markdown_rule_rejects_too_many_or_unknown_letters(align):
    with pytest.raises(ValueError, match="align"):
        markdown_rule(3, align)


def test_markdown_grid_writes_header_rule_and_rows_of_cells():
    table = markdown_grid(["clip", "speed (m/s)", "ok"], [["walk", "1.20", None], ["run", 3, ""]], align="-rc")
    assert table == (
        "| clip | speed (m/s) | ok |\n"  # a header, no index column
        "|---|---:|:---:|\n"
        "| walk | 1.20 | None |\n"  # cells as str(), as markdown_row writes them
        "| run | 3 |  |"
    )
    assert markdown_grid(["a"], []) == "| a |\n|---|"


def test_markdown_table_unchanged_by_the_shared_rule():
    rows = {"walk": {"error": 0.12, "falls": 0}, "run": {"error": float("nan")}}
    assert markdown_table(rows, ["error", "falls"]) == (
        "| | error | falls |\n|---|---|---|\n| walk | 0.120 | 0 |\n| run | nan | - |"
    )
    assert markdown_row(["a", 1]) == "| a | 1 |"


def test_write_report_writes_the_text_exactly_and_replaces_an_earlier_report(tmp_path):
    """srb / com-cnn evaluations: report.md is the rendered text, byte for byte (as the Path.write_text they
    had), and a re-run replaces it; append_report (cgail's sections) keeps what was there."""
    text = "# srb reproduction report\n\n| a | b |\n|---|---|\n| 1 | é |\n"
    path = write_report(tmp_path, text)
    assert path == tmp_path / "report.md"
    assert path.read_text() == text
    (tmp_path / "plain.md").write_text(text)
    assert path.read_bytes() == (tmp_path / "plain.md").read_bytes()
    write_report(tmp_path, "# second run\n")
    assert path.read_text() == "# second run\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain.md", "report.md"]  # no temporary file left
    append_report(tmp_path, "Table", "| x |", None)
    assert path.read_text() == "# second run\n\n## Table\n\n| x |\n"
