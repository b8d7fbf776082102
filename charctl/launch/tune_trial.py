"""`charctl tune`'s Ray Tune Trainable: one `charctl train` child per trial, its logs, and waiting for the
children after a stop."""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections import deque
from pathlib import Path

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
from charctl.launch.tune_setup import TrialFailed, TuneSetup


def trial_class():
    """The Ray Tune Trainable (a function so that importing this module does not import Ray Tune).

    It is long because the class must be defined inside it, after the lazy `from ray import tune`;
    its methods are each short."""
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


def trial_dirname(trial) -> str:
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
