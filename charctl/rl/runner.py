"""The on-policy training loop's plumbing, shared by every PPO experiment (cgail, srb).

An experiment supplies a *learner*: an object that knows how to run one iteration (rollout +
updates) and how to save and restore itself. The runner owns everything around it, the same
way for every experiment (the rsl_rl pattern: a runner owns the loop, the algorithm is small):

- resume from the run's last checkpoint (shape-checked by the learner's signature);
- stop signals: the first Ctrl-C / SIGTERM finishes the iteration, writes the checkpoint and ends
  the run with `Interrupted` (exit 130 / 143 at the CLI);
- a progress bar over samples with the learner's chosen live statistics;
- TensorBoard scalars every `log_every` iterations, periodic and final checkpoints;
- divergence: a non-finite statistic or parameter stops the run *without* overwriting the last
  (finite) checkpoint, and raises a one-line error;
- final metrics with the same keys for every experiment (`iterations`, `samples`, `wall_s`,
  `samples_per_s`, then the learner's own);
- torch's global random states in every checkpoint (`torch_rng`, and `cuda_rng` when CUDA is in
  use), restored on resume; a checkpoint written on a GPU resumes on a CPU-only machine without
  its CUDA states (a note says so).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Protocol

import torch

from charctl.errors import CharctlError
from charctl.guard import BlowupMonitor, check_finite, check_policy_step


class Learner(Protocol):
    """What an experiment plugs into `run_on_policy`."""

    iteration: int  # completed iterations
    samples: int  # environment steps consumed so far
    samples_per_iteration: int

    def iterate(self) -> dict[str, float]:
        """One iteration (rollout + updates); returns scalars keyed by their TensorBoard names."""

    def state_dict(self) -> dict:
        """Everything a checkpoint holds (tensors, numbers, strings, lists, dicts only)."""

    def load_state_dict(self, state: dict) -> None: ...

    def signature(self) -> dict:
        """Shapes that must match for a checkpoint to load (network widths, skill names ...)."""

    def modules(self) -> list[torch.nn.Module]:
        """Networks whose parameters must stay finite."""

    def progress_fields(self, stats: dict[str, float]) -> dict[str, float]:
        """The few statistics shown on the progress bar."""

    def summary(self, stats: dict[str, float]) -> dict:
        """Experiment-specific final metrics from the last iteration's statistics."""


class AgentCounters:
    """Mixin for learners whose counters live on `self.agent` (so checkpoints keep their layout):
    `iteration` and `samples` read and write `self.agent.iteration` / `self.agent.samples`."""

    agent: object

    @property
    def iteration(self) -> int:
        return self.agent.iteration

    @iteration.setter
    def iteration(self, value: int) -> None:
        self.agent.iteration = value

    @property
    def samples(self) -> int:
        return self.agent.samples

    @samples.setter
    def samples(self, value: int) -> None:
        self.agent.samples = value


@dataclass(frozen=True)
class RunnerSettings:
    """Loop settings (from the experiment's `train` config section)."""

    total_samples: int
    checkpoint_every: int = 10  # iterations
    keep_every: int = 0  # samples between checkpoints kept as checkpoints/samples_<n>.pt (0 = only last.pt)
    log_every: int = 1  # iterations
    description: str = "training"
    blowup_threshold: float = 0.01  # simulator resets per sample above which a sustained rate is warned
    blowup_window: int = 10  # iterations the rate must stay above the threshold


# ---------------------------------------------------------------------------- random states
TORCH_RNG_KEY = "torch_rng"  # CPU generator state (ByteTensor), saved and restored here for every learner
CUDA_RNG_KEY = "cuda_rng"  # list of ByteTensors, one per visible CUDA device


def cuda_rng_states() -> list[torch.Tensor] | None:
    """Every visible CUDA device's global generator state (CPU ByteTensors), or None when CUDA is
    absent or not initialised (nothing in this process used it, so there is nothing to keep, and
    asking would create a CUDA context)."""
    if not torch.cuda.is_available() or not torch.cuda.is_initialized():
        return None
    return [s.cpu() for s in torch.cuda.get_rng_state_all()]


def with_rng_states(state: dict) -> dict:
    """`state` plus torch's global random states: `torch_rng` (unless the learner stored its own) and
    `cuda_rng` when CUDA is in use. Plain tensors and lists, so `weights_only=True` loading works."""
    out = dict(state)
    out.setdefault(TORCH_RNG_KEY, torch.get_rng_state())
    cuda = cuda_rng_states()
    if cuda is not None:
        out[CUDA_RNG_KEY] = cuda
    return out


def restore_rng_states(state: dict) -> str | None:
    """Set torch's global random states from a checkpoint's `state` (keys absent: left alone).
    Returns a note when CUDA states were skipped (no CUDA here, or fewer devices than saved)."""
    if TORCH_RNG_KEY in state:
        torch.set_rng_state(state[TORCH_RNG_KEY].cpu())
    saved = state.get(CUDA_RNG_KEY)
    if not saved:
        return None
    if not torch.cuda.is_available():
        return (
            f"note: the checkpoint holds CUDA random states of {len(saved)} device(s) but CUDA is not "
            "available here; they are skipped (CPU random states are restored)"
        )
    count = torch.cuda.device_count()
    for index, s in enumerate(saved[:count]):
        torch.cuda.set_rng_state(s.cpu(), index)  # lazy: applied when CUDA initialises
    if len(saved) > count:
        return f"note: the checkpoint holds CUDA random states of {len(saved)} devices, this machine has {count}"
    return None


def _stop_if_diverged(learner: Learner, run, stats: dict[str, float]) -> None:
    """Raise `Diverged` (before any checkpoint of this iteration is written) on a NaN/inf."""
    try:
        where = f"iteration {learner.iteration}"
        check_finite(stats, *learner.modules(), where=where, checkpoint=run.checkpoint_path)
        check_policy_step(stats, where=where, checkpoint=run.checkpoint_path)
    except CharctlError as exc:
        run.log_scalars({k: v for k, v in stats.items() if math.isfinite(v)}, learner.samples)
        run.write_metrics(
            {"diverged": True, "error": str(exc), "iterations": learner.iteration, "samples": learner.samples}
        )
        run.close()
        raise


def crossed_multiple(samples: int, step: int, every: int) -> bool:
    """True when the count went past a multiple of `every` in its last `step` (never for every <= 0)."""
    return every > 0 and samples // every > (samples - step) // every


def run_on_policy(learner: Learner, run, settings: RunnerSettings) -> dict:
    """Train `learner` until `settings.total_samples`, writing into `run` (charctl.runs.Run)."""
    from charctl.checkpoints import kept_checkpoint_name
    from charctl.progress import TrainingProgress
    from charctl.signals import StopFlag

    if run.resumed:
        state = run.load_checkpoint(learner.signature())
        learner.load_state_dict(state)
        note = restore_rng_states(state)
        if note:
            print(note, flush=True)
    total = int(settings.total_samples)
    if learner.samples >= total:
        raise CharctlError(
            f"{run.dir} already reached train.total_samples={total}; raise it to continue (train.total_samples=...)"
        )
    samples_at_start, stats = learner.samples, {}
    blowups = BlowupMonitor(settings.blowup_threshold, settings.blowup_window)
    t_start = time.perf_counter()
    with StopFlag() as stop, TrainingProgress(total, settings.description) as bar:
        bar.resume_at(learner.samples)
        while learner.samples < total:
            stats = learner.iterate()
            learner.iteration += 1
            learner.samples += learner.samples_per_iteration
            _stop_if_diverged(learner, run, stats)
            warning = blowups.update(stats.get("sim/unstable_resets", 0.0), learner.samples_per_iteration)
            stats["sim/blowup_rate"] = blowups.rate
            if warning:
                print(f"\n{warning}", flush=True)
            if learner.iteration % settings.log_every == 0:
                run.log_scalars(stats, learner.samples)
            fields = learner.progress_fields(stats)
            if blowups.active:
                fields["BLOWUPS"] = f"{100 * blowups.rate:.1f}%"
            bar.update(learner.samples_per_iteration, **fields)
            names = ["last.pt"] if learner.iteration % settings.checkpoint_every == 0 or stop.requested else []
            if crossed_multiple(learner.samples, learner.samples_per_iteration, settings.keep_every):
                names.append(kept_checkpoint_name(learner.samples))
            if names:
                state = with_rng_states(learner.state_dict())  # built once for both files
                for name in names:
                    run.save_checkpoint(state, learner.signature(), name=name)
            if stop.requested:
                break
    if stop.requested:
        # metrics.json describes the run as it stands (replacing e.g. a diverged entry of an earlier segment)
        summary = learner.summary(stats) if stats else {}
        run.write_metrics({"interrupted": True, "iterations": learner.iteration, "samples": learner.samples, **summary})
        run.close()
        message = f"interrupted at iteration {learner.iteration}: checkpoint written; continue with --resume {run.dir}"
        raise stop.interrupted(message)
    run.save_checkpoint(with_rng_states(learner.state_dict()), learner.signature())
    wall = time.perf_counter() - t_start
    metrics = {
        "iterations": learner.iteration,
        "samples": learner.samples,
        "wall_s": round(wall, 1),
        "samples_per_s": (learner.samples - samples_at_start) / max(wall, 1e-9),
        **learner.summary(stats),
    }
    run.write_metrics(metrics)
    return metrics
