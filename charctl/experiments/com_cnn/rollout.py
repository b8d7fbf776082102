"""Predictors (the CNN, the nearest-neighbour baseline) and the autoregressive rollout shared by
`charctl eval` (history from the model's own output) and `charctl export` (a user's COM path).

A rollout keeps world-frame frames (root position, root rotation, joint exponential maps) in a
buffer; each step expresses the last `history` frames and the next COM in the reference frame,
predicts m̂_t, turns it back into a world pose (hinge/fixed joints constrained) and appends it.
Everything is batched over B rollouts; the only loop is over time, which is sequential by nature.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from charctl.experiments.com_cnn.body import BodyModel
from charctl.experiments.com_cnn.data import WindowSet, decode_pose, encode_pose, heading_frame
from charctl.motion import rotations as R


class Predictor(Protocol):
    name: str
    history: int
    frame: str

    def predict(self, hist: np.ndarray, com: np.ndarray) -> np.ndarray:
        """hist (B, i, D), com (B, 3) in the reference frame -> pose (B, D) in that frame."""


# ---------------------------------------------------------------------------- the CNN
@dataclass
class CnnPredictor:
    name: str
    model: object  # ComCNN
    history: int
    frame: str
    device: str = "cpu"

    def predict(self, hist: np.ndarray, com: np.ndarray) -> np.ndarray:
        import torch

        with torch.no_grad():
            h = torch.as_tensor(hist, dtype=torch.float32, device=self.device)
            c = torch.as_tensor(com, dtype=torch.float32, device=self.device)
            return self.model(h, c).cpu().numpy().astype(float)


# ---------------------------------------------------------------------------- zero-velocity reference
@dataclass
class LastFrame:
    """Reference, not a learned model: m̂_t = m_{t-1} (the last history frame, in the same frame)."""

    history: int
    frame: str
    name: str = "last history frame (reference)"

    def predict(self, hist: np.ndarray, com: np.ndarray) -> np.ndarray:
        return np.asarray(hist[:, -1], dtype=float).copy()


# ---------------------------------------------------------------------------- nearest neighbour
@dataclass
class NearestNeighbour:
    """Nearest training window on (history, C_t); its target is the prediction.

    Distance: standardised history compressed to `pca_dims` principal components, plus the
    standardised C_t scaled so that, at com_weight = 1, it carries as much variance as the whole
    compressed history (without it, 3 COM numbers would be lost among 90 x 48 history numbers).
    """

    name: str
    history: int
    frame: str
    mean: np.ndarray  # (D,) history standardisation
    std: np.ndarray
    com_mean: np.ndarray
    com_std: np.ndarray
    basis: np.ndarray  # (i*D, k) PCA directions
    center: np.ndarray  # (i*D,)
    com_scale: float
    keys: np.ndarray  # (S, k + 3)
    values: np.ndarray  # (S, D) training targets

    def embed(self, hist: np.ndarray, com: np.ndarray) -> np.ndarray:
        h = ((hist - self.mean) / self.std).reshape(hist.shape[0], -1)
        z = (h - self.center) @ self.basis
        c = (com - self.com_mean) / self.com_std * self.com_scale
        return np.concatenate([z, c], axis=1)

    def predict(self, hist: np.ndarray, com: np.ndarray) -> np.ndarray:
        q = self.embed(np.asarray(hist, float), np.asarray(com, float))
        d = (q * q).sum(1)[:, None] - 2.0 * q @ self.keys.T + (self.keys * self.keys).sum(1)[None, :]
        return self.values[np.argmin(d, axis=1)]


def fit_nearest_neighbour(
    train: WindowSet, pca_dims: int, com_weight: float, seed: int = 0, chunk: int = 1024
) -> NearestNeighbour:
    """Index every training window of `train` (history length and frame taken from it)."""
    import torch

    S = len(train)
    hist_sum = np.zeros(train.body.pose_dim)
    hist_sq = np.zeros(train.body.pose_dim)
    coms, values = [], []
    for s in range(0, S, chunk):
        h, c, y = train.features(np.arange(s, min(s + chunk, S)))
        flat = h.reshape(-1, h.shape[-1]).astype(float)
        hist_sum += flat.sum(0)
        hist_sq += (flat * flat).sum(0)
        coms.append(c)
        values.append(y)
    n = S * train.history
    mean = hist_sum / n
    std = np.maximum(np.sqrt(np.maximum(hist_sq / n - mean * mean, 0.0)), 1e-3)
    com = np.concatenate(coms).astype(float)
    com_mean, com_std = com.mean(0), np.maximum(com.std(0), 1e-3)
    rng = np.random.default_rng(seed)
    fit_idx = np.sort(rng.choice(S, size=min(S, 8000), replace=False))  # PCA fitted on at most 8000 windows
    X = ((train.features(fit_idx)[0] - mean) / std).reshape(len(fit_idx), -1).astype(np.float32)
    center = X.mean(0)
    k = int(min(pca_dims, X.shape[0] - 1, X.shape[1]))
    torch.manual_seed(seed)
    _, sv, V = torch.svd_lowrank(torch.as_tensor(X - center), q=k, niter=3)
    basis = V.double().numpy()
    var = float((sv.double().numpy() ** 2).sum() / max(X.shape[0] - 1, 1))
    com_scale = float(np.sqrt(var / 3.0) * com_weight)
    nn = NearestNeighbour(
        "nearest neighbour",
        train.history,
        train.frame,
        mean,
        std,
        com_mean,
        com_std,
        basis,
        center,
        com_scale,
        np.zeros((0, k + 3)),
        np.concatenate(values).astype(float),
    )
    keys = [nn.embed(*train.features(np.arange(s, min(s + chunk, S)))[:2]) for s in range(0, S, chunk)]
    nn.keys = np.concatenate(keys)
    return nn


# ---------------------------------------------------------------------------- rollouts
@dataclass
class Buffer:
    """World-frame frames of B rollouts: (B, L, 3) root positions, (B, L, 4) rotations, (B, L, 3J) joints."""

    root_pos: np.ndarray
    root_rot: np.ndarray
    joint_exp: np.ndarray


# reference(step k, target index s, buffer, com_t) -> (origin (B, 3), q (B, 4)) of the frame for target s
ReferenceFn = Callable[[int, int, Buffer, np.ndarray], tuple[np.ndarray, np.ndarray]]


def previous_root_reference(body: BodyModel) -> ReferenceFn:
    """data.frame=root_prev: the heading frame of the last frame in the buffer (fully autoregressive)."""

    def ref(k: int, s: int, buf: Buffer, com_t: np.ndarray):
        return heading_frame(buf.root_pos[:, s - 1], buf.root_rot[:, s - 1], body.forward)

    return ref


def given_reference(origin: np.ndarray, q: np.ndarray) -> ReferenceFn:
    """data.frame=root_t with the root frame at t supplied (ground truth), (B, H, 3) / (B, H, 4)."""

    def ref(k: int, s: int, buf: Buffer, com_t: np.ndarray):
        return origin[:, k], q[:, k]

    return ref


def rollout(
    predictor: Predictor,
    body: BodyModel,
    seed: Buffer,
    com_path: np.ndarray,
    reference: ReferenceFn,
    on_step: Callable[[int, Buffer], None] | None = None,
) -> Buffer:
    """Generate H = com_path.shape[1] frames after the seed frames (B, L0 >= 1, ...), autoregressively.

    The seed is edge-padded at its start to the predictor's history length. `com_path` (B, H, 3)
    is the world COM C_t of each generated frame. Returns the generated frames only (B, H, ...).
    """
    B, H = com_path.shape[:2]
    i = predictor.history
    L0 = seed.root_pos.shape[1]
    pad = max(i - L0, 0)

    def padded(x: np.ndarray) -> np.ndarray:
        out = np.empty((B, pad + L0 + H) + x.shape[2:])
        out[:, :pad] = x[:, :1]
        out[:, pad : pad + L0] = x
        return out

    buf = Buffer(padded(seed.root_pos), padded(seed.root_rot), padded(seed.joint_exp))
    start = pad + L0
    for k in range(H):
        s = start + k
        origin, q = reference(k, s, buf, com_path[:, k])
        hist = encode_pose(
            origin[:, None],
            q[:, None],
            buf.root_pos[:, s - i : s],
            buf.root_rot[:, s - i : s],
            buf.joint_exp[:, s - i : s],
        )
        com = R.rotate(R.conjugate(q), com_path[:, k] - origin)
        m = predictor.predict(hist, com)
        pos, rot, joints = decode_pose(m, origin, q, body)
        buf.root_pos[:, s], buf.root_rot[:, s] = pos, rot
        buf.joint_exp[:, s] = R.log_map(joints).reshape(B, -1)
        if on_step is not None:
            on_step(s, buf)
    return Buffer(buf.root_pos[:, start:], buf.root_rot[:, start:], buf.joint_exp[:, start:])
