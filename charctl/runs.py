"""Run directories, atomic checkpoints, metrics and clean interruption — shared by every experiment.

Layout of a run: `<output_root>/<experiment>/<YYYY-mm-dd_HH-MM-SS>/`
    config.yaml        resolved config
    tb/                TensorBoard events
    checkpoints/       last.pt (+ optional numbered ones), written atomically
    metrics.json       final / evaluation metrics
    *.png, *.mp4, *.bvh

Checkpoints are plain dicts of tensors, numbers, strings, lists and dicts so that they load
with `torch.load(..., weights_only=True)`; each carries the experiment name and a shape
signature, and loading one into another experiment (or another network shape) is a one-line
`CharctlError`.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

from charctl.errors import CharctlError, Interrupted

CHECKPOINT_FORMAT = 1
# `charctl tune` (charctl.launch.tune) sets this to a file: every scalar set a run logs, and its final
# metrics.json numbers, are appended there as one JSON line each, which the tuner reads as the run goes.
METRICS_STREAM_ENV = "CHARCTL_METRICS_STREAM"
_TEMP_RE = re.compile(r"\.tmp(\d+)$")


@dataclass
class Run:
    """A run directory and the handles an experiment writes through."""

    dir: Path
    experiment: str
    cfg: Any  # DictConfig
    resumed: bool = False
    # a resume's overrides: written into config.yaml (and resumes.txt) once the checkpoint has loaded against
    # the new config's signature, so a rejected resume leaves the run as it was
    resume_overrides: list[str] = field(default_factory=list)
    _writer: Any = field(default=None, repr=False)
    _max_step: int | None = field(default=None, repr=False)  # largest TensorBoard step logged by this process
    _purge_step: int | None = field(default=None, repr=False)  # resumed: TensorBoard events from here on are stale

    # -------------------------------------------------------------- paths
    def path(self, *parts: str) -> Path:
        p = self.dir.joinpath(*parts)
        p.parent.mkdir(parents=True, exist_ok=True)
        return p

    @property
    def checkpoint_path(self) -> Path:
        return self.path("checkpoints", "last.pt")

    # -------------------------------------------------------------- TensorBoard
    @property
    def writer(self):
        """Lazily created TensorBoard SummaryWriter writing to `tb/`. A resumed run passes
        `purge_step` (one past the last step logged before its checkpoint), so steps logged after
        that checkpoint by a killed process are hidden instead of appearing twice."""
        if self._writer is None:
            from torch.utils.tensorboard import SummaryWriter

            self._writer = SummaryWriter(log_dir=str(self.path("tb")), purge_step=self._purge_step)
        return self._writer

    def log_scalars(self, scalars: dict[str, float], step: int) -> None:
        """Scalars at `step`; non-finite values are skipped (TensorBoard and strict JSON cannot hold them)."""
        finite = {}
        for k, v in scalars.items():
            v = float(v)
            if math.isfinite(v):
                self.writer.add_scalar(k, v, step)
                finite[k] = v
        self._max_step = int(step) if self._max_step is None else max(self._max_step, int(step))
        stream_scalars(self.dir, int(step), finite)

    def close(self) -> None:
        if self._writer is not None:
            warnings = count_mujoco_warnings(self.dir)
            if warnings:  # MuJoCo's "Nan, Inf or huge value" warnings of this run (its mujoco.log), counted
                self._writer.add_scalar("sim/mujoco_warnings", warnings, self._max_step or 0)
            self._writer.flush()
            self._writer.close()
            self._writer = None

    # -------------------------------------------------------------- metrics
    def write_metrics(self, metrics: dict, name: str = "metrics.json") -> Path:
        """Strict JSON (NaN / infinity become null); MuJoCo warnings of this run are counted in."""
        metrics = dict(metrics)
        warnings = count_mujoco_warnings(self.dir)
        if warnings and "mujoco_warnings" not in metrics:
            metrics["mujoco_warnings"] = warnings
        path = self.path(name)
        atomic_write_text(path, strict_json(metrics))
        if name == "metrics.json":
            numbers = {k: float(v) for k, v in metrics.items() if _is_number(v) and math.isfinite(float(v))}
            stream_scalars(self.dir, self._max_step or 0, numbers, final=True)
        return path

    # -------------------------------------------------------------- checkpoints
    def save_checkpoint(self, state: dict, signature: dict | None = None, name: str = "last.pt") -> Path:
        path = self.path("checkpoints", name)
        return save_checkpoint(path, self.experiment, state, signature, tb_step=self._max_step)

    def load_checkpoint(self, signature: dict | None = None, name: str = "last.pt") -> dict:
        payload = load_checkpoint(self.dir / "checkpoints" / name, self.experiment, signature, payload=True)
        if self.resumed and self.resume_overrides:
            record_resume_overrides(self, self.resume_overrides)
            self.resume_overrides = []
        if self.resumed and "tb_step" in payload:
            # tb_step None: nothing was logged before this checkpoint, so every step in tb/ is stale
            # (a killed process logged past it): purge from step 0.
            last = payload["tb_step"]
            self._purge_step = 0 if last is None else int(last) + 1
            self._max_step = None if last is None else int(last)
            if self._writer is not None:  # created before the checkpoint was read: reopen with purge_step
                self.close()
        return payload["state"]

    def has_checkpoint(self, name: str = "last.pt") -> bool:
        return (self.dir / "checkpoints" / name).is_file()


def stream_scalars(run_dir: Path, step: int, scalars: dict[str, float], final: bool = False) -> None:
    """Append `{"run_dir", "step", "final", "scalars"}` as a JSON line to $CHARCTL_METRICS_STREAM (if set)."""
    path = os.environ.get(METRICS_STREAM_ENV)
    if not path or not scalars:
        return
    line = json.dumps({"run_dir": str(run_dir), "step": step, "final": final, "scalars": scalars})
    with contextlib.suppress(OSError), open(path, "a") as fh:
        fh.write(line + "\n")


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def new_run(cfg, experiment: str | None = None) -> Run:
    """Create `<output_root>/<experiment>/<timestamp>/` and write the resolved config there."""
    from charctl.config import to_yaml

    experiment = experiment or cfg.experiment
    check_writable_dir(cfg.output_root, "output_root")
    root = Path(cfg.output_root) / experiment
    check_writable_dir(root, "output_root")
    stamp = datetime.now().strftime("%Y-%m-%d_%H-%M-%S")
    run_dir = root / stamp
    try:
        run_dir = make_unique_dir(root, stamp)
        atomic_write_text(run_dir / "config.yaml", to_yaml(cfg))
    except OSError as exc:
        raise os_error(exc, "cannot create the run directory", run_dir) from None
    return Run(dir=run_dir, experiment=experiment, cfg=cfg)


def make_unique_dir(root: Path, stamp: str) -> Path:
    """Create `root/stamp`, or `stamp_1`, `stamp_2` ... when taken: two runs in the same second
    (multirun, tests, jobs started side by side by another process) each get their own folder."""
    root.mkdir(parents=True, exist_ok=True)
    n = 0
    while True:
        run_dir = root / (stamp if n == 0 else f"{stamp}_{n}")
        try:
            run_dir.mkdir()
            return run_dir
        except FileExistsError:
            n += 1


def _dir_problem(path: Path) -> str | None:
    """Why `path` cannot be (created as) a writable folder, or None."""
    probe = path
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        return "it is a file, not a folder" if probe == path else f"{probe} is a file, not a folder"
    if probe.exists():  # try it: permission bits do not tell root, read-only mounts or ACLs apart
        import tempfile

        try:
            fd, name = tempfile.mkstemp(dir=probe, prefix=".charctl-probe-")
            os.close(fd)
            os.unlink(name)
        except OSError as exc:
            cause = exc.strerror or type(exc).__name__
            return cause if probe == path else f"{cause} ({probe})"
    return None


def check_writable_dir(path: str | Path, what: str = "folder") -> None:
    """One-line error unless `path` is (or can be created as) a writable folder. Creates nothing."""
    problem = _dir_problem(Path(path))
    if problem:
        raise CharctlError(f"cannot write to {what} {path}: {problem}")


def check_output_file(path: str | Path, option: str = "-o") -> None:
    """One-line error unless `path` can be written as a file (its folder exists or can be created and
    is writable; the path itself is not a folder). Creates nothing."""
    path = Path(path)
    if path.is_dir():
        raise CharctlError(f"cannot write {option} {path}: it is a folder; give a file name")
    if path.exists() and not os.access(path, os.W_OK):
        raise CharctlError(f"cannot write {option} {path}: permission denied")
    problem = _dir_problem(path.parent)
    if problem:
        raise CharctlError(f"cannot write {option} {path}: {problem}")


def os_error(exc: OSError, doing: str, path: str | Path | None = None) -> CharctlError:
    """`CharctlError("cannot write checkpoint X: No space left on device")` from an OSError."""
    where = path if path is not None else (exc.filename or "")
    cause = exc.strerror or str(exc) or type(exc).__name__
    return CharctlError(f"{doing} {where}: {cause}".replace("  ", " "))


def read_run_config(run_dir: str | Path):
    """The resolved config stored in a run directory."""
    from omegaconf import OmegaConf

    run_dir = Path(run_dir)
    cfg_path = run_dir / "config.yaml"
    if not cfg_path.is_file():
        raise CharctlError(f"not a charctl run directory (no config.yaml): {run_dir}")
    try:
        return OmegaConf.load(cfg_path)
    except Exception as exc:  # malformed YAML
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise CharctlError(f"{cfg_path}: cannot read config ({first})") from None


def run_experiment(run_dir: str | Path) -> str:
    cfg = read_run_config(run_dir)
    exp = cfg.get("experiment")
    if not exp:
        raise CharctlError(f"{run_dir}/config.yaml names no experiment")
    return str(exp)


def open_run(run_dir: str | Path, schema: type | None = None, overrides: list[str] | None = None) -> Run:
    """Re-open an existing run (for --resume or evaluation), validating its config against `schema`."""
    from omegaconf import OmegaConf

    from charctl.config import validate

    run_dir = Path(run_dir)
    cfg = read_run_config(run_dir)
    experiment = str(cfg.get("experiment"))
    remove_stale_temp_files(run_dir)
    if overrides:
        from charctl.config import _check_override_syntax

        _check_override_syntax(overrides)
        cfg = OmegaConf.merge(cfg, OmegaConf.from_dotlist(overrides))
    if schema is not None:
        cfg = validate(cfg, schema, experiment)
    return Run(dir=run_dir, experiment=experiment, cfg=cfg, resumed=True)


def record_resume_overrides(run: Run, overrides: list[str]) -> None:
    """A resume with overrides writes the merged config back to config.yaml (so a later resume, eval or export
    sees what the run now trains with) and appends the override line to resumes.txt (the run's history)."""
    from charctl.config import to_yaml

    if not overrides:
        return
    atomic_write_text(run.dir / "config.yaml", to_yaml(run.cfg))
    with open(run.dir / "resumes.txt", "a") as fh:
        fh.write(f"{datetime.now().isoformat(timespec='seconds')} --resume {' '.join(overrides)}\n")


def latest_run(output_root: str | Path, experiment: str, require_checkpoint: bool = True) -> Path:
    """Most recent run directory of `experiment` (by name = timestamp)."""
    root = Path(output_root) / experiment
    runs = sorted(
        p
        for p in root.glob("*")
        if (p / "config.yaml").is_file() and (not require_checkpoint or (p / "checkpoints" / "last.pt").is_file())
    )
    if not runs:
        raise CharctlError(
            f"no {experiment} run with a checkpoint in {root}/ — train one first: charctl train {experiment}"
        )
    return runs[-1]


# ---------------------------------------------------------------------------- checkpoint files
KEPT_CHECKPOINT = re.compile(r"samples_(\d+)\.pt")  # checkpoints kept every N samples beside last.pt


def kept_checkpoint_name(samples: int) -> str:
    """File name of a checkpoint kept at `samples` samples: samples_000123456.pt (sorts by sample count)."""
    return f"samples_{samples:09d}.pt"


def checkpoint_file_name(name: str | None) -> str:
    """The file in RUN/checkpoints/ a user names (a plain file name such as samples_020000000.pt), or last.pt."""
    if not name:
        return "last.pt"
    if Path(name).name != name or name in (".", ".."):
        raise CharctlError(
            f"--checkpoint takes a file name inside RUN/checkpoints/ (e.g. samples_020000000.pt), got {name!r}"
        )
    return name


def save_checkpoint(
    path: Path, experiment: str, state: dict, signature: dict | None = None, tb_step: int | None = None
) -> Path:
    """Write a checkpoint atomically (temp file + fsync + rename): a crash never leaves half a file.

    SIGINT / SIGTERM are held back while the file is written (delivered right after), so a second
    Ctrl-C cannot interrupt a write; a failed write (disk full, read-only, ...) removes the temp
    file, keeps the previous checkpoint and is a one-line `CharctlError`. `tb_step` is the last
    TensorBoard step logged before this checkpoint (a resumed run purges later steps).
    """
    path = Path(path)
    payload = {
        "format": CHECKPOINT_FORMAT,
        "experiment": experiment,
        "signature": signature or {},
        "saved_at": time.time(),
        "tb_step": tb_step,
        "state": state,
    }
    tmp = path.with_suffix(path.suffix + f".tmp{os.getpid()}")
    try:
        with signals_held():
            path.parent.mkdir(parents=True, exist_ok=True)
            try:
                with open(tmp, "wb") as fh:
                    _save_payload(fh, payload)
                    fh.flush()
                    os.fsync(fh.fileno())
                os.replace(tmp, path)
            except BaseException:
                with contextlib.suppress(OSError):
                    tmp.unlink()
                raise
    except OSError as exc:
        kept = "; the previous checkpoint is kept" if path.is_file() else ""
        raise CharctlError(f"cannot write checkpoint {path}: {exc.strerror or exc}{kept}") from None
    return path


def _save_payload(fh, payload: dict) -> None:
    """Serialise a checkpoint payload into the open temp file `fh` (the test suite's fault hooks,
    tests/fault_hooks/sitecustomize.py, replace this function to stall or fail a write half-way)."""
    import torch

    torch.save(payload, fh)


def load_checkpoint(path: Path, experiment: str, signature: dict | None = None, payload: bool = False) -> dict:
    """Load a checkpoint with `weights_only=True`; wrong experiment or shapes -> one-line error.
    Returns the saved state (or, with `payload=True`, the whole payload with its "state")."""
    import torch

    path = Path(path)
    if not path.is_file():
        raise CharctlError(f"checkpoint not found: {path}")
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises UnpicklingError, RuntimeError, EOFError, KeyError, ... on non-checkpoints
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:120]
        raise CharctlError(f"{path}: not a readable charctl checkpoint ({first})") from None
    if not isinstance(data, dict) or "experiment" not in data or "state" not in data:
        raise CharctlError(f"{path}: not a charctl checkpoint")
    if data["experiment"] != experiment:
        raise CharctlError(f"{path} is a {data['experiment']!r} checkpoint, not {experiment!r}")
    if signature:
        saved = data.get("signature") or {}
        diff = [k for k in signature if k in saved and saved[k] != signature[k]]
        if diff:
            k = diff[0]
            raise CharctlError(f"{path}: checkpoint was made with {k}={saved[k]}, this config has {k}={signature[k]}")
    return data if payload else data["state"]


def atomic_write_text(path: Path, text: str) -> None:
    path = Path(path)
    tmp = path.with_suffix(path.suffix + f".tmp{os.getpid()}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text(text)
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise os_error(exc, "cannot write", path) from None


def remove_stale_temp_files(run_dir: str | Path) -> list[Path]:
    """Delete `*.tmp<pid>` files a killed process left in a run directory (its checkpoints, metrics,
    config); files of a process that is still alive are kept. Returns what was removed."""
    removed = []
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        return removed
    for p in list(run_dir.glob("*.tmp*")) + list(run_dir.glob("checkpoints/*.tmp*")):
        m = _TEMP_RE.search(p.name)
        if m is None or not p.is_file() or _pid_alive(int(m.group(1))):
            continue
        with contextlib.suppress(OSError):
            p.unlink()
            removed.append(p)
    return removed


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return False  # this process has not written anything yet: a leftover of an older process with our pid
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def strict_json(obj: Any, indent: int | None = 2) -> str:
    """JSON that every parser accepts: numpy/torch scalars and arrays converted, NaN and +-inf -> null."""
    return json.dumps(_jsonable(obj), indent=indent, allow_nan=False)


def _jsonable(x: Any) -> Any:
    import numpy as np

    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        x = x.item()
    elif hasattr(x, "item") and callable(x.item) and getattr(x, "ndim", 1) == 0:
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, Path):
        return str(x)
    return x


# ---------------------------------------------------------------------------- MuJoCo's log
MUJOCO_LOG = "mujoco.log"


_mujoco_log_dir: list[Path] = []  # the run whose mujoco.log receives MuJoCo's warnings (empty: none)


def capture_mujoco_log(run_dir: str | Path | None) -> None:
    """Send MuJoCo's warnings ("Nan, Inf or huge value in QACC ...") to `<run_dir>/mujoco.log` from
    now on, instead of MUJOCO_LOG.TXT in the current directory and the console. Applied at once if
    MuJoCo is loaded, else when a model is built (charctl.sim.humanoid.load_model)."""
    _mujoco_log_dir[:] = [Path(run_dir)] if run_dir is not None else []
    if "mujoco" in sys.modules:
        apply_mujoco_log()


def apply_mujoco_log() -> None:
    """Configure MuJoCo's log: the current run's mujoco.log, or (no run: export, eval, play) nowhere;
    the simulator counts its blow-ups itself. A MuJoCo without MjLogConfig gets a warning callback."""
    import mujoco

    cls = getattr(mujoco, "MjLogConfig", None)
    if cls is None:  # pragma: no cover - older MuJoCo
        setter = getattr(mujoco, "set_mju_user_warning", None)
        if setter is not None:
            setter(_log_mujoco_warning)
        return
    cfg = cls.get()
    cfg.logto_console = False
    cfg.logto_file = bool(_mujoco_log_dir)
    if _mujoco_log_dir:
        cfg.logfile = str(_mujoco_log_dir[0] / MUJOCO_LOG)
    cfg.set()


def _log_mujoco_warning(message: str) -> None:
    if _mujoco_log_dir:
        with contextlib.suppress(OSError), open(_mujoco_log_dir[0] / MUJOCO_LOG, "a") as fh:
            fh.write(f"WARNING: {message}\n")


def count_mujoco_warnings(run_dir: str | Path) -> int:
    """Warnings MuJoCo wrote into the run's mujoco.log (0 when there is none)."""
    path = Path(run_dir) / MUJOCO_LOG
    try:
        with open(path, errors="replace") as fh:
            return sum(1 for line in fh if line.startswith("WARNING"))
    except OSError:
        return 0


# ---------------------------------------------------------------------------- interruption
_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_received: list[int] = []  # signals a StopFlag turned into a stop request in this process


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT / SIGTERM back for the duration (they are delivered when it ends). Main thread only."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, set(_STOP_SIGNALS))
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def stop_signal() -> int | None:
    """The first signal a StopFlag received in this process (None if none): a training function that
    returned normally after one was still interrupted (see charctl.commands.train)."""
    return _received[0] if _received else None


class StopFlag:
    """Turns Ctrl-C (SIGINT) / SIGTERM into `requested = True` so a training loop can finish its
    iteration, write a checkpoint and raise `stop.interrupted(...)` (exit 130 / 143):

        with StopFlag() as stop:
            for it in ...:
                ...
                if stop.requested:
                    run.save_checkpoint(...)
                    raise stop.interrupted(f"interrupted at iteration {it}: checkpoint written; "
                                           f"continue with --resume {run.dir}")

    A second signal only says that the stop is under way (the checkpoint is still written, the exit
    code is the first signal's); a third one gives up on the current iteration and raises
    `Interrupted` at once (the last checkpoint on disk is kept). Checkpoint writes hold signals
    back (`signals_held`), so no signal lands inside one.
    """

    give_up_after = 3

    def __init__(self) -> None:
        self.requested = False
        self.signum: int | None = None
        self.count = 0
        self._old: dict[int, Any] = {}

    @property
    def exit_code(self) -> int:
        return 128 + int(self.signum or signal.SIGINT)

    def interrupted(self, message: str) -> Interrupted:
        return Interrupted(message, signum=self.signum)

    def _handle(self, signum, frame) -> None:  # noqa: ARG002
        self.count += 1
        if not self.requested:
            self.requested = True
            self.signum = int(signum)
            _received.append(int(signum))
            print(
                "\nstopping: finishing this iteration and writing a checkpoint (press Ctrl-C twice more to quit "
                "without it)",
                file=sys.stderr,
                flush=True,
            )
            return
        if self.count >= self.give_up_after:
            raise Interrupted(
                "interrupted before the current iteration finished; the last checkpoint on disk is kept",
                signum=self.signum,
            )
        print("\nstill stopping (press Ctrl-C once more to quit without the checkpoint)", file=sys.stderr, flush=True)

    def __enter__(self) -> StopFlag:
        for sig in _STOP_SIGNALS:
            try:
                self._old[sig] = signal.signal(sig, self._handle)
            except ValueError:  # not the main thread
                pass
        return self

    def __exit__(self, *exc) -> None:
        if self.requested:  # the run is ending with Interrupted: later signals keep counting, same exit code
            return
        for sig, old in self._old.items():
            signal.signal(sig, old)
