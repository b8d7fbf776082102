"""MuJoCo's warnings go to the current run's mujoco.log (or nowhere), never to MUJOCO_LOG.TXT in the current
folder or the console; `count_mujoco_warnings` reads them back for metrics.json and TensorBoard."""

from __future__ import annotations

import contextlib
import sys
from pathlib import Path

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
