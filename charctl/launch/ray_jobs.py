"""`charctl train EXP -m ... --launcher ray`: every multirun job as a Ray actor holding its declared
CPUs / GPUs for as long as the job runs, the jobs side by side as far as the cluster's resources go.

The driver validates every job's config first: an invalid job is reported failed with its one-line
message and the valid ones still run. Each job runs `charctl train` as a child process on the node
Ray picks (charctl.launch.job), writing its own run directory under the job's `output_root`, made
absolute here; on a cluster that path must be one every node can write (a shared filesystem). The
driver shows each job's state (pending, running, done, failed, interrupted) and its run directory;
a failed job is reported with its last stderr line (charctl's one-line error) while the others
finish. Ctrl-C (or SIGTERM) on the driver forwards one SIGINT to every running job, which writes its
checkpoint and stops (`interrupted ...; continue with --resume RUN`); jobs not started yet are
cancelled. A third Ctrl-C kills the jobs without waiting.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import time
from dataclasses import dataclass, field
from pathlib import Path

from charctl.errors import CharctlError, Interrupted
from charctl.launch.job import ChildJob, JobSpec, run_to_end

POLL_S = 0.5
GIVE_UP_AFTER = 3  # Ctrl-C presses on the driver: the third kills the jobs without their checkpoints


@dataclass
class JobResult:
    """How one job ended. `state`: done | failed | interrupted | cancelled."""

    index: int
    overrides: list[str]
    state: str
    message: str = ""
    run_dir: str = ""
    exit_code: int | None = None
    started: float = 0.0  # wall-clock time (time.time()) the child started; 0 if it never did
    ended: float = 0.0
    node: str = ""

    @property
    def label(self) -> str:
        return " ".join(self.overrides) or "(defaults)"


@dataclass(frozen=True)
class Resources:
    """What each job declares to Ray (fractions allowed, e.g. 0.5 GPU)."""

    cpus: float = 1.0
    gpus: float = 0.0

    def check(self) -> None:
        if not self.cpus > 0:
            raise CharctlError(f"--cpus-per-job must be > 0, got {self.cpus:g}")
        if self.gpus < 0:
            raise CharctlError(f"--gpus-per-job must be >= 0, got {self.gpus:g}")

    @property
    def threads(self) -> int:
        return max(1, int(self.cpus))


class JobActor:
    """Runs one job (as a Ray actor, so the driver can ask for its state and stop it while it runs)."""

    def __init__(self, spec: JobSpec) -> None:
        self.spec = spec
        self.job: ChildJob | None = None
        self.stop_requested = False
        self.node = socket.gethostname()

    def run(self) -> dict:
        """Start the child and wait for it; the outcome as a dict (JobResult fields)."""
        if self.stop_requested:
            return {"state": "cancelled", "message": "cancelled before it started", "node": self.node}
        self.job = ChildJob(self.spec)
        started = time.time()
        outcome = run_to_end(self.job, lambda: self.stop_requested)
        return {
            "state": outcome.state,
            "message": outcome.message,
            "run_dir": outcome.run_dir,
            "exit_code": outcome.exit_code,
            "started": started,
            "ended": time.time(),
            "node": self.node,
        }

    def status(self) -> dict:
        """'pending' until the child starts, then 'running' with its run directory once known."""
        if self.job is None:
            return {"state": "pending"}
        return {"state": "running", "run_dir": self.job.run_dir, "node": self.node}

    def stop(self) -> None:
        """Forward one SIGINT to the child (or make sure it never starts)."""
        self.stop_requested = True
        if self.job is not None:
            self.job.interrupt()


# ---------------------------------------------------------------------------- driver
def prepare_jobs(experiment: str, jobs: list[list[str]], resources: Resources) -> list[JobSpec | str]:
    """Per job: its JobSpec (config validated, output_root made absolute) or its one-line error."""
    from charctl.config import compose_config
    from charctl.experiments import load
    from charctl.paths import check_writable_dir

    schema = load(experiment).config_class()
    out: list[JobSpec | str] = []
    for job in jobs:
        try:
            cfg = compose_config(experiment, job, schema)
            root = Path(str(cfg.output_root)).expanduser().resolve()
            check_writable_dir(root, "output_root")
        except CharctlError as exc:
            out.append(str(exc))
            continue
        overrides = [o for o in job if o.split("=", 1)[0].lstrip("+~") != "output_root"]
        out.append(
            JobSpec(
                experiment,
                (*overrides, f"output_root={root}"),
                cwd=os.getcwd(),
                threads=resources.threads,
            )
        )
    return out


def run_on_ray(
    experiment: str, jobs: list[list[str]], address: str | None = None, resources: Resources | None = None
) -> list[JobResult]:
    """Run every job on Ray and wait for all of them; one JobResult per job, in order."""
    from charctl.launch.cluster import cluster_summary, ray_session
    from charctl.launch.table import JobTable

    resources = resources or Resources()
    resources.check()
    specs = prepare_jobs(experiment, jobs, resources)
    results: dict[int, JobResult] = {}
    for i, spec in enumerate(specs):
        if isinstance(spec, str):
            results[i] = JobResult(i, jobs[i], "failed", spec, exit_code=2)
    labels = job_labels(jobs)
    valid = {i: s for i, s in enumerate(specs) if isinstance(s, JobSpec)}
    with ray_session(address) as ray:
        if valid:
            _check_fits(ray, resources)
        print(f"{experiment}: {len(jobs)} job(s) on Ray ({cluster_summary(ray)}; {_per_job(resources)} per job)")
        with JobTable(f"{experiment} multirun", labels) as view:
            for i, res in results.items():
                view.update(i, state=res.state, message=res.message)
            driver = _Driver(ray, view, resources)
            results.update(driver.run(valid, jobs))
    return [results[i] for i in range(len(jobs))]


def job_labels(jobs: list[list[str]]) -> list[str]:
    """Each job's overrides that differ between the jobs (all of them for a single job)."""
    if len(jobs) < 2:
        return [" ".join(job) or "(defaults)" for job in jobs]
    common = set(jobs[0]).intersection(*map(set, jobs[1:]))
    return [" ".join(o for o in job if o not in common) or "(defaults)" for job in jobs]


def _per_job(resources: Resources) -> str:
    return f"{resources.cpus:g} CPU" + (f", {resources.gpus:g} GPU" if resources.gpus else "")


def _check_fits(ray, resources: Resources) -> None:
    """A job that asks for more than the whole cluster has would wait forever: a one-line error."""
    total = ray.cluster_resources()
    for name, want in (("CPU", resources.cpus), ("GPU", resources.gpus)):
        have = float(total.get(name, 0))
        if want > have:
            flag = f"--{name.lower()}s-per-job"
            raise CharctlError(f"{flag} {want:g} but the Ray cluster has {have:g} {name}(s) in all")


@dataclass
class _Driver:
    """Submits the actors, polls their states into the view, handles Ctrl-C."""

    ray: object
    view: object
    resources: Resources
    actors: dict[int, object] = field(default_factory=dict)
    presses: int = 0
    signum: int = 0
    pending: int = 0  # signal presses not yet acted on

    def run(self, valid: dict[int, JobSpec], jobs: list[list[str]]) -> dict[int, JobResult]:
        ray = self.ray
        cls = ray.remote(JobActor).options(
            num_cpus=self.resources.cpus, num_gpus=self.resources.gpus, max_concurrency=4
        )
        refs = {}
        for i, spec in valid.items():
            self.actors[i] = cls.remote(spec)
            refs[i] = self.actors[i].run.remote()
        status = {i: self.actors[i].status.remote() for i in refs}
        results: dict[int, JobResult] = {}
        with self._signals():
            while refs:
                self._poll(refs, status, results, jobs)
                while self.pending > 0:  # presses that arrived during the poll, handled between Ray calls
                    self.pending -= 1
                    self._on_interrupt()
        if self.signum:
            self._raise_interrupted(results)
        return results

    def _poll(self, refs: dict, status: dict, results: dict, jobs: list[list[str]]) -> None:
        ray = self.ray
        done, _ = ray.wait(list(refs.values()), num_returns=len(refs), timeout=POLL_S)
        for i in [i for i, r in refs.items() if r in done]:
            results[i] = self._result(i, refs[i], jobs[i])
            del refs[i]  # only now: a Ctrl-C in between leaves the job to the next poll
            status.pop(i, None)
            self.view.update(i, state=results[i].state, run_dir=results[i].run_dir, message=results[i].message)
            with contextlib.suppress(Exception):
                ray.kill(self.actors.pop(i))  # its CPUs / GPUs go to the next pending job now
        if status:
            ready, _ = ray.wait(list(status.values()), num_returns=len(status), timeout=0)
            for i in [i for i, r in status.items() if r in ready]:
                try:
                    st = ray.get(status[i])
                except Exception:  # the actor is gone; its run() reference says why
                    status.pop(i)
                    continue
                msg = "stopping: writing its checkpoint" if self.presses and st["state"] == "running" else ""
                self.view.update(i, state=st["state"], run_dir=st.get("run_dir", ""), message=msg)
                status[i] = self.actors[i].status.remote()

    def _result(self, i: int, ref, overrides: list[str]) -> JobResult:
        try:
            d = self.ray.get(ref)
        except Exception as exc:  # the worker or its node died
            line = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
            state = "interrupted" if self.presses >= GIVE_UP_AFTER else "failed"
            return JobResult(i, overrides, state, f"the Ray worker died: {line}")
        return JobResult(i, overrides, **d)

    def _on_interrupt(self) -> None:
        self.presses += 1
        self.signum = self.signum or int(signal.SIGINT)
        if self.presses == 1:
            print("\nstopping: every running job writes its checkpoint (press Ctrl-C twice more to kill them)")
            for actor in self.actors.values():
                actor.stop.remote()
        elif self.presses < GIVE_UP_AFTER:
            print("\nstill stopping (press Ctrl-C once more to kill the jobs without their checkpoints)")
        else:
            for actor in self.actors.values():
                with contextlib.suppress(Exception):
                    self.ray.kill(actor)

    @contextlib.contextmanager
    def _signals(self):
        """While the jobs run, Ctrl-C (SIGINT) and SIGTERM on the driver only count a press; the poll loop
        acts on it between Ray calls. (Raised as KeyboardInterrupt, a press could land inside one of
        Ray's own calls and leave its client half-way; Ray's SIGTERM handler would just exit.)"""

        def on_signal(signum, frame) -> None:  # noqa: ARG001
            self.signum = self.signum or int(signum)
            self.pending += 1

        try:
            old = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
        except ValueError:  # not the main thread
            yield
            return
        try:
            yield
        finally:
            for sig, handler in old.items():
                signal.signal(sig, handler)

    def _raise_interrupted(self, results: dict[int, JobResult]) -> None:
        stopped = [r for r in results.values() if r.state == "interrupted" and r.run_dir]
        resume = "; ".join(f"--resume {r.run_dir}" for r in stopped)
        raise Interrupted(
            f"interrupted: {len(stopped)} job(s) stopped with a checkpoint"
            + (f"; continue with {resume}" if resume else ""),
            signum=self.signum,
        )


def summary_error(results: list[JobResult]) -> CharctlError | None:
    """The driver's final one-line error when any job failed (None when every job is done)."""
    failed = [r for r in results if r.state != "done"]
    if not failed:
        return None
    first = failed[0]
    return CharctlError(
        f"{len(failed)} of {len(results)} job(s) did not finish (first: job {first.index + 1}, "
        f"{first.label}: {first.message})"
    )
