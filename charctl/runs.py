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

import json
import os
import signal
import time
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

from charctl.errors import CharctlError

CHECKPOINT_FORMAT = 1


@dataclass
class Run:
    """A run directory and the handles an experiment writes through."""

    dir: Path
    experiment: str
    cfg: Any  # DictConfig
    resumed: bool = False
    _writer: Any = field(default=None, repr=False)

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
        """Lazily created TensorBoard SummaryWriter writing to `tb/`."""
        if self._writer is None:
            from torch.utils.tensorboard import SummaryWriter

            self._writer = SummaryWriter(log_dir=str(self.path("tb")))
        return self._writer

    def log_scalars(self, scalars: dict[str, float], step: int) -> None:
        for k, v in scalars.items():
            self.writer.add_scalar(k, float(v), step)

    def close(self) -> None:
        if self._writer is not None:
            self._writer.flush()
            self._writer.close()
            self._writer = None

    # -------------------------------------------------------------- metrics
    def write_metrics(self, metrics: dict, name: str = "metrics.json") -> Path:
        path = self.path(name)
        atomic_write_text(path, json.dumps(_jsonable(metrics), indent=2))
        return path

    # -------------------------------------------------------------- checkpoints
    def save_checkpoint(self, state: dict, signature: dict | None = None, name: str = "last.pt") -> Path:
        return save_checkpoint(self.path("checkpoints", name), self.experiment, state, signature)

    def load_checkpoint(self, signature: dict | None = None, name: str = "last.pt") -> dict:
        return load_checkpoint(self.dir / "checkpoints" / name, self.experiment, signature)

    def has_checkpoint(self, name: str = "last.pt") -> bool:
        return (self.dir / "checkpoints" / name).is_file()


def new_run(cfg, experiment: str | None = None) -> Run:
    """Create `<output_root>/<experiment>/<timestamp>/` and write the resolved config there."""
    from charctl.config import to_yaml

    experiment = experiment or cfg.experiment
    root = Path(cfg.output_root) / experiment
    stamp = datetime.now().strftime("%Y-%m-%d_%H-%M-%S")
    run_dir = root / stamp
    n = 1
    while run_dir.exists():  # two runs in the same second (multirun, tests)
        run_dir = root / f"{stamp}_{n}"
        n += 1
    run_dir.mkdir(parents=True)
    atomic_write_text(run_dir / "config.yaml", to_yaml(cfg))
    return Run(dir=run_dir, experiment=experiment, cfg=cfg)


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
    if overrides:
        from charctl.config import _check_override_syntax

        _check_override_syntax(overrides)
        cfg = OmegaConf.merge(cfg, OmegaConf.from_dotlist(overrides))
    if schema is not None:
        cfg = validate(cfg, schema, experiment)
    return Run(dir=run_dir, experiment=experiment, cfg=cfg, resumed=True)


def latest_run(output_root: str | Path, experiment: str, require_checkpoint: bool = True) -> Path:
    """Most recent run directory of `experiment` (by name = timestamp)."""
    root = Path(output_root) / experiment
    runs = sorted(p for p in root.glob("*") if (p / "config.yaml").is_file() and (not require_checkpoint or (p / "checkpoints" / "last.pt").is_file()))
    if not runs:
        raise CharctlError(f"no {experiment} run with a checkpoint in {root}/ — train one first: charctl train {experiment}")
    return runs[-1]


# ---------------------------------------------------------------------------- checkpoint files
def save_checkpoint(path: Path, experiment: str, state: dict, signature: dict | None = None) -> Path:
    """Write a checkpoint atomically (temp file + fsync + rename): a crash never leaves half a file."""
    import torch

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {"format": CHECKPOINT_FORMAT, "experiment": experiment, "signature": signature or {}, "saved_at": time.time(), "state": state}
    tmp = path.with_suffix(path.suffix + f".tmp{os.getpid()}")
    with open(tmp, "wb") as fh:
        torch.save(payload, fh)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    return path


def load_checkpoint(path: Path, experiment: str, signature: dict | None = None) -> dict:
    """Load a checkpoint with `weights_only=True`; wrong experiment or shapes -> one-line error."""
    import torch

    path = Path(path)
    if not path.is_file():
        raise CharctlError(f"checkpoint not found: {path}")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises UnpicklingError, RuntimeError, EOFError, KeyError, ... on non-checkpoints
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:120]
        raise CharctlError(f"{path}: not a readable charctl checkpoint ({first})") from None
    if not isinstance(payload, dict) or "experiment" not in payload or "state" not in payload:
        raise CharctlError(f"{path}: not a charctl checkpoint")
    if payload["experiment"] != experiment:
        raise CharctlError(f"{path} is a {payload['experiment']!r} checkpoint, not {experiment!r}")
    if signature:
        saved = payload.get("signature") or {}
        diff = [k for k in signature if k in saved and saved[k] != signature[k]]
        if diff:
            k = diff[0]
            raise CharctlError(f"{path}: checkpoint was made with {k}={saved[k]}, this config has {k}={signature[k]}")
    return payload["state"]


def atomic_write_text(path: Path, text: str) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + f".tmp{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def _jsonable(x: Any) -> Any:
    import numpy as np

    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    if hasattr(x, "item") and callable(x.item) and getattr(x, "ndim", 1) == 0:
        return x.item()
    return x


# ---------------------------------------------------------------------------- interruption
class StopFlag:
    """Turns the first Ctrl-C (SIGINT) / SIGTERM into `requested = True` so a training loop can
    finish its iteration, write a checkpoint and return; a second Ctrl-C interrupts at once.

        with StopFlag() as stop:
            for it in ...:
                ...
                if stop.requested: break
    """

    def __init__(self) -> None:
        self.requested = False
        self._old: dict[int, Any] = {}

    def _handle(self, signum, frame) -> None:  # noqa: ARG002
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def __enter__(self) -> "StopFlag":
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                self._old[sig] = signal.signal(sig, self._handle)
            except ValueError:  # not the main thread
                pass
        return self

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)
