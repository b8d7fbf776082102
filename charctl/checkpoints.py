"""Atomic checkpoints: write (temp file + fsync + rename, signals held), load with `weights_only=True` and a
shape signature, kept-checkpoint names, and removal of temp files a killed process left behind.

Checkpoints are plain dicts of tensors, numbers, strings, lists and dicts so that they load with
`torch.load(..., weights_only=True)`; each carries the experiment name and a shape signature, and loading
one into another experiment (or another network shape) is a one-line `CharctlError`."""

from __future__ import annotations

import contextlib
import os
import re
import time
from pathlib import Path

from charctl.errors import CharctlError
from charctl.signals import signals_held

CHECKPOINT_FORMAT = 1
_TEMP_RE = re.compile(r"\.tmp(\d+)$")


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


def kept_checkpoints(run_dir: str | Path, experiment: str, samples_key: str = "samples") -> list[tuple[int, str]]:
    """(samples, file name) of RUN/checkpoints/samples_*.pt and last.pt (unless it is one of those), by
    sample count; last.pt's count is read from its state's `samples_key` (the learner's sample count as
    the shared runner names kept checkpoints by it: "samples", hopper-ga's "evaluations")."""
    run_dir = Path(run_dir)
    found = []
    for p in sorted((run_dir / "checkpoints").glob("samples_*.pt")):
        m = KEPT_CHECKPOINT.fullmatch(p.name)
        if m:
            found.append((int(m.group(1)), p.name))
    last = run_dir / "checkpoints" / "last.pt"
    if last.is_file():
        state = load_checkpoint(last, experiment)
        if samples_key not in state:
            raise CharctlError(f"{last}: its state holds no sample count ({samples_key!r})")
        n = int(state[samples_key])
        if all(n != s for s, _ in found):
            found.append((n, "last.pt"))
    return sorted(found)


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
