"""The training loop's plumbing, shared by every experiment that trains in iterations: the PPO
experiments (cgail, srb: one iteration = rollout + updates), com-cnn (one iteration = one minibatch
step of the supervised CNN) and hopper-ga (one iteration = one generation of the GA).

An experiment supplies a *learner*: an object that knows how to run one iteration and how to save
and restore itself. The runner owns everything around it, the same way for every experiment (the
rsl_rl pattern: a runner owns the loop, the algorithm is small):

- resume from the run's last checkpoint (shape-checked by the learner's signature);
- stop signals: the first Ctrl-C / SIGTERM finishes the iteration, writes the checkpoint and ends
  the run with `Interrupted` (exit 130 / 143 at the CLI);
- a budget in samples (`total_samples`) or in iterations (`total_iterations`), and a progress bar
  over samples (or iterations, `bar_unit`) with the learner's chosen live statistics;
- TensorBoard scalars (at the sample count) every `log_every` iterations, periodic and final
  checkpoints, and checkpoints kept every `keep_every` samples;
- divergence: a non-finite statistic or parameter stops the run *without* overwriting the last
  (finite) checkpoint, writes `{"diverged": true, ...}` metrics and raises a one-line error;
- the simulator's blow-up rate (`sim/blowup_rate`, a warning when it stays high), for learners that
  step a simulator (`track_blowups`);
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
    """What an experiment plugs into `run_on_policy`. The runner advances `iteration` (by one) and
    `samples` (by `samples_per_iteration`) after each `iterate()`."""

    iteration: int  # completed iterations
    samples: int  # samples consumed so far: environment steps, training examples, GA evaluations
    # samples consumed by the last iterate(), read right after it: constant for PPO and com-cnn, the
    # generation's evaluations for hopper-ga
    samples_per_iteration: int

    def iterate(self) -> dict[str, float]:
        """One iteration; returns the scalars to log for it, keyed by their TensorBoard names (every one
        is checked for NaN / inf; a learner may return only some on some iterations, e.g. com-cnn's
        held-out loss every train.eval_every steps)."""

    def state_dict(self) -> dict:
        """Everything a checkpoint holds (tensors, numbers, strings, lists, dicts only)."""

    def load_state_dict(self, state: dict) -> None: ...

    def signature(self) -> dict:
        """Shapes that must match for a checkpoint to load (network widths, skill names ...)."""

    def modules(self) -> list[torch.nn.Module]:
        """Networks whose parameters must stay finite (none for a GA)."""

    def progress_fields(self, stats: dict[str, float]) -> dict[str, float]:
        """The few statistics shown on the progress bar."""

    def summary(self, stats: dict[str, float]) -> dict:
        """Experiment-specific final metrics from the last iteration's statistics (also on a stop: the
        place for outputs an interrupted run should still leave, e.g. hopper-ga's figures)."""


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
    """Loop settings (from the experiment's `train` config section). The budget is `total_samples`
    (cgail, srb) or `total_iterations` (com-cnn's steps, hopper-ga's generations): exactly one > 0."""

    total_samples: int = 0  # train until this many samples (cgail, srb) ...
    total_iterations: int = 0  # ... or until this many iterations (com-cnn: train.steps, hopper-ga: ga.generations)
    budget_key: str = "train.total_samples"  # the config key of the budget, named when a resume already reached it
    iteration_name: str = "iteration"  # what an iteration is called in messages ("interrupted at step 12")
    # "samples": the progress bar counts samples (with an iteration budget, the remaining iterations at the
    # current samples_per_iteration); another word (hopper-ga: "gen") counts iterations under that name
    bar_unit: str = "samples"
    checkpoint_every: int = 10  # iterations
    keep_every: int = 0  # samples between checkpoints kept as checkpoints/samples_<n>.pt (0 = only last.pt)
    log_every: int = 1  # iterations
    description: str = "training"
    track_blowups: bool = True  # the learner steps a simulator: sim/blowup_rate and its warning
    blowup_threshold: float = 0.01  # simulator resets per sample above which a sustained rate is warned
    blowup_window: int = 10  # iterations the rate must stay above the threshold

    def __post_init__(self) -> None:
        if (self.total_samples > 0) == (self.total_iterations > 0):
            raise ValueError("RunnerSettings needs exactly one of total_samples and total_iterations > 0")
        if self.bar_unit != "samples" and not self.by_iterations:
            raise ValueError("a progress bar over iterations needs an iteration budget (total_iterations)")

    @property
    def by_iterations(self) -> bool:
        return self.total_iterations > 0

    @property
    def total(self) -> int:
        return int(self.total_iterations if self.by_iterations else self.total_samples)

    def done(self, learner: Learner) -> int:
        """How much of the budget `learner` has used, in the budget's unit."""
        return learner.iteration if self.by_iterations else learner.samples

    def bar(self, learner: Learner) -> tuple[int, int]:
        """(total, done) of the progress bar, in `bar_unit`."""
        if self.bar_unit != "samples":
            return self.total_iterations, learner.iteration
        if self.by_iterations:
            remaining = self.total_iterations - learner.iteration
            return learner.samples + remaining * learner.samples_per_iteration, learner.samples
        return self.total_samples, learner.samples

    def at(self, learner: Learner) -> str:
        """ "iteration 12" (a sample budget) or "step 12/3000" (an iteration budget)."""
        total = f"/{self.total_iterations}" if self.by_iterations else ""
        return f"{self.iteration_name} {learner.iteration}{total}"


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


def _stop_if_diverged(learner: Learner, run, stats: dict[str, float], name: str = "iteration") -> None:
    """Raise `Diverged` (before any checkpoint of this iteration is written) on a NaN/inf."""
    try:
        where = f"{name} {learner.iteration}"
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
    """Train `learner` until its budget (`settings.total_samples` or `total_iterations`), writing into
    `run` (charctl.runs.Run)."""
    from charctl.progress import TrainingProgress
    from charctl.signals import StopFlag

    if run.resumed:
        _resume(learner, run)
    total = settings.total
    if settings.done(learner) >= total:
        key = settings.budget_key
        raise CharctlError(f"{run.dir} already reached {key}={total}; raise it to continue ({key}=...)")
    if run.resumed:
        run.record_resume()
    samples_at_start, iterations_at_start, stats = learner.samples, learner.iteration, {}
    blowups = BlowupMonitor(settings.blowup_threshold, settings.blowup_window)
    bar_total, bar_done = settings.bar(learner)
    t_start = time.perf_counter()
    with StopFlag() as stop, TrainingProgress(bar_total, settings.description, unit=settings.bar_unit) as bar:
        bar.resume_at(bar_done)
        while settings.done(learner) < total:
            stats = learner.iterate()
            step = learner.samples_per_iteration  # read after iterate(): a GA's generations differ
            learner.iteration += 1
            learner.samples += step
            _stop_if_diverged(learner, run, stats, settings.iteration_name)
            _watch_blowups(stats, blowups, settings, step)
            if learner.iteration % settings.log_every == 0:
                run.log_scalars(stats, learner.samples)
            fields = learner.progress_fields(stats)
            if blowups.active:
                fields["BLOWUPS"] = f"{100 * blowups.rate:.1f}%"
            bar.update(step if settings.bar_unit == "samples" else 1, **fields)
            _save_due_checkpoints(learner, run, settings, step, stop.requested)
            if stop.requested:
                break
    if stop.requested:
        _write_interrupted(learner, run, stats, iterations_at_start)
        message = f"interrupted at {settings.at(learner)}: checkpoint written; continue with --resume {run.dir}"
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


def _resume(learner: Learner, run) -> None:
    """Load the run's last checkpoint into `learner` and restore the RNG states saved with it."""
    state = run.load_checkpoint(learner.signature())
    learner.load_state_dict(state)
    note = restore_rng_states(state)
    if note:
        print(note, flush=True)


def _watch_blowups(stats: dict, blowups: BlowupMonitor, settings: RunnerSettings, step: int) -> None:
    """With `settings.track_blowups`: feed the iteration's unstable resets to `blowups`, add its rate to
    `stats` (sim/blowup_rate) and print its warning, if any."""
    warning = None
    if settings.track_blowups:
        warning = blowups.update(stats.get("sim/unstable_resets", 0.0), step)
        stats["sim/blowup_rate"] = blowups.rate
    if warning:
        print(f"\n{warning}", flush=True)


def _save_due_checkpoints(learner: Learner, run, settings: RunnerSettings, step: int, stopping: bool) -> None:
    """last.pt every `checkpoint_every` iterations or when stopping, and a kept checkpoint each time the
    sample count passes a multiple of `keep_every`; one state (with the RNG states) for both files."""
    from charctl.checkpoints import kept_checkpoint_name

    names = ["last.pt"] if learner.iteration % settings.checkpoint_every == 0 or stopping else []
    if crossed_multiple(learner.samples, step, settings.keep_every):
        names.append(kept_checkpoint_name(learner.samples))
    if names:
        state = with_rng_states(learner.state_dict())  # built once for both files
        for name in names:
            run.save_checkpoint(state, learner.signature(), name=name)


def _write_interrupted(learner: Learner, run, stats: dict, iterations_at_start: int) -> None:
    """metrics.json of a stopped run, then close the run."""
    # metrics.json describes the run as it stands (replacing e.g. a diverged entry of an earlier segment)
    summary = learner.summary(stats) if learner.iteration > iterations_at_start else {}
    run.write_metrics({"interrupted": True, "iterations": learner.iteration, "samples": learner.samples, **summary})
    run.close()
