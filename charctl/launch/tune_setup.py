"""`charctl tune`'s settings and records: what to search, how one trial is launched, what it reported."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from charctl.launch.search_space import Dim

BIG_T = 10**9  # ASHA's max_t when --max-reports is not given: trials end on their own


@dataclass(frozen=True)
class SearchSettings:
    """The search's size and resources (the `charctl tune` options besides the metric)."""

    trials: int = 8
    address: str | None = None  # Ray cluster address; None = a local Ray
    cpus: float = 1.0  # per trial
    gpus: float = 0.0  # per trial
    grace_period: int = 1  # ASHA: reports a trial makes before it can be stopped
    max_reports: int | None = None  # ASHA max_t; None = trials end on their own
    seed: int = 0  # of the random search


@dataclass(frozen=True)
class TuneSetup:
    """Everything a search needs (sent to every trial through the object store)."""

    experiment: str
    fixed: tuple[str, ...]
    dims: tuple[Dim, ...]
    metric: str
    mode: str  # max | min
    out_dir: str  # absolute
    settings: SearchSettings = SearchSettings()
    report_keys: tuple[str, ...] = ()  # further scalars copied into each result (the declared metrics)
    cwd: str = ""

    def overrides(self, config: dict) -> list[str]:
        """The trial's full override list: fixed ones, sampled ones, its output_root."""
        sampled = [d.override(config[d.name]) for d in self.dims]
        return [*self.fixed, *sampled, f"output_root={Path(self.out_dir) / 'runs'}"]


@dataclass
class TrialRecord:
    """One trial as the driver saw it."""

    number: int
    trial_id: str
    values: dict[str, str]  # searched key -> override value
    state: str = "pending"  # running | done | stopped | failed
    metric: float | None = None
    reports: int = 0
    run_dir: str = ""
    message: str = ""


class TrialFailed(RuntimeError):
    """A trial's run ended with an error; the message is its one line."""
