"""`charctl tune`'s live view: the trial table, the Tune callback that feeds it, the one-line error of a
failed trial, and the Ctrl-C / SIGTERM handling of the search."""

from __future__ import annotations

import contextlib
import math
import os
import signal
from typing import Any

from charctl.launch.tune_setup import TrialRecord, TuneSetup


class TuneView:
    """Driver-side Tune callback: trial states into the live table and the TrialRecords."""

    def __init__(self, setup: TuneSetup, table, stop: StopRequest | None = None) -> None:
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


def tune_callback(view: TuneView):
    """A Tune Callback forwarding trial events to `view` (Tune pickles its run config for restores:
    the view, with its live console, is left out of the pickle)."""
    from ray.tune import Callback

    class _Forward(Callback):
        def __init__(self, view: TuneView | None) -> None:
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


class StopRequest:
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
