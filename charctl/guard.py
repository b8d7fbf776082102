"""Divergence guards shared by every training loop.

    from charctl.guard import BlowupMonitor, check_finite

    stats = learner.iterate()                        # dict of floats (losses, rewards, ...)
    check_finite(stats, model, disc, where=f"iteration {it}", checkpoint=run.checkpoint_path)
    # -> raises charctl.errors.Diverged naming the first NaN/inf statistic or parameter;
    #    call it *before* writing a checkpoint, so the last checkpoint on disk stays finite.

    monitor = BlowupMonitor(threshold=0.05, window=10)
    warning = monitor.update(resets=ro.unstable, samples=n)   # None, or a one-line warning
    stats["sim/blowup_rate"] = monitor.rate                    # for TensorBoard

Torch is imported lazily (only when modules are given).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from charctl.errors import Diverged


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def first_non_finite(stats: dict | None = None, *modules: Any) -> str | None:
    """`"train/loss = nan"` or `"parameter ActorCritic.actor.0.weight"` for the first non-finite
    statistic (numbers, numpy / 0-d torch scalars) or parameter of `modules`; None when all finite."""
    for key, value in (stats or {}).items():
        if hasattr(value, "item") and getattr(value, "ndim", 1) == 0:
            value = value.item()
        if _is_number(value) and not math.isfinite(float(value)):
            return f"{key} = {value}"
    for module in _flatten(modules):
        if module is None:
            continue
        named = module.named_parameters() if hasattr(module, "named_parameters") else []
        for name, p in named:
            import torch

            if not bool(torch.isfinite(p.detach()).all()):
                return f"parameter {type(module).__name__}.{name}"
    return None


def _flatten(modules: Iterable[Any]) -> list:
    out: list = []
    for m in modules:
        if isinstance(m, (list, tuple)):
            out += _flatten(m)
        else:
            out.append(m)
    return out


def check_finite(
    stats: dict | None = None, *modules: Any, where: str = "", checkpoint: str | Path | None = None
) -> None:
    """Raise `Diverged` if a statistic of `stats` or a parameter of `modules` is NaN or infinite.

    `where` (e.g. "step 120" / "iteration 4") and `checkpoint` (the path that was *not*
    overwritten) make the one-line message say what happened and what is kept.
    """
    bad = first_non_finite(stats, *modules)
    if bad is not None:
        raise diverged(bad, where=where, checkpoint=checkpoint)


MAX_RATIO_CLAMPED = 0.01  # share of PPO samples whose log-ratio left +-LOG_RATIO_LIMIT within one update


def check_policy_step(stats: dict, where: str = "", checkpoint: str | Path | None = None) -> None:
    """Raise `Diverged` when PPO's log-ratio clamp (charctl.rl.ppo) caught more than 1 % of an update's
    samples: an isolated outlier is absorbed by the clamp, a policy that jumps everywhere has diverged
    (e.g. a learning rate of 10), even though every number stays finite."""
    share = float(stats.get("losses/ratio_clamped", 0.0))
    if share > MAX_RATIO_CLAMPED:
        what = f"the policy's log-probability moved by > 20 nats on {100 * share:.1f} % of samples in one update"
        raise diverged(what, where=where, checkpoint=checkpoint)


def diverged(what: str, where: str = "", checkpoint: str | Path | None = None) -> Diverged:
    """The `Diverged` exception with the standard message."""
    at = f" at {where}" if where else ""
    if checkpoint is not None and Path(checkpoint).is_file():
        kept = f"the last finite checkpoint {checkpoint} was kept"
    elif checkpoint is not None:
        kept = "no checkpoint had been written yet"
    else:
        kept = "the last finite checkpoint was kept"
    return Diverged(f"training diverged{at} ({what}); {kept}; lower the learning rate(s) and train again")


class BlowupMonitor:
    """Warns when the simulator's blow-up (unstable reset) rate stays above `threshold` for
    `window` consecutive updates.

    `update(resets, samples)` takes the resets and samples of one iteration and returns a
    one-line warning (once, when the condition starts; again only after it cleared) or None.
    `rate` is the mean rate over the window (resets per sample), for the progress bar and
    TensorBoard; `warning` is the active warning text (or "").
    """

    def __init__(self, threshold: float = 0.01, window: int = 10) -> None:
        if window < 1:
            raise ValueError("window must be >= 1")
        self.threshold = float(threshold)
        self.window = int(window)
        self._resets: deque = deque(maxlen=self.window)
        self._samples: deque = deque(maxlen=self.window)
        self._above: deque = deque(maxlen=self.window)
        self.active = False
        self.warning = ""

    @property
    def rate(self) -> float:
        n = sum(self._samples)
        return float(sum(self._resets)) / n if n > 0 else 0.0

    def update(self, resets: float, samples: float) -> str | None:
        self._resets.append(float(resets))
        self._samples.append(float(samples))
        self._above.append(float(resets) > self.threshold * float(samples))
        sustained = len(self._above) == self.window and all(self._above)
        if sustained and not self.active:
            self.active = True
            self.warning = (
                f"warning: simulator blow-ups at {100 * self.rate:.1f}% of samples for {self.window} "
                f"iterations (threshold {100 * self.threshold:.1f}%); check the physics rate, action scale "
                f"and learning rates"
            )
            return self.warning
        if self.active and not any(self._above):
            self.active = False
            self.warning = ""
        return None
