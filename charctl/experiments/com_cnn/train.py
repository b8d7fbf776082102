"""`charctl train com-cnn`: supervised training of the COM-conditioned CNN (paper §3.4).

Loss: MSE between the standardised prediction and the standardised ground-truth pose (paper eq.
Cost = ||y - P({N(M), C})||^2 on standardised vectors). Minibatches are drawn uniformly from every
training window (paper §3.4: every frame cut into history-length sub-clips, sampled at random).
"""

from __future__ import annotations

import time

import numpy as np

from charctl.experiments.com_cnn.body import BodyModel
from charctl.experiments.com_cnn.data import WindowSet, build_windows, constrain_joint_exp
from charctl.experiments.com_cnn.model import ComCNN, build_model, model_signature


def make_optimizer(params, t):
    """The optimiser named by train.optimizer (paper §4: SGD)."""
    import torch

    table = {
        "sgd": lambda: torch.optim.SGD(params, lr=t.lr, momentum=t.momentum, weight_decay=t.weight_decay),
        "adam": lambda: torch.optim.Adam(params, lr=t.lr, weight_decay=t.weight_decay),
        "adamw": lambda: torch.optim.AdamW(params, lr=t.lr, weight_decay=t.weight_decay),
    }
    return table[str(t.optimizer)]()


def pick_device(name: str) -> str:
    """auto -> cuda when available, else cpu; an absent CUDA device is a one-line error."""
    from charctl.config import resolve_device

    return resolve_device(name)


class BatchSource:
    """Minibatches of (hist, com, target) tensors; all windows precomputed when they fit in `cache_mb`."""

    def __init__(self, windows: WindowSet, device: str, cache_mb: int, chunk: int = 1024) -> None:
        import torch

        self.windows, self.device = windows, device
        self.dense = None
        if windows.dense_bytes() <= cache_mb * 1e6:
            parts = [
                windows.features(np.arange(s, min(s + chunk, len(windows)))) for s in range(0, len(windows), chunk)
            ]
            self.dense = tuple(torch.from_numpy(np.concatenate(p)).to(device) for p in zip(*parts))

    def __len__(self) -> int:
        return len(self.windows)

    def batch(self, idx: np.ndarray):
        import torch

        if self.dense is not None:
            t = torch.from_numpy(idx).to(self.device)
            return tuple(x[t] for x in self.dense)
        return tuple(torch.from_numpy(x).to(self.device) for x in self.windows.features(idx))

    def chunks(self, size: int = 1024):
        for s in range(0, len(self), size):
            yield self.batch(np.arange(s, min(s + size, len(self))))


def normalizer_stats(source: BatchSource) -> dict:
    """Mean/std of the history frames, C_t and the targets over the training windows (std floor 1e-3)."""
    import torch

    sums = {k: 0.0 for k in ("hist", "com", "pose")}
    sq = dict(sums)
    n = {k: 0 for k in sums}
    for hist, com, target in source.chunks():
        for k, x in (("hist", hist.reshape(-1, hist.shape[-1])), ("com", com), ("pose", target)):
            x = x.double()
            sums[k] = sums[k] + x.sum(0)
            sq[k] = sq[k] + (x * x).sum(0)
            n[k] += x.shape[0]
    out = {}
    for k in sums:
        mean = sums[k] / n[k]
        std = torch.sqrt(torch.clamp(sq[k] / n[k] - mean * mean, min=0.0))
        out[k] = (mean.float(), torch.clamp(std, min=1e-3).float())
    return out


def joint_angle_error_deg(pred, target, body: BodyModel) -> np.ndarray:
    """(B,) mean over the movable joints of the angle (degrees) between predicted and true local rotations."""
    from charctl.motion import rotations as R

    J = body.num_joints
    p = R.exp_map(constrain_joint_exp(np.asarray(pred, dtype=float)[:, 6:].reshape(-1, J, 3), body))
    t = R.exp_map(np.asarray(target, dtype=float)[:, 6:].reshape(-1, J, 3))
    ang = R.angle_between(p, t)[:, body.error_joints]
    return np.degrees(ang.mean(axis=1))


def teacher_forced(model: ComCNN, source: BatchSource) -> tuple[np.ndarray, np.ndarray, float]:
    """Predictions (S, D) and targets (S, D) of every window (history from the ground truth), and the loss."""
    import torch

    preds, targets, loss_sum = [], [], 0.0
    model.eval()
    with torch.no_grad():
        for hist, com, target in source.chunks():
            h, c = model.normalize_inputs(hist, com)
            out = model.forward_normalized(h, c)
            loss_sum += float(((out - model.normalize_pose(target)) ** 2).mean(dim=1).sum())
            preds.append((out * model.pose_std + model.pose_mean).cpu().numpy())
            targets.append(target.cpu().numpy())
    model.train()
    return np.concatenate(preds), np.concatenate(targets), loss_sum / max(len(source), 1)


class ComCnnLearner:
    """Minibatch SGD on the CNN for the shared runner (charctl.rl.runner): one iteration = one minibatch
    step, `samples` = training windows seen. The checkpoint keeps its layout ("step" = `iteration`)."""

    def __init__(self, cfg, run):
        import torch

        torch.set_num_threads(int(cfg.train.torch_threads))
        torch.manual_seed(int(cfg.seed))
        self.cfg, self.run = cfg, run
        self.device = pick_device(str(cfg.device))
        t_data = time.perf_counter()
        self.train_w, self.test_w, self.body = build_windows(cfg)
        cache = int(cfg.data.window_cache_mb)
        self.source = BatchSource(self.train_w, self.device, cache)
        self.test_source = BatchSource(self.test_w, self.device, cache) if len(self.test_w) else None
        self.data_s = time.perf_counter() - t_data
        self.model = build_model(cfg, self.body.pose_dim).to(self.device)
        self.model.set_normalizer(normalizer_stats(self.source))
        self.opt = make_optimizer(self.model.parameters(), cfg.train)
        self.iteration = 0  # minibatch steps done
        self.samples = 0
        self.samples_per_iteration = int(cfg.train.batch_size)
        self.wall = 0.0  # seconds spent in the steps themselves, over every session of the run
        self.ema: float | None = None  # exponential moving average of the training loss (progress bar, metrics)
        self.test_metrics: dict = {}

    def signature(self) -> dict:
        return model_signature(self.cfg, self.body.pose_dim)

    def modules(self) -> list:
        return [self.model]

    def state_dict(self) -> dict:
        return {
            "model": self.model.state_dict(),
            "optimizer": self.opt.state_dict(),
            "step": self.iteration,
            "samples": self.samples,
            "train_wall_s": self.wall,
            "loss_ema": self.ema,
            "pose_dim": self.body.pose_dim,
        }

    def load_state_dict(self, state: dict) -> None:
        self.model.load_state_dict(state["model"])
        self.opt.load_state_dict(state["optimizer"])
        self.iteration = int(state["step"])
        self.samples = int(state.get("samples", self.iteration * self.samples_per_iteration))
        self.wall, self.ema = float(state["train_wall_s"]), state.get("loss_ema")

    def iterate(self) -> dict[str, float]:
        """One minibatch step; the scalars of train.log_every steps, test/* every train.eval_every steps
        and the last step's, and the loss whenever it is not finite (the runner stops the run then)."""
        import torch

        tc, model = self.cfg.train, self.model
        t0 = time.perf_counter()
        idx = np.random.default_rng([int(self.cfg.seed), self.iteration]).integers(
            0, len(self.source), size=self.samples_per_iteration
        )
        hist, com, target = self.source.batch(idx)
        h, c = model.normalize_inputs(hist, com)
        loss = ((model.forward_normalized(h, c) - model.normalize_pose(target)) ** 2).mean()
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        if tc.grad_clip > 0:
            torch.nn.utils.clip_grad_norm_(model.parameters(), float(tc.grad_clip))
        self.opt.step()
        self.wall += time.perf_counter() - t0
        step, samples = self.iteration + 1, self.samples + self.samples_per_iteration  # after this step
        lv = float(loss.detach())
        if not np.isfinite(lv):  # the update that produced this loss has already been applied: stop here
            return {"train/loss": lv}
        self.ema = lv if self.ema is None else 0.98 * self.ema + 0.02 * lv
        last = step == int(tc.steps)
        stats = {}
        if step % int(tc.log_every) == 0 or last:
            stats = {
                "train/loss": lv,
                "train/loss_ema": self.ema,
                "train/samples_per_s": samples / max(self.wall, 1e-9),
            }
        if self.test_source is not None and (step % int(tc.eval_every) == 0 or last):
            self.test_metrics = evaluate_test(model, self.test_source, self.body)
            stats.update({f"test/{k}": v for k, v in self.test_metrics.items()})
        return stats

    def progress_fields(self, stats: dict[str, float]) -> dict[str, float]:  # noqa: ARG002
        test = {"test_deg": self.test_metrics["joint_angle_deg"]} if self.test_metrics else {}
        return {"loss": self.ema, **test}

    def summary(self, stats: dict[str, float]) -> dict:  # noqa: ARG002
        train_w, test_w = self.train_w, self.test_w
        return {
            "step": self.iteration,
            "train_loss_ema": self.ema,
            **{f"test_{k}": v for k, v in self.test_metrics.items()},
            "train_wall_s": self.wall,
            "data_build_s": self.data_s,
            "train_windows": len(train_w),
            "test_windows": len(test_w),
            "pose_dim": self.body.pose_dim,
            "z_dim": self.model.z_dim,
            "parameters": sum(p.numel() for p in self.model.parameters()),
            "device": self.device,
            "train_clips": sorted({s.base for s in train_w.seqs}),
            "test_clips": sorted({s.base for s in test_w.seqs}),
        }


def train(cfg, run) -> dict:
    """Train one network into `run` with the shared runner (resumable) and write metrics.json."""
    from charctl.rl.runner import RunnerSettings, run_on_policy

    tc = cfg.train
    settings = RunnerSettings(
        total_iterations=int(tc.steps),
        budget_key="train.steps",
        iteration_name="step",
        checkpoint_every=int(tc.checkpoint_every),
        keep_every=int(tc.keep_checkpoint_every),
        description="com-cnn",
        track_blowups=False,
    )
    return run_on_policy(ComCnnLearner(cfg, run), run, settings)


def evaluate_test(model: ComCNN, source: BatchSource, body: BodyModel) -> dict:
    pred, target, loss = teacher_forced(model, source)
    return {"loss": loss, "joint_angle_deg": float(joint_angle_error_deg(pred, target, body).mean())}
