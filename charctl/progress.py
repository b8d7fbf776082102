"""Rich progress bars for long loops (training iterations, sweeps, rollouts)."""

from __future__ import annotations

import sys
import time


def eta_text(remaining: float, rate: float) -> str:
    """Time left for `remaining` units at `rate` units/s, as the plain line shows it: "ETA 2h 05m", "ETA 4m 10s",
    "ETA 9s"; "ETA ?" before any rate is measured."""
    if rate <= 0.0:
        return "ETA ?"
    s = int(round(max(remaining, 0.0) / rate))
    h, m = divmod(s // 60, 60)
    if h:
        return f"ETA {h}h {m:02d}m"
    return f"ETA {m}m {s % 60:02d}s" if m else f"ETA {s}s"


class TrainingProgress:
    """A progress bar over `total` samples (or generations, frames ...) with rate and ETA.

    `update(n, **stats)` advances by n and shows the latest stats (e.g. r_S=0.61) on the bar.
    On a non-terminal (CI, pipes, nohup) it prints one plain line every `plain_every` seconds instead, with the
    same rate and ETA (`eta_text`).
    """

    def __init__(self, total: float, description: str, unit: str = "samples", plain_every: float = 10.0):
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self.total = total
        self.unit = unit
        self.description = description
        self.start = time.perf_counter()
        self.done = 0.0
        self.resumed_from = 0.0  # work done before this session (a resumed run): not part of the rate
        self.interactive = sys.stderr.isatty()
        self.plain_every = plain_every
        self._last_plain = 0.0
        self.progress = None
        if self.interactive:
            self.progress = Progress(
                TextColumn("[bold]{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("{task.fields[rate]}"),
                TimeElapsedColumn(),
                TextColumn("ETA"),
                TimeRemainingColumn(),
                TextColumn("{task.fields[stats]}"),
                transient=False,
            )
            self.task = self.progress.add_task(description, total=total, rate="", stats="")

    def __enter__(self) -> TrainingProgress:
        if self.progress is not None:
            self.progress.start()
        return self

    def __exit__(self, *exc) -> None:
        if self.progress is not None:
            self.progress.stop()
        else:
            self._plain(force=True)

    @property
    def rate(self) -> float:
        """Units per second in this session (work done before a resume is not counted)."""
        return (self.done - self.resumed_from) / max(time.perf_counter() - self.start, 1e-9)

    def resume_at(self, done: float) -> None:
        """Start the bar at `done` (a resumed run) without counting it in the rate."""
        self.resumed_from = done
        self.update(done)

    def update(self, n: float = 1, **stats: float) -> None:
        self.done += n
        text = "  ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in stats.items())
        self._stats = text
        if self.progress is not None:
            self.progress.update(self.task, advance=n, rate=f"{self.rate:,.0f} {self.unit}/s", stats=text)
        else:
            self._plain()

    def _plain(self, force: bool = False) -> None:
        now = time.perf_counter()
        if force or now - self._last_plain >= self.plain_every:
            self._last_plain = now
            pct = 100.0 * self.done / max(self.total, 1e-9)
            print(
                f"{self.description}: {self.done:,.0f}/{self.total:,.0f} {self.unit} "
                f"({pct:.0f}%), {self.rate:,.0f} {self.unit}/s, {eta_text(self.total - self.done, self.rate)}  "
                f"{getattr(self, '_stats', '')}",
                file=sys.stderr,
                flush=True,
            )
