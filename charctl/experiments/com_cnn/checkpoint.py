"""A trained com-cnn run loaded from its directory: config, data, network (used by evaluation and export)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from charctl.errors import CharctlError
from charctl.experiments.com_cnn.body import BodyModel
from charctl.experiments.com_cnn.rollout import CnnPredictor
from charctl.experiments.com_cnn.sequences import Sequence, load_sequences


@dataclass
class LoadedRun:
    dir: Path
    cfg: object
    model: object
    body: BodyModel
    seqs: list[Sequence]
    metrics: dict
    suffix: str = ""  # tells apart runs whose settings read the same

    @property
    def label(self) -> str:
        m, d = self.cfg.model, self.cfg.data
        kind = "CNN, history + COM" if m.use_com else "CNN, history only"
        extra = "".join(
            f", {k}={v}"
            for k, v in (("fc", m.fc_activation), ("opt", self.cfg.train.optimizer))
            if v not in ("none", "sgd")
        )
        return (
            f"{kind} (i={d.history}, w={m.kernel}, "
            f"ch={'/'.join(str(c) for c in m.channels)}, {d.frame}{extra}){self.suffix}"
        )

    def predictor(self) -> CnnPredictor:
        """The network as an evaluation predictor; its inputs go to the device the network is on."""
        device = str(next(self.model.parameters()).device)
        return CnnPredictor(self.label, self.model, int(self.cfg.data.history), str(self.cfg.data.frame), device)


def load_run(run_dir: str | Path, overrides: list[str] | None = None, device: str = "cpu") -> LoadedRun:
    """Config, data and trained network of a com-cnn run directory."""
    from charctl.experiments.com_cnn.model import model_signature

    run = open_com_cnn_run(run_dir, overrides)
    if not run.has_checkpoint():
        raise CharctlError(f"{run_dir} has no checkpoint (checkpoints/last.pt): train it first")
    seqs, body = load_sequences(run.cfg)
    state = run.load_checkpoint(model_signature(run.cfg, body.pose_dim))
    model = model_from_state(run.cfg, body.pose_dim, state, device)
    metrics_path = Path(run_dir) / "metrics.json"
    metrics = json.loads(metrics_path.read_text()) if metrics_path.is_file() else {}
    return LoadedRun(Path(run_dir), run.cfg, model, body, seqs, metrics)


def open_com_cnn_run(run_dir: str | Path, overrides: list[str] | None = None):
    """The re-opened run (charctl.runs.Run, config validated, `overrides` applied), torch's threads set
    from its train.torch_threads; a one-line error for a run of another experiment."""
    import torch

    from charctl.experiments.com_cnn.config import Config
    from charctl.runs import open_run

    run = open_run(run_dir, Config, overrides)
    if run.experiment != "com-cnn":
        raise CharctlError(f"{run_dir} is a {run.experiment!r} run, not com-cnn")
    torch.set_num_threads(int(run.cfg.train.torch_threads))
    return run


def model_from_state(cfg, pose_dim: int, state: dict, device: str = "cpu"):
    """The network of a checkpoint's `state` (its "model"), built for `cfg`, in eval mode on `device`."""
    from charctl.experiments.com_cnn.model import build_model

    model = build_model(cfg, pose_dim)
    model.load_state_dict(state["model"])
    return model.eval().to(device)


def resolve_targets(targets: list[str], overrides: list[str] | tuple[str, ...] = ()) -> list[Path]:
    """Run directories; the experiment name stands for its latest run under the configured output_root."""
    from charctl.experiments import latest_run_dir

    return [latest_run_dir("com-cnn", overrides) if t == "com-cnn" else Path(t) for t in targets]
