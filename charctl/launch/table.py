"""The driver's view of its jobs: a live rich table on a terminal; elsewhere (pipes, CI) one plain line
per state change. Either way the final table is printed when the view closes.

States: pending -> running -> done | failed | interrupted | cancelled (never started) | stopped
(ended early by the tuner's scheduler).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field

STYLES = {
    "pending": "dim",
    "running": "yellow",
    "done": "green",
    "failed": "bold red",
    "interrupted": "magenta",
    "cancelled": "dim",
    "stopped": "cyan",
}
FINAL = ("done", "failed", "interrupted", "cancelled", "stopped")


@dataclass
class Row:
    """One job: its label (the overrides), state, run directory, message and extra columns."""

    label: str
    state: str = "pending"
    run_dir: str = ""
    message: str = ""
    extra: dict[str, str] = field(default_factory=dict)


class JobTable:
    """`with JobTable(title, labels) as view: view.update(i, state="running", run_dir=...)`."""

    def __init__(
        self, title: str, labels: list[str], extra_columns: tuple[str, ...] = (), final_table: bool = True
    ) -> None:
        from rich.console import Console

        self.title = title
        self.rows = [Row(label) for label in labels]
        self.extra_columns = extra_columns
        self.final_table = final_table
        self.console = Console(highlight=False)
        self.interactive = self.console.is_terminal and sys.stdout.isatty()
        self._live = None

    def __enter__(self) -> JobTable:
        if self.interactive:
            from rich.live import Live

            self._live = Live(self.render(), console=self.console, refresh_per_second=4, transient=True)
            self._live.start()
        return self

    def __exit__(self, *exc) -> None:
        if self._live is not None:
            self._live.stop()
            self._live = None
        if self.final_table:
            self.console.print(self.render())

    def update(self, index: int, **fields: str) -> None:
        """Change row `index` (state, run_dir, message, or an extra column by name)."""
        row = self.rows[index]
        old_state = row.state
        for key, value in fields.items():
            if key in ("state", "run_dir", "message", "label"):
                setattr(row, key, value)
            else:
                row.extra[key] = value
        if self._live is not None:
            self._live.update(self.render())
        elif row.state != old_state:
            self._plain(index)

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for row in self.rows:
            out[row.state] = out.get(row.state, 0) + 1
        return out

    def _plain(self, index: int) -> None:
        row = self.rows[index]
        parts = [f"[{index + 1}/{len(self.rows)}]", f"{row.state:<11}", row.label]
        if row.run_dir:
            parts.append(row.run_dir)
        if row.state in ("failed", "interrupted", "stopped") and row.message:
            parts.append(f"- {row.message}")
        print("  ".join(parts), flush=True)

    def render(self):
        """The table as a rich renderable."""
        from rich.table import Table
        from rich.text import Text

        counts = ", ".join(f"{n} {s}" for s, n in self.counts().items())
        table = Table(title=Text(f"{self.title} ({counts})"), title_justify="left", expand=False)
        table.add_column("#", justify="right")
        table.add_column("job")
        table.add_column("state")
        for col in self.extra_columns:
            table.add_column(col, justify="right")
        table.add_column("run directory / message", overflow="fold")
        for i, row in enumerate(self.rows):
            detail = row.run_dir
            if row.message and row.state in ("failed", "interrupted", "stopped", "cancelled"):
                detail = f"{detail}\n{row.message}" if detail else row.message
            cells = [Text(str(i + 1)), Text(row.label), Text(row.state, style=STYLES.get(row.state, ""))]
            cells += [Text(row.extra.get(col, "")) for col in self.extra_columns]
            table.add_row(*cells, Text(detail))
        return table
