"""Output paths: checks that a folder or file can be written (one-line errors before anything is written),
OS errors as one line, and unique run-directory names."""

from __future__ import annotations

import os
from pathlib import Path

from charctl.errors import CharctlError


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
