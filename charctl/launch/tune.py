"""`charctl tune`: random search over `choice / range / loguniform` overrides on Ray Tune, with ASHA
stopping the trials that trail the others.

Each trial is a `charctl train EXP overrides...` child process (charctl.launch.job) whose run streams
every scalar set it logs (`charctl.runs.METRICS_STREAM_ENV`, one JSON line per `Run.log_scalars`
call, then its metrics.json numbers). The trial reports one result to Tune per logged value of the
metric, so every experiment reports at its own natural pace (PPO iterations, GA generations,
evaluation steps) without knowing about Tune. ASHA stops a trial by stopping its Trainable, whose
`cleanup` sends the child one SIGINT: it writes its checkpoint and exits like a Ctrl-C'd run.

Output, under `<output_root>/tune/<EXP>/<timestamp>/`:
    runs/<EXP>/<run>/   every trial's run directory (config.yaml, tb/, checkpoints/, job.log ...)
    logs/<trial id>/    each trial's stdout, stderr and exit code as its child wrote them
    trials.md|csv|json  one row per trial, best first: state, sampled values, metric, reports, run
    tune.png            the metric against each searched key (hollow: stopped early by ASHA)
    best.yaml           the best trial's overrides as `key: value` lines, with the command line to rerun it
    ray/                Ray Tune's own records
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import signal
import tempfile
import time
from collections import deque
from dataclasses import asdict, dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

from charctl.errors import CharctlError, Interrupted
from charctl.launch.job import (
    INTERRUPT_GRACE_S,
    JOB_LOG,
    STDOUT,
    ChildJob,
    JobSpec,
    exit_code_of,
    outcome_from_logs,
    run_dir_of,
)
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


def trial_class():
    """The Ray Tune Trainable (a function so that importing this module does not import Ray Tune)."""
    from ray import tune

    class CharctlTrial(tune.Trainable):
        """One `charctl train` child; `step` returns its next value of the metric."""

        def setup(self, config: dict, setup: TuneSetup | None = None) -> None:
            self.spec = setup
            fd, stream = tempfile.mkstemp(prefix="charctl-tune-", suffix=".jsonl")
            os.close(fd)
            self.stream = Path(stream)
            self.offset = 0
            self.partial = ""
            self.latest: dict[str, float] = {}
            self.pending: deque[dict] = deque()
            self.run_dir = ""
            self.ended = False
            job = JobSpec(
                setup.experiment,
                tuple(setup.overrides(config)),
                cwd=setup.cwd,
                threads=max(1, int(setup.settings.cpus)),
                env={"CHARCTL_METRICS_STREAM": str(self.stream)},
            )
            self.job = ChildJob(job, log_dir=trial_log_dir(setup, self.trial_id))
            self.job.start()

        def step(self) -> dict:
            while True:
                ended = self.job.poll() is not None
                self._read()
                if len(self.pending) >= 2 or (ended and self.pending and self.job.poll() == 0):
                    result = self.pending.popleft()
                    if ended and not self.pending:
                        self._finish()
                        result.update(done=True, run_finished=True)  # Tune also sets done on a scheduler stop
                    return result
                if ended:
                    outcome = self._finish()
                    if outcome.state != "done":
                        raise TrialFailed(outcome.message)
                    logged = ", ".join(sorted(self.latest)[:12]) or "nothing"
                    raise TrialFailed(f"the run logged no {self.spec.metric!r} (it logged: {logged})")
                time.sleep(0.2)

        def _read(self) -> None:
            """New complete JSON lines of the stream -> pending results (one per value of the metric)."""
            try:
                with open(self.stream, encoding="utf-8") as fh:
                    fh.seek(self.offset)
                    chunk = fh.read()
                    self.offset = fh.tell()
            except OSError:
                return
            lines = (self.partial + chunk).split("\n")
            self.partial = lines.pop()
            for line in filter(None, lines):
                rec = json.loads(line)
                self.run_dir = rec.get("run_dir", self.run_dir)
                scalars = rec.get("scalars", {})
                self.latest.update(scalars)
                if self.spec.metric not in self.latest:
                    continue
                if rec.get("final") and self.pending:  # the run's last numbers belong to its last report
                    self.pending[-1].update(self._snapshot(rec.get("step", 0)))
                elif self.spec.metric in scalars or rec.get("final"):
                    self.pending.append(self._snapshot(rec.get("step", 0)))

        def _snapshot(self, step: int) -> dict:
            keys = (self.spec.metric, *self.spec.report_keys)
            out = {k: self.latest[k] for k in keys if k in self.latest}
            return {**out, "run_step": int(step), "run_dir": self.run_dir}

        def _finish(self):
            if self.ended:
                return self.outcome
            self.ended = True
            self.outcome = self.job.finish()
            self.stream.unlink(missing_ok=True)
            return self.outcome

        def cleanup(self) -> None:
            """Stopped by the scheduler or the driver: one SIGINT, the child writes its checkpoint and exits."""
            if not self.ended:
                self.job.stop()
                self._finish()

    return CharctlTrial


def _trial_dirname(trial) -> str:
    return trial.trial_id


def trial_log_dir(setup: TuneSetup, trial_id: str) -> Path:
    """Where a trial's child logs (stdout, stderr, exit code): `<out>/logs/<trial id>/`."""
    return Path(setup.out_dir) / "logs" / trial_id


def wait_for_children(setup: TuneSetup, trial_ids: list[str], timeout: float = INTERRUPT_GRACE_S) -> None:
    """Tune kills a trial's actor 10 s after the experiment ends, even while its child is still writing
    the checkpoint ASHA asked for; the child carries on by itself. Wait for every started child to
    write its exit code, then make sure its run has its job.log."""
    logs = [trial_log_dir(setup, t) for t in trial_ids]
    started = [d for d in logs if (d / STDOUT).is_file()]
    waiting = [d for d in started if exit_code_of(d) is None]
    if waiting:
        print(f"waiting for {len(waiting)} stopped trial(s) to write their checkpoints ...", flush=True)
    deadline = time.monotonic() + timeout
    while waiting and time.monotonic() < deadline:
        time.sleep(0.5)
        waiting = [d for d in waiting if exit_code_of(d) is None]
    for d in started:
        run_dir = run_dir_of(d)
        if run_dir and not (Path(run_dir) / JOB_LOG).is_file():
            outcome_from_logs(d)


class _View:
    """Driver-side Tune callback: trial states into the live table and the TrialRecords."""

    def __init__(self, setup: TuneSetup, table, stop: _StopRequest | None = None) -> None:
        self.setup = setup
        self.table = table
        self.stop = stop
        self.records: dict[str, TrialRecord] = {}
        self.trials: dict[str, Any] = {}

    def record(self, trial) -> TrialRecord:
        if trial.trial_id not in self.records:
            from charctl.launch.search_space import format_value

            values = {d.name: format_value(trial.config.get(d.name)) for d in self.setup.dims}
            rec = TrialRecord(len(self.records), trial.trial_id, values)
            self.records[trial.trial_id] = rec
            self.trials[trial.trial_id] = trial
            self.table.update(rec.number, label=" ".join(f"{k}={v}" for k, v in values.items()))
        return self.records[trial.trial_id]

    def show(self, rec: TrialRecord) -> None:
        if rec.number >= len(self.table.rows):
            return
        metric = "" if rec.metric is None else f"{rec.metric:.4g}"
        self.table.update(
            rec.number,
            state=rec.state,
            run_dir=rec.run_dir,
            message=rec.message,
            **{self.setup.metric: metric, "reports": str(rec.reports)},
        )

    def started(self, trial) -> None:
        rec = self.record(trial)
        rec.state = "running"
        self.show(rec)

    def result(self, trial, result: dict) -> None:
        rec = self.record(trial)
        rec.state = "running"
        value = result.get(self.setup.metric)
        if isinstance(value, (int, float)) and math.isfinite(value):
            rec.metric = float(value)
        rec.reports = int(result.get("training_iteration", rec.reports))
        rec.run_dir = str(result.get("run_dir", rec.run_dir))
        self.show(rec)

    def completed(self, trial) -> None:
        rec = self.record(trial)
        finished = bool((trial.last_result or {}).get("run_finished"))
        rec.state = "done" if finished else "stopped"
        if not finished:
            by = "Ctrl-C" if self.stop is not None and self.stop.signum else "ASHA"
            rec.message = f"stopped by {by} after {rec.reports} report(s); checkpoint written"
        self.show(rec)

    def errored(self, trial) -> None:
        rec = self.record(trial)
        rec.state = "failed"
        rec.message = trial_error(trial)
        self.show(rec)


def _callback(view: _View):
    """A Tune Callback forwarding trial events to `view` (Tune pickles its run config for restores:
    the view, with its live console, is left out of the pickle)."""
    from ray.tune import Callback

    class _Forward(Callback):
        def __init__(self, view: _View | None) -> None:
            self.view = view

        def __getstate__(self) -> dict:
            return {"view": None}

        def on_trial_start(self, iteration, trials, trial, **info):  # noqa: ARG002
            if self.view is not None:
                self.view.started(trial)

        def on_trial_result(self, iteration, trials, trial, result, **info):  # noqa: ARG002
            if self.view is not None:
                self.view.result(trial, result)

        def on_trial_complete(self, iteration, trials, trial, **info):  # noqa: ARG002
            if self.view is not None:
                self.view.completed(trial)

        def on_trial_error(self, iteration, trials, trial, **info):  # noqa: ARG002
            if self.view is not None:
                self.view.errored(trial)

    return _Forward(view)


def trial_error(trial) -> str:
    """The one-line message of a failed trial (our TrialFailed text, else the error's first line)."""
    err = None
    try:
        err = trial.get_pickled_error() or trial.get_error()
    except Exception:  # storage not readable: fall back to Tune's status text
        err = None
    cause = getattr(err, "cause", None) or err
    if cause is None:
        return str(getattr(trial, "error_msg", "") or "the trial failed")[:300]
    text = str(cause).strip()
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    for line in reversed(lines):  # a traceback's last line names the exception
        if "TrialFailed:" in line:
            return line.split("TrialFailed:", 1)[1].strip()[:300]
    if not lines:
        return type(cause).__name__
    return (lines[-1] if len(lines) > 1 else lines[0])[:300]


# ---------------------------------------------------------------------------- driver
def run_tune(setup: TuneSetup) -> tuple[list[TrialRecord], TrialRecord | None]:
    """Run the search; write the tables, the plot and best.yaml into `setup.out_dir`."""
    from charctl.launch.cluster import cluster_summary, import_tune, ray_session
    from charctl.launch.table import JobTable

    tune = import_tune()
    from ray.tune.schedulers import ASHAScheduler
    from ray.tune.search.basic_variant import BasicVariantGenerator

    out = Path(setup.out_dir)
    labels = ["(not sampled yet)"] * setup.settings.trials
    stop = _StopRequest()
    with ray_session(setup.settings.address, "charctl tune") as ray:
        print(
            f"tune {setup.experiment}: {setup.settings.trials} trial(s), {setup.metric} ({setup.mode}), ASHA; "
            f"Ray: {cluster_summary(ray)}; {setup.settings.cpus:g} CPU per trial -> {out}"
        )
        os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")  # Tune's own progress tables off (verbose=0): ours instead
        columns = (setup.metric, "reports")
        with JobTable(f"tune {setup.experiment}", labels, extra_columns=columns, final_table=False) as table:
            view = _View(setup, table, stop)
            trainable = tune.with_resources(
                tune.with_parameters(trial_class(), setup=setup),
                {"cpu": setup.settings.cpus, "gpu": setup.settings.gpus},
            )
            tuner = tune.Tuner(
                trainable,
                param_space={d.name: d.to_tune() for d in setup.dims},
                tune_config=tune.TuneConfig(
                    metric=setup.metric,
                    mode=setup.mode,
                    num_samples=setup.settings.trials,
                    scheduler=ASHAScheduler(
                        max_t=setup.settings.max_reports or BIG_T,
                        grace_period=setup.settings.grace_period,
                        reduction_factor=4,
                    ),
                    search_alg=BasicVariantGenerator(random_state=setup.settings.seed),
                    trial_dirname_creator=_trial_dirname,
                ),
                run_config=tune.RunConfig(
                    name="ray",
                    storage_path=str(out),
                    verbose=0,
                    callbacks=[_callback(view)],
                    failure_config=tune.FailureConfig(max_failures=0),
                    checkpoint_config=tune.CheckpointConfig(checkpoint_frequency=0, checkpoint_at_end=False),
                ),
            )
            with stop.installed():
                try:
                    tuner.fit()
                except KeyboardInterrupt:  # a second Ctrl-C: Tune gave up on the graceful stop
                    stop.signum = stop.signum or int(signal.SIGINT)
            for trial_id, rec in view.records.items():  # states Tune settled after the last callback
                if rec.state in ("pending", "running"):
                    trial = view.trials[trial_id]
                    if trial.status == "ERROR":
                        view.errored(trial)
                    elif trial.status == "TERMINATED":
                        view.completed(trial)
    wait_for_children(setup, list(view.records))
    records = sorted(view.records.values(), key=lambda r: r.number)
    best = write_outputs(setup, records)
    if stop.signum:
        raise Interrupted(f"interrupted: the trials so far, with their checkpoints, are in {out}", signum=stop.signum)
    return records, best


class _StopRequest:
    """Ctrl-C / SIGTERM during the search: the first asks Tune to stop gracefully (through Tune's own
    SIGUSR1 handler; Tune's SIGINT handler is switched off so that charctl knows it happened): every
    running trial gets its SIGINT and writes its checkpoint. A further one aborts."""

    def __init__(self) -> None:
        self.signum = 0
        self.count = 0

    def __call__(self, signum, frame) -> None:  # noqa: ARG002
        self.count += 1
        self.signum = self.signum or int(signum)
        if self.count > 1 or not hasattr(signal, "SIGUSR1"):
            raise KeyboardInterrupt
        print("\nstopping: every running trial writes its checkpoint (Ctrl-C again to abort)", flush=True)
        os.kill(os.getpid(), signal.SIGUSR1)

    @contextlib.contextmanager
    def installed(self):
        os.environ["TUNE_DISABLE_SIGINT_HANDLER"] = "1"
        old = {}
        try:
            for sig in (signal.SIGINT, signal.SIGTERM):
                old[sig] = signal.signal(sig, self)
        except ValueError:  # not the main thread: Tune's defaults apply
            pass
        try:
            yield self
        finally:
            for sig, handler in old.items():
                signal.signal(sig, handler)


# ---------------------------------------------------------------------------- outputs
def ranked(records: list[TrialRecord], mode: str) -> list[TrialRecord]:
    """Best first: finished trials by metric, then those ASHA stopped, then the rest."""
    order = {"done": 0, "stopped": 1}

    def key(r: TrialRecord):
        value = r.metric if r.metric is not None else math.inf * (1 if mode == "min" else -1)
        return (order.get(r.state, 2), value if mode == "min" else -value, r.number)

    return sorted(records, key=key)


def best_trial(records: list[TrialRecord], mode: str) -> TrialRecord | None:
    rows = [r for r in ranked(records, mode) if r.metric is not None and r.state in ("done", "stopped")]
    return rows[0] if rows else None


def write_outputs(setup: TuneSetup, records: list[TrialRecord]) -> TrialRecord | None:
    """trials.md / .csv / .json, tune.png and best.yaml; returns the best trial."""
    out = Path(setup.out_dir)
    rows = ranked(records, setup.mode)
    keys = [d.name for d in setup.dims]
    table = [_row(r, keys, setup.metric) for r in rows]
    (out / "trials.json").write_text(json.dumps([asdict(r) for r in rows], indent=2) + "\n")
    with open(out / "trials.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(table[0]) if table else ["trial"])
        writer.writeheader()
        writer.writerows(table)
    (out / "trials.md").write_text(markdown_table(setup, table))
    plot(setup, rows, out / "tune.png")
    best = best_trial(records, setup.mode)
    if best is not None:
        write_best(setup, best, out / "best.yaml")
    return best


def _row(r: TrialRecord, keys: list[str], metric: str) -> dict[str, str]:
    return {
        "trial": str(r.number + 1),
        "state": r.state,
        **{k: r.values.get(k, "") for k in keys},
        metric: "" if r.metric is None else f"{r.metric:.6g}",
        "reports": str(r.reports),
        "run_dir": r.run_dir,
        "message": r.message if r.state != "done" else "",
    }


def markdown_table(setup: TuneSetup, table: list[dict[str, str]]) -> str:
    """The trials as a markdown table, best first."""
    head = (
        f"# tune {setup.experiment}: {setup.metric} ({setup.mode}), {len(table)} trial(s)\n\n"
        f"Fixed overrides: `{' '.join(setup.fixed) or '(none)'}`; searched: "
        + ", ".join(f"`{d.key}` {d.kind}" for d in setup.dims)
        + "\n\n"
    )
    if not table:
        return head + "(no trial started)\n"
    cols = [c for c in table[0] if c != "message" or any(r["message"] for r in table)]
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    lines += ["| " + " | ".join(r[c].replace("|", "\\|") for c in cols) + " |" for r in table]
    return head + "\n".join(lines) + "\n"


def write_best(setup: TuneSetup, best: TrialRecord, path: Path) -> None:
    """best.yaml: the best trial's overrides as `key: value` lines, the command line in a comment."""
    import yaml

    overrides = [*setup.fixed, *(f"{d.key}={best.values[d.name]}" for d in setup.dims)]
    mapping = {}
    for o in overrides:
        key, _, value = o.partition("=")
        try:
            mapping[key] = yaml.safe_load(value)
        except yaml.YAMLError:
            mapping[key] = value
    command = f"charctl train {setup.experiment} " + " ".join(_shell_quote(o) for o in overrides)
    header = (
        f"# best of {setup.settings.trials} trial(s) of `charctl tune {setup.experiment}`: {setup.metric} = "
        f"{best.metric:.6g} ({setup.mode}); run {best.run_dir}\n"
        f"# run it again with these overrides:\n#   {command.strip()}\n"
    )
    path.write_text(header + yaml.safe_dump(mapping, default_flow_style=False, sort_keys=False))


def _shell_quote(text: str) -> str:
    import shlex

    return shlex.quote(text)


def plot(setup: TuneSetup, rows: list[TrialRecord], path: Path) -> None:
    """The metric against each searched key: filled = finished, hollow = stopped early, star = best."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dims = list(setup.dims)
    fig, axes = plt.subplots(1, len(dims), figsize=(4.2 * len(dims), 3.4), squeeze=False)
    best = best_trial(rows, setup.mode)
    for ax, dim in zip(axes[0], dims):
        xs_all = [r.values.get(dim.name, "") for r in rows if r.metric is not None]
        numeric = all(_number(x) is not None for x in xs_all)
        cats = list(dict.fromkeys(dim.values)) if dim.kind == "choice" else []
        for state, style in (("done", {"marker": "o"}), ("stopped", {"marker": "o", "facecolors": "none"})):
            pts = [(r.values.get(dim.name, ""), r.metric) for r in rows if r.state == state and r.metric is not None]
            if not pts:
                continue
            xs = [_number(x) if numeric else cats.index(x) if x in cats else 0 for x, _ in pts]
            ax.scatter(xs, [y for _, y in pts], edgecolors="C0", label=state, **style)
        if best is not None:
            x = best.values.get(dim.name, "")
            bx = _number(x) if numeric else cats.index(x) if x in cats else 0
            ax.scatter([bx], [best.metric], marker="*", s=160, color="C3", label="best", zorder=3)
        if not numeric and cats:
            ax.set_xticks(range(len(cats)), cats, rotation=20)
        if dim.log:
            ax.set_xscale("log")
        ax.set_xlabel(dim.name)
        ax.set_ylabel(f"{setup.metric} ({setup.mode})")
        ax.grid(alpha=0.3)
    if axes[0][0].get_legend_handles_labels()[0]:
        axes[0][0].legend(fontsize=8)
    fig.suptitle(f"tune {setup.experiment}: {len(rows)} trial(s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _number(text: str) -> float | None:
    try:
        value = float(text)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None


def make_out_dir(output_root: str | Path, experiment: str) -> Path:
    """`<output_root>/tune/<experiment>/<timestamp>/` (absolute; `_1`, `_2` ... when taken)."""
    from charctl.paths import make_unique_dir

    root = Path(output_root).expanduser().resolve() / "tune" / experiment
    try:
        return make_unique_dir(root, datetime.now().strftime("%Y-%m-%d_%H-%M-%S"))
    except OSError as exc:
        raise CharctlError(f"cannot create the tune folder in {root}: {exc.strerror or exc}") from None
