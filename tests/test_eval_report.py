"""charctl.eval.report's Markdown table helpers, exact strings."""

from __future__ import annotations

import pytest

from charctl.eval.report import markdown_grid, markdown_row, markdown_rule, markdown_table


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
