"""One training as a child process: charctl's own CLI, `charctl train EXP overrides...`, started as
`python -c "...; child_main(main)" train EXP overrides...` (the CLI's `main` behind `child_main`).

The child behaves exactly as on the command line: its checkpoints, its one-line `error: ...` and its
exit code (0, 2 bad input, 3 diverged, 130 / 143 interrupted). It runs in its own session, so a
Ctrl-C typed at the terminal reaches only the driver, which forwards a single SIGINT (`interrupt`);
on Linux it also gets SIGTERM should the process that started it die (a killed Ray worker), so it
still writes its checkpoint. Its stdout, stderr and exit code go to a log folder (private and
temporary unless given); `<run_dir>/job.log` keeps them once it has ended.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

RUN_DIR_PREFIX = "run directory: "  # printed by charctl.commands.train for every new run
JOB_LOG = "job.log"
STDOUT, STDERR, STATUS, COMMAND = "stdout.log", "stderr.log", "exit_code", "command"  # a job's log folder
INTERRUPT_GRACE_S = 300.0  # after SIGINT: time to finish the iteration and write the checkpoint
_PR_SET_PDEATHSIG = 1
_PARENT_ENV = "CHARCTL_LAUNCH_PARENT"
_STATUS_ENV = "CHARCTL_LAUNCH_STATUS"  # where the child writes its exit code as it ends
# the child's entry point: `charctl` itself, with its signals as on a command line (child_main)
_BOOT = "from charctl.launch.job import child_main; from charctl.cli import main; child_main(main)"


@dataclass(frozen=True)
class JobSpec:
    """What to run and where: the same command line on any node of the cluster."""

    experiment: str
    overrides: tuple[str, ...]
    cwd: str = ""  # the driver's working directory (used when it exists on this node)
    threads: int = 1  # OMP / MKL threads of the child (its share of the CPUs)
    env: dict[str, str] = field(default_factory=dict)

    def argv(self) -> list[str]:
        """`python -c BOOT train EXP overrides...`: charctl's CLI behind `child_main`."""
        return [sys.executable, "-c", _BOOT, "train", self.experiment, *self.overrides]

    def command_line(self) -> str:
        return " ".join(["charctl", "train", self.experiment, *self.overrides])


@dataclass
class Outcome:
    """How a child ended. `state`: done | failed | interrupted."""

    state: str
    exit_code: int
    message: str  # the last line of stderr when it failed or was interrupted, else its "done: ..." line
    run_dir: str = ""


class ChildJob:
    """A running `charctl train` child: start(), poll(), interrupt(), finish().

    Its stdout, stderr and exit code (written by the child as it ends) go to `log_dir`: a private
    temporary folder by default (removed by `finish`), or a given folder that is kept, so that
    another process can still read how the child ended (`outcome_from_logs`) should this one die."""

    def __init__(self, spec: JobSpec, log_dir: Path | None = None) -> None:
        self.spec = spec
        self.keep_logs = log_dir is not None
        self.log_dir = Path(log_dir) if log_dir is not None else Path(tempfile.mkdtemp(prefix="charctl-job-"))
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.stdout_path = self.log_dir / STDOUT
        self.stderr_path = self.log_dir / STDERR
        self.proc: subprocess.Popen | None = None
        self.interrupted = False
        self._run_dir = ""
        self._outcome: Outcome | None = None

    def start(self) -> None:
        env = {**os.environ, **self.spec.env, "PYTHONUNBUFFERED": "1", _PARENT_ENV: str(os.getpid())}
        env[_STATUS_ENV] = str(self.log_dir / STATUS)
        for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            env[var] = str(max(1, int(self.spec.threads)))
        cwd = self.spec.cwd if self.spec.cwd and os.path.isdir(self.spec.cwd) else None
        (self.log_dir / COMMAND).write_text(self.spec.command_line() + "\n")
        with open(self.stdout_path, "wb") as out, open(self.stderr_path, "wb") as err:
            self.proc = subprocess.Popen(
                self.spec.argv(),
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=err,
                cwd=cwd,
                env=env,
                start_new_session=True,
            )

    @property
    def pid(self) -> int | None:
        return self.proc.pid if self.proc is not None else None

    def poll(self) -> int | None:
        return self.proc.poll() if self.proc is not None else None

    @property
    def run_dir(self) -> str:
        """The run directory, once the child has printed it."""
        if not self._run_dir:
            self._run_dir = run_dir_of(self.log_dir)
        return self._run_dir

    def interrupt(self) -> None:
        """Ctrl-C for the child (once): it finishes its iteration, writes its checkpoint and exits 130."""
        if self.proc is not None and self.proc.poll() is None and not self.interrupted:
            self.interrupted = True
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.proc.pid, signal.SIGINT)

    def wait(self, timeout: float | None = None) -> int | None:
        """Wait for the child to end (None on timeout)."""
        if self.proc is None:
            return None
        try:
            return self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            return None

    def stop(self, grace: float = INTERRUPT_GRACE_S) -> None:
        """Interrupt the child and wait for its checkpoint; kill it if it does not end within `grace`."""
        if self.proc is None or self.proc.poll() is not None:
            return
        self.interrupt()
        if self.wait(grace) is None:
            with contextlib.suppress(ProcessLookupError):
                self.proc.kill()
            self.proc.wait()

    def finish(self) -> Outcome:
        """The outcome of the ended child; its output is kept as `<run_dir>/job.log`, a temporary log
        folder removed."""
        if self._outcome is None:
            code = self.proc.wait() if self.proc is not None else 1
            self._outcome = outcome_from_logs(self.log_dir, code)
            if not self.keep_logs:
                shutil.rmtree(self.log_dir, ignore_errors=True)
        return self._outcome


def run_dir_of(log_dir: Path) -> str:
    """The run directory a child printed into `log_dir/stdout.log` ('' until it has)."""
    for line in _read_lines(Path(log_dir) / STDOUT):
        if line.startswith(RUN_DIR_PREFIX):
            return line[len(RUN_DIR_PREFIX) :].strip()
    return ""


def exit_code_of(log_dir: Path) -> int | None:
    """The exit code the child wrote as it ended (None while it runs, or if it was killed)."""
    text = "".join(_read_lines(Path(log_dir) / STATUS)).strip()
    return int(text) if text.lstrip("-").isdigit() else None


def outcome_from_logs(log_dir: Path, code: int | None = None) -> Outcome:
    """How the child logging into `log_dir` ended (`code`: its exit code as its parent saw it, else
    the one it wrote); also writes `<run_dir>/job.log` (the command, stdout, stderr, exit code)."""
    log_dir = Path(log_dir)
    command_line = " ".join(_read_lines(log_dir / COMMAND)).strip()
    if code is None:
        code = exit_code_of(log_dir)
    code = 1 if code is None else code
    run_dir = run_dir_of(log_dir)
    err = [line for line in _read_lines(log_dir / STDERR) if line.strip()]
    out = [line for line in _read_lines(log_dir / STDOUT) if line.strip()]
    if code == 0:
        done = [line for line in out if line.startswith("done:")]
        outcome = Outcome("done", 0, done[-1] if done else "done", run_dir)
    else:
        last = err[-1].strip() if err else f"exit code {code}"
        if code < 0:  # killed by a signal it could not handle (SIGKILL ...): no checkpoint promised
            last = f"killed by signal {-code} ({signal.Signals(-code).name})"
        outcome = Outcome("interrupted" if code in (130, 143) else "failed", code, last, run_dir)
    if run_dir and Path(run_dir).is_dir():
        with contextlib.suppress(OSError):
            text = "\n".join(["$ " + command_line, *out, "--- stderr", *err, f"--- exit code {code}"])
            (Path(run_dir) / JOB_LOG).write_text(text + "\n")
    return outcome


def run_to_end(job: ChildJob, stop_requested, on_run_dir=None, poll_s: float = 0.2) -> Outcome:
    """Start `job` and wait for it; `stop_requested()` true -> interrupt it (once) and keep waiting.
    `on_run_dir(path)` is called once the run directory is known. A KeyboardInterrupt while waiting
    (a signal delivered to this process) interrupts the child too."""
    job.start()
    reported = False
    while job.poll() is None:
        try:
            if stop_requested():
                job.interrupt()
            if not reported and on_run_dir is not None and job.run_dir:
                on_run_dir(job.run_dir)
                reported = True
            time.sleep(poll_s)
        except KeyboardInterrupt:
            job.interrupt()
    if not reported and on_run_dir is not None and job.run_dir:
        on_run_dir(job.run_dir)
    return job.finish()


def child_main(main: Callable[[], None]) -> None:
    """The child's entry point: signals as on a command line (`child_setup`), then `main` (charctl's
    CLI, passed in by the boot line so that this module does not import the CLI); the exit code is
    written to $CHARCTL_LAUNCH_STATUS as it ends. A stop request that arrives before the CLI has
    taken over ends the child at once with 130 / 143 (there is no checkpoint to write yet)."""
    code = 1
    try:
        child_setup()
        main()
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        raise
    except KeyboardInterrupt:
        code = 143 if _EARLY_TERM else 130
        print("terminated" if _EARLY_TERM else "interrupted", file=sys.stderr)
        raise SystemExit(code) from None
    finally:
        path = os.environ.get(_STATUS_ENV)
        if path:
            with contextlib.suppress(OSError):
                Path(path).write_text(f"{code}\n")


_EARLY_TERM: list[int] = []  # a SIGTERM that arrived before charctl's CLI installed its own handler


def _on_early_term(signum, frame) -> None:  # noqa: ARG001
    _EARLY_TERM.append(signum)
    raise KeyboardInterrupt


def child_setup() -> None:
    """In the child, before charctl starts: SIGINT / SIGTERM delivered and handled as on a command line
    (a Ray worker's thread blocks SIGINT, and a child inherits the signal mask of the thread that
    started it), and on Linux SIGTERM when the process that started it dies (prctl
    PR_SET_PDEATHSIG), so a killed Ray worker's job still writes its checkpoint."""
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _on_early_term)  # charctl's main() replaces it with its own
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    if sys.platform.startswith("linux"):
        _die_with_parent()


def _die_with_parent() -> None:
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
    except (OSError, AttributeError):  # no usable libc: the child just outlives a killed parent
        return
    parent = os.environ.get(_PARENT_ENV, "")
    if parent.isdigit() and os.getppid() != int(parent):  # the parent died before prctl took effect
        os.kill(os.getpid(), signal.SIGTERM)


def _read_lines(path: Path) -> list[str]:
    try:
        return path.read_text(errors="replace").splitlines()
    except OSError:
        return []
