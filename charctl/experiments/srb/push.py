"""Push-robustness protocol (paper §9, Table 1), independent of the simulator it is applied to.

The protocol is a list of `PushCase`s and K trials per case. Any simulator takes part through one
callable, `simulate_case(case, seed) -> survived` (or a batched `simulate_batch(list of (case,
seed)) -> list of survived`); `run_push_study` runs every (case, trial), and `PushTable` turns the
outcomes into survival rates per cell (a cell = one force and duration, pooled over directions and
gait phases), a markdown table and a PNG, side by side for several simulators.

"Impulse" semantics (decision, docs/srb.md): the paper's "N newton impulse" is a constant force
of N newtons held for `impulse_duration` = 0.2 s (an impulse of 0.2 N N s). With 0.2 s the paper's
two statements about the full-body baseline agree: it falls at 200 N (x 0.2 s = 40 N s) and at
100 N held 0.4 s (40 N s) but survives 100 N held 0.3 s (30 N s).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from charctl.eval.report import markdown_grid, write_json

WALK_CYCLE_S = 38 / 30.00120004800192  # one cycle of the shipped walk clip (38 frames at its 30 fps)


@dataclass(frozen=True)
class PushCase:
    """One push condition. Every simulator must apply it exactly like this:

    kind          "impulse" (force sweep at a fixed short duration), "sustained" (Table 1:
                  fixed force, duration sweep) or "control" (force 0: does the character walk the
                  whole episode unpushed?). A label only; the physics is in the fields below.
    force_n       magnitude (newtons) of a constant horizontal force applied at the body's centre
                  of mass (SRB: the box's COM; full body: the root/pelvis body, e.g. MuJoCo
                  xfrc_applied on the root) during the push window. No torque is applied.
    duration_s    length (seconds) of the push window. Windows shorter than a control step
                  deliver exactly force_n * duration_s (SRB: the force is scaled by the overlap
                  of the window with each step; a physics-rate simulator applies it per substep).
    direction_deg direction of the force in the character's heading frame at the push onset,
                  degrees, rotation about world +y (up) from the heading's forward axis:
                  0 = forward (+x of the heading frame), 90 = to the character's left,
                  180 = backward, 270 = to the right. World direction =
                  R_y(heading + direction) (1, 0, 0) = (cos a, 0, -sin a), a = heading + direction;
                  it is fixed in the world for the whole window.
    phase         gait phase in [0, 1) of the walk cycle at the push onset (0 = frame 0 of the
                  walk clip). A simulator that tracks the reference cycle (SRB) starts the push
                  at the first control step after settle_s whose reference phase has reached
                  `phase`; one without a phase variable (an AMP policy) starts an episode from
                  walk frame 0 and pushes at start_s = settle_s + phase * cycle_s.
    settle_s      seconds of unperturbed walking before the push window can open.
    observe_s     seconds after the push window closes the character must still be up.
    cycle_s       duration (s) of one walk cycle, for the time-based phase above.

    Survived = the simulator's fall criterion never triggers from the start of the episode until
    observe_s after the window closes (SRB: paper §5.3's termination rules, COM height and tilt;
    full body: its own early-termination rule, e.g. a non-foot body touching the ground).
    The trial seed may randomise the initial state; it must not change the case.
    """

    kind: str
    force_n: float
    duration_s: float
    direction_deg: float
    phase: float
    settle_s: float = 1.0
    observe_s: float = 2.0
    cycle_s: float = WALK_CYCLE_S

    @property
    def impulse_ns(self) -> float:
        return self.force_n * self.duration_s

    @property
    def start_s(self) -> float:
        """Push onset for the time-based phase convention."""
        return self.settle_s + self.phase * self.cycle_s

    @property
    def total_s(self) -> float:
        """Upper bound of the episode length (s): settle + one cycle to reach the phase + window + observe."""
        return self.settle_s + self.cycle_s + self.duration_s + self.observe_s

    def direction_world(self, heading: np.ndarray) -> np.ndarray:
        """(..., 3) unit force direction in the world for heading angles (radians about +y)."""
        a = np.asarray(heading, dtype=float) + math.radians(self.direction_deg)
        return np.stack([np.cos(a), np.zeros_like(a), -np.sin(a)], axis=-1)


def make_cases(push_cfg) -> list[PushCase]:
    """A no-push control (per direction x phase: the same episode with force 0), the impulse sweep
    (forces x directions x phases at impulse_duration) and Table 1's sustained sweep
    (sustained_force for each duration x directions x phases)."""
    p = push_cfg
    common = dict(settle_s=float(p.settle), observe_s=float(p.observe))
    grid = [(float(d), float(ph)) for d in p.directions for ph in p.phases]
    cases = [PushCase("control", 0.0, float(p.impulse_duration), d, ph, **common) for d, ph in grid]
    cases += [
        PushCase("impulse", float(f), float(p.impulse_duration), d, ph, **common) for f in p.forces for d, ph in grid
    ]
    cases += [
        PushCase("sustained", float(p.sustained_force), float(t), d, ph, **common)
        for t in p.durations
        for d, ph in grid
    ]
    return cases


SimulateCase = Callable[[PushCase, int], bool]
SimulateBatch = Callable[[list[tuple[PushCase, int]]], list[bool]]


def run_push_study(
    simulate_case: SimulateCase | None,
    cases: Sequence[PushCase],
    trials: int,
    seed: int = 0,
    simulate_batch: SimulateBatch | None = None,
    label: str = "",
    progress: bool = True,
) -> PushTable:
    """Run K = `trials` trials of every case; trial k uses seed `seed + k` for every case (paired trials).

    Give `simulate_case` (called once per case and trial) or `simulate_batch` (called once with
    every (case, seed) pair; a simulator that can step many episodes together)."""
    if (simulate_case is None) == (simulate_batch is None):
        raise ValueError("give exactly one of simulate_case and simulate_batch")
    jobs = [(c, seed + k) for c in cases for k in range(trials)]
    if simulate_batch is not None:
        results = [bool(r) for r in simulate_batch(jobs)]
    else:
        results = []
        from charctl.progress import TrainingProgress

        with TrainingProgress(len(jobs), f"push study {label}".strip(), unit="trials") as bar:
            for case, s in jobs:
                results.append(bool(simulate_case(case, s)))
                bar.update(1)
    if len(results) != len(jobs):
        raise ValueError(f"the simulator returned {len(results)} outcomes for {len(jobs)} trials")
    return PushTable(label=label, cases=list(cases), outcomes=np.array(results, dtype=bool).reshape(len(cases), trials))


@dataclass
class PushTable:
    """Outcomes (cases x trials) of one simulator and the survival statistics built from them."""

    label: str
    cases: list[PushCase]
    outcomes: np.ndarray  # (n_cases, K) bool
    meta: dict = field(default_factory=dict)

    def cells(self) -> list[dict]:
        """Survival per cell (kind, force, duration), pooled over directions, phases and trials."""
        groups: dict[tuple, list[int]] = {}
        for i, c in enumerate(self.cases):
            groups.setdefault((c.kind, c.force_n, c.duration_s), []).append(i)
        rows = []
        for (kind, force, dur), idx in groups.items():
            o = self.outcomes[idx]
            rows.append(
                {
                    "kind": kind,
                    "force_n": force,
                    "duration_s": dur,
                    "impulse_ns": force * dur,
                    "survival": float(o.mean()),
                    "trials": int(o.size),
                }
            )
        return rows

    def by_direction(self) -> list[dict]:
        """Survival per (cell, direction), pooled over phases and trials."""
        groups: dict[tuple, list[int]] = {}
        for i, c in enumerate(self.cases):
            groups.setdefault((c.kind, c.force_n, c.duration_s, c.direction_deg), []).append(i)
        return [
            {"kind": k, "force_n": f, "duration_s": d, "direction_deg": a, "survival": float(self.outcomes[idx].mean())}
            for (k, f, d, a), idx in groups.items()
        ]

    def survival(self, kind: str, force: float, duration: float) -> float:
        for r in self.cells():
            if r["kind"] == kind and math.isclose(r["force_n"], force) and math.isclose(r["duration_s"], duration):
                return r["survival"]
        return float("nan")

    def largest_survived(self, rate: float = 0.5) -> dict:
        """Largest impulse-sweep force with survival >= `rate`, largest with survival 1, and the
        smallest force with any fall (None where no such force)."""
        imp = sorted((r for r in self.cells() if r["kind"] == "impulse"), key=lambda r: r["force_n"])
        ok = [r["force_n"] for r in imp if r["survival"] >= rate]
        full = [r["force_n"] for r in imp if r["survival"] >= 1.0]
        fails = [r["force_n"] for r in imp if r["survival"] < 1.0]
        return {
            "largest_force_rate": max(ok) if ok else None,
            "rate": rate,
            "largest_force_all_survived": max(full) if full else None,
            "first_force_with_fall": min(fails) if fails else None,
        }

    def to_dict(self) -> dict:
        return {
            "label": self.label,
            "cases": [asdict(c) for c in self.cases],
            "outcomes": self.outcomes.astype(int).tolist(),
            "cells": self.cells(),
            "by_direction": self.by_direction(),
            "meta": self.meta,
        }


# ---------------------------------------------------------------------------- reporting
def comparison_markdown(
    tables: Sequence[PushTable | None], labels: Sequence[str], rate: float = 0.5, missing_note: str = ""
) -> str:
    """Markdown: one row per cell, one survival column per simulator (— where a table is missing)."""
    present = [t for t in tables if t is not None]
    if not present:
        return "no push results\n"
    ref = present[0]
    header = ["push", "impulse (N s)", *labels]
    lines = []
    for kind, title in (
        ("control", "no push (control: the same episodes unpushed)"),
        ("impulse", "impulse sweep"),
        ("sustained", "sustained (Table 1)"),
    ):
        rows = [r for r in ref.cells() if r["kind"] == kind]
        if not rows:
            continue
        body = [_comparison_row(kind, r, tables) for r in rows]
        lines.append(f"\n**{title}** — survival rate over directions x phases x trials\n\n")
        lines.append(markdown_grid(header, body) + "\n")
    summary = ["\n**largest survived impulse-sweep force**\n"]
    for t, name in zip(tables, labels):
        if t is None:
            summary.append(f"- {name}: missing{(' (' + missing_note + ')') if missing_note else ''}\n")
            continue
        ls = t.largest_survived(rate)
        summary.append(
            f"- {name}: survival >= {rate:g} up to {_fmt_force(ls['largest_force_rate'])}; all trials survived up to "
            f"{_fmt_force(ls['largest_force_all_survived'])}; first fall at {_fmt_force(ls['first_force_with_fall'])}\n"
        )
    return "".join(lines) + "".join(summary)


def _comparison_row(kind: str, r: dict, tables: Sequence[PushTable | None]) -> list[str]:
    """One row of `comparison_markdown`: the cell `r` (of the first table) named, its impulse, then each
    table's survival there (— where a table is missing)."""
    cells = [f"{t.survival(kind, r['force_n'], r['duration_s']):.2f}" if t is not None else "—" for t in tables]
    name = "no push" if kind == "control" else f"{r['force_n']:.0f} N for {r['duration_s']:g} s"
    return [name, f"{r['impulse_ns']:g}", *cells]


def _fmt_force(f) -> str:
    return "none" if f is None else f"{f:.0f} N"


def plot_comparison(tables: Sequence[PushTable | None], labels: Sequence[str], path: str | Path) -> Path:
    """PNG: survival vs force (impulse sweep) and survival vs duration (sustained), one line per simulator."""
    from charctl.viz.plots import new_figure, save_figure

    fig, axes = new_figure(1, 2, figsize=(11, 4))
    for t, name in zip(tables, labels):
        if t is None:
            continue
        imp = sorted((r for r in t.cells() if r["kind"] == "impulse"), key=lambda r: r["force_n"])
        sus = sorted((r for r in t.cells() if r["kind"] == "sustained"), key=lambda r: r["duration_s"])
        if imp:
            axes[0].plot([r["force_n"] for r in imp], [r["survival"] for r in imp], "o-", label=name)
        if sus:
            axes[1].plot([r["duration_s"] for r in sus], [r["survival"] for r in sus], "s-", label=name)
    ref = next((t for t in tables if t is not None), None)
    dur = next((r["duration_s"] for r in ref.cells() if r["kind"] == "impulse"), None) if ref else None
    force = next((r["force_n"] for r in ref.cells() if r["kind"] == "sustained"), None) if ref else None
    axes[0].set_xlabel(f"push force (N), held {dur:g} s" if dur else "push force (N)")
    axes[1].set_xlabel(f"duration (s) of a {force:g} N push" if force else "duration (s)")
    missing = [n for t, n in zip(tables, labels) if t is None]
    for ax in axes:
        ax.set_ylabel("survival rate")
        ax.set_ylim(-0.05, 1.05)
        ax.grid(alpha=0.3)
        ax.legend(title=("missing: " + ", ".join(missing)) if missing else None)
    axes[0].set_title("impulse sweep")
    axes[1].set_title("Table 1: sustained push")
    return save_figure(fig, path)


def save_tables(tables: dict[str, PushTable | None], path: str | Path) -> Path:
    """Every table's `to_dict()` (null where missing) by name, as JSON at `path` (charctl.eval.report.write_json)."""
    path = Path(path)
    write_json(path, {k: (v.to_dict() if v is not None else None) for k, v in tables.items()})
    return path


def window_fraction(t0: np.ndarray, dt: float, start: np.ndarray, duration: np.ndarray) -> np.ndarray:
    """Fraction of the step [t0, t0 + dt) covered by the push window [start, start + duration)."""
    overlap = np.minimum(t0 + dt, start + duration) - np.maximum(t0, start)
    return np.clip(overlap, 0.0, dt) / dt


def iter_chunks(items: list, size: int) -> Iterable[list]:
    for i in range(0, len(items), size):
        yield items[i : i + size]
