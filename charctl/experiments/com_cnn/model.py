"""The paper's motion prediction network (§3.3, Fig. 2, Table 2).

    N(M) = three times [1-D conv over time (valid, width w) -> ReLU -> max pool (2)]   -> Z (384-D)
    P(K) = W1 (W0 K + b0) + b1,   K = [Z, C_t] (387-D)                                -> m̂_t

Shapes for the best setting (history 90, kernel 10, channels 32/64/128, 48-D poses):
(B, 48, 90) -> (B, 32, 40) -> (B, 64, 15) -> (B, 128, 3) -> Z (B, 384) -> K (B, 387) -> (B, 48).
Inputs and outputs are standardised with the training set's mean/std, stored as buffers so a
checkpoint carries them.
"""

from __future__ import annotations

import torch
from torch import nn

from charctl.experiments.com_cnn.config import conv_output_length

ACTIVATIONS: dict[str, type[nn.Module]] = {"none": nn.Identity, "relu": nn.ReLU}


class ComCNN(nn.Module):
    """History (B, i, D) + COM (B, 3) -> pose (B, D). `use_com=False` is the history-only baseline."""

    def __init__(
        self,
        pose_dim: int,
        history: int,
        channels: list[int],
        kernel: int = 10,
        pool: int = 2,
        fc_hidden: int = 512,
        fc_activation: str = "none",
        use_com: bool = True,
    ) -> None:
        super().__init__()
        self.pose_dim, self.history, self.use_com = pose_dim, history, use_com
        layers: list[nn.Module] = []
        c_in = pose_dim
        for c_out in channels:
            layers += [nn.Conv1d(c_in, c_out, kernel), nn.ReLU(), nn.MaxPool1d(pool)]
            c_in = c_out
        self.conv = nn.Sequential(*layers)
        self.z_dim = c_in * conv_output_length(history, kernel, pool, len(channels))
        k_dim = self.z_dim + (3 if use_com else 0)
        self.fc = nn.Sequential(
            nn.Linear(k_dim, fc_hidden), ACTIVATIONS[fc_activation](), nn.Linear(fc_hidden, pose_dim)
        )
        for name, size in (("hist", pose_dim), ("com", 3), ("pose", pose_dim)):
            self.register_buffer(f"{name}_mean", torch.zeros(size))
            self.register_buffer(f"{name}_std", torch.ones(size))

    def set_normalizer(self, stats: dict[str, tuple[torch.Tensor, torch.Tensor]]) -> None:
        """stats: name -> (mean, std) for hist, com, pose."""
        for name, (mean, std) in stats.items():
            getattr(self, f"{name}_mean").copy_(torch.as_tensor(mean))
            getattr(self, f"{name}_std").copy_(torch.as_tensor(std))

    def features(self, hist: torch.Tensor) -> torch.Tensor:
        """Z (B, z_dim): the CNN N(M) on a standardised history (B, i, D)."""
        return self.conv(hist.transpose(1, 2).contiguous()).flatten(1)

    def forward_normalized(self, hist_n: torch.Tensor, com_n: torch.Tensor) -> torch.Tensor:
        """Standardised prediction from standardised inputs (what the MSE loss sees)."""
        z = self.features(hist_n)
        k = torch.cat([z, com_n], dim=1) if self.use_com else z
        return self.fc(k)

    def normalize_inputs(self, hist: torch.Tensor, com: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return (hist - self.hist_mean) / self.hist_std, (com - self.com_mean) / self.com_std

    def normalize_pose(self, pose: torch.Tensor) -> torch.Tensor:
        return (pose - self.pose_mean) / self.pose_std

    def forward(self, hist: torch.Tensor, com: torch.Tensor) -> torch.Tensor:
        """Pose m̂_t (B, D) in the reference frame, raw units (metres, radians)."""
        h, c = self.normalize_inputs(hist, com)
        return self.forward_normalized(h, c) * self.pose_std + self.pose_mean


def build_model(cfg, pose_dim: int) -> ComCNN:
    m = cfg.model
    return ComCNN(
        pose_dim, cfg.data.history, list(m.channels), m.kernel, m.pool, m.fc_hidden, m.fc_activation, m.use_com
    )


def model_signature(cfg, pose_dim: int) -> dict:
    """What a checkpoint must match to load into this config's network."""
    m = cfg.model
    return {
        "pose_dim": pose_dim,
        "history": int(cfg.data.history),
        "channels": [int(c) for c in m.channels],
        "kernel": int(m.kernel),
        "pool": int(m.pool),
        "fc_hidden": int(m.fc_hidden),
        "use_com": bool(m.use_com),
    }
