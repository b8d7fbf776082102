"""`charctl train com-cnn`: supervised training of the COM-conditioned CNN (paper §3.4).

Loss: MSE between the standardised prediction and the standardised ground-truth pose (paper eq.
Cost = ||y - P({N(M), C})||^2 on standardised vectors). Minibatches are drawn uniformly from every
training window (paper §3.4: every frame cut into history-length sub-clips, sampled at random).
"""

from __future__ import annotations

import time

import numpy as np

from charctl.experiments.com_cnn.data import BodyModel, WindowSet, build_windows, constrain_joint_exp
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


def train(cfg, run) -> dict:
    """Train one network into `run` (resumable) and write metrics.json."""
    import torch

    from charctl.guard import diverged, first_non_finite
    from charctl.progress import TrainingProgress
    from charctl.signals import StopFlag

    torch.set_num_threads(int(cfg.train.torch_threads))
    torch.manual_seed(int(cfg.seed))
    device = pick_device(str(cfg.device))
    t_data = time.perf_counter()
    train_w, test_w, body = build_windows(cfg)
    source = BatchSource(train_w, device, int(cfg.data.window_cache_mb))
    test_source = BatchSource(test_w, device, int(cfg.data.window_cache_mb)) if len(test_w) else None
    data_s = time.perf_counter() - t_data
    model = build_model(cfg, body.pose_dim).to(device)
    model.set_normalizer(normalizer_stats(source))
    opt = make_optimizer(model.parameters(), cfg.train)
    signature = model_signature(cfg, body.pose_dim)
    step, wall, ema = 0, 0.0, None
    if run.resumed and run.has_checkpoint():
        state = run.load_checkpoint(signature)
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["optimizer"])
        step, wall, ema = int(state["step"]), float(state["train_wall_s"]), state.get("loss_ema")
        print(f"resumed at step {step}")
    steps, batch = int(cfg.train.steps), int(cfg.train.batch_size)

    def save() -> None:
        bad = first_non_finite({"train/loss_ema": ema}, model)
        if bad:  # never overwrite the last finite checkpoint with a diverged network
            stop_diverged(bad)
        run.save_checkpoint(
            {
                "model": model.state_dict(),
                "optimizer": opt.state_dict(),
                "step": step,
                "train_wall_s": wall,
                "loss_ema": ema,
                "pose_dim": body.pose_dim,
            },
            signature,
        )

    def stop_diverged(what: str) -> None:
        run.log_scalars({"train/diverged": 1.0}, step * batch)
        run.write_metrics(
            {
                "diverged": True,
                "diverged_at_step": step,
                "diverged_on": what,
                "step": step,
                "samples": step * batch,
                "train_loss_ema": ema,
                "wall_s": wall,
                "device": device,
            }
        )
        raise diverged(what, where=f"step {step}", checkpoint=run.checkpoint_path)

    test_metrics: dict = {}
    with StopFlag() as stop, TrainingProgress(steps * batch, "com-cnn", unit="samples") as bar:
        bar.update(step * batch)
        while step < steps:
            t0 = time.perf_counter()
            idx = np.random.default_rng([int(cfg.seed), step]).integers(0, len(source), size=batch)
            hist, com, target = source.batch(idx)
            h, c = model.normalize_inputs(hist, com)
            loss = ((model.forward_normalized(h, c) - model.normalize_pose(target)) ** 2).mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            if cfg.train.grad_clip > 0:
                torch.nn.utils.clip_grad_norm_(model.parameters(), float(cfg.train.grad_clip))
            opt.step()
            wall += time.perf_counter() - t0
            step += 1
            lv = float(loss.detach())
            if not np.isfinite(lv):  # the update that produced this loss has already been applied: stop here
                stop_diverged(f"train/loss = {lv}")
            ema = lv if ema is None else 0.98 * ema + 0.02 * lv
            if step % 20 == 0 or step == steps:
                run.log_scalars(
                    {"train/loss": lv, "train/loss_ema": ema, "train/samples_per_s": step * batch / max(wall, 1e-9)},
                    step * batch,
                )
            if test_source is not None and (step % int(cfg.train.eval_every) == 0 or step == steps):
                test_metrics = evaluate_test(model, test_source, body)
                run.log_scalars({f"test/{k}": v for k, v in test_metrics.items()}, step * batch)
            bar.update(batch, loss=ema, **({"test_deg": test_metrics["joint_angle_deg"]} if test_metrics else {}))
            if step % int(cfg.train.checkpoint_every) == 0 or stop.requested:
                save()
            if stop.requested:
                raise stop.interrupted(
                    f"interrupted at step {step} ({step * batch} samples): checkpoint written; "
                    f"continue with --resume {run.dir}"
                )
    save()
    metrics = {
        "step": step,
        "samples": step * batch,
        "train_loss_ema": ema,
        **{f"test_{k}": v for k, v in test_metrics.items()},
        "wall_s": wall,
        "samples_per_s": step * batch / max(wall, 1e-9),
        "data_build_s": data_s,
        "train_windows": len(train_w),
        "test_windows": len(test_w),
        "pose_dim": body.pose_dim,
        "z_dim": model.z_dim,
        "parameters": sum(p.numel() for p in model.parameters()),
        "device": device,
        "train_clips": sorted({s.base for s in train_w.seqs}),
        "test_clips": sorted({s.base for s in test_w.seqs}),
    }
    run.write_metrics(metrics)
    return metrics


def evaluate_test(model: ComCNN, source: BatchSource, body: BodyModel) -> dict:
    pred, target, loss = teacher_forced(model, source)
    return {"loss": loss, "joint_angle_deg": float(joint_angle_error_deg(pred, target, body).mean())}
