"""Run directories: creating, reopening (resume) and finding them, and the handles an experiment writes
through (TensorBoard, metrics.json, checkpoints) — shared by every experiment.

Layout of a run: `<output_root>/<experiment>/<YYYY-mm-dd_HH-MM-SS>/`
    config.yaml        resolved config
    tb/                TensorBoard events
    checkpoints/       last.pt (+ optional numbered ones), written atomically
    metrics.json       final / evaluation metrics
    *.png, *.mp4, *.bvh

The jobs beside it, one module each: `charctl.checkpoints` (atomic write, safe load), `charctl.paths`
(writable-path checks), `charctl.files` (atomic text, strict JSON), `charctl.mujoco_log` (MuJoCo's
warnings into the run), `charctl.signals` (Ctrl-C / SIGTERM as a stop request).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

from charctl.checkpoints import load_checkpoint, remove_stale_temp_files, save_checkpoint
from charctl.errors import CharctlError
from charctl.files import atomic_write_text, strict_json
from charctl.mujoco_log import count_mujoco_warnings
from charctl.paths import check_writable_dir, make_unique_dir, os_error

# `charctl tune` (charctl.launch.tune) sets this to a file: every scalar set a run logs, and its final
# metrics.json numbers, are appended there as one JSON line each, which the tuner reads as the run goes.
METRICS_STREAM_ENV = "CHARCTL_METRICS_STREAM"


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

    def record_resume(self) -> None:
        """A resumed run that will train: its overrides into config.yaml and resumes.txt (once). The runner calls
        this after the checkpoint has loaded and the budget check has passed, so a refused resume writes nothing."""
        if self.resumed and self.resume_overrides:
            record_resume_overrides(self, self.resume_overrides)
            self.resume_overrides = []

    # -------------------------------------------------------------- checkpoints
    def save_checkpoint(self, state: dict, signature: dict | None = None, name: str = "last.pt") -> Path:
        path = self.path("checkpoints", name)
        return save_checkpoint(path, self.experiment, state, signature, tb_step=self._max_step)

    def load_checkpoint(self, signature: dict | None = None, name: str = "last.pt") -> dict:
        payload = load_checkpoint(self.dir / "checkpoints" / name, self.experiment, signature, payload=True)
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
    from charctl.config import drop_removed_keys, validate

    run_dir = Path(run_dir)
    cfg = read_run_config(run_dir)
    experiment = str(cfg.get("experiment"))
    if schema is not None:  # keys the schema has dropped since the run was recorded (its REMOVED table)
        drop_removed_keys(cfg, schema, run_dir)
    remove_stale_temp_files(run_dir)
    if overrides:
        from charctl.config import apply_overrides

        cfg = apply_overrides(cfg, overrides)
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
