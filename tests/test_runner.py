"""The shared training runner (charctl.rl.runner) with a tiny fake learner: what every experiment on it
(cgail, srb, com-cnn, hopper-ga) gets without testing it again — a stop signal finishes the iteration,
checkpoints and raises `Interrupted` (exit 130 / 143: the first of one or two signals decides); --resume
continues the counters; a reached budget, a NaN statistic or parameter are one-line errors that keep the
last finite checkpoint (or say that none was written yet); budgets in samples or in iterations; a
per-iteration sample count read after each iteration (a GA's generations differ). One smoke per experiment
shows that its `charctl train` runs on the runner: a stop signal in its first iteration ends the command
the runner's way."""

from __future__ import annotations

import json
import os
import signal

import pytest
import torch

from charctl.errors import CharctlError, Diverged, Interrupted
from charctl.rl.runner import RunnerSettings, run_on_policy
from charctl.runs import Run


class FakeLearner:
    """Iteration i consumes `sizes[i % len(sizes)]` samples and returns loss 1 / (i + 1), or only every
    `log_stride`-th iteration (com-cnn's cadence); `events` maps an iteration number (1-based) to what
    happens in it: signals sent to this process in order ("SIGTERM", "SIGINT+SIGINT", ...), "nan" (the
    loss), "inf-weight" (a parameter)."""

    def __init__(self, sizes=(4,), events=None, log_stride: int = 1) -> None:
        self.iteration = 0
        self.samples = 0
        self.samples_per_iteration = sizes[0]
        self.sizes, self.events, self.log_stride = tuple(sizes), dict(events or {}), log_stride
        self.net = torch.nn.Linear(2, 1)
        self.seen: list[tuple[int, int]] = []  # (iteration, samples) at the start of each iterate()

    def iterate(self) -> dict[str, float]:
        i = self.iteration
        self.seen.append((i, self.samples))
        self.samples_per_iteration = self.sizes[i % len(self.sizes)]
        event = self.events.get(i + 1)
        if event and event.startswith("SIG"):
            for name in event.split("+"):
                os.kill(os.getpid(), getattr(signal, name))
        if event == "inf-weight":
            with torch.no_grad():
                self.net.weight.fill_(float("inf"))
        loss = float("nan") if event == "nan" else 1.0 / (i + 1)
        return {"train/loss": loss} if (i + 1) % self.log_stride == 0 or event == "nan" else {}

    def state_dict(self) -> dict:
        return {"iteration": self.iteration, "samples": self.samples, "net": self.net.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        self.iteration, self.samples = int(state["iteration"]), int(state["samples"])
        self.net.load_state_dict(state["net"])

    def signature(self) -> dict:
        return {"width": 2}

    def modules(self) -> list[torch.nn.Module]:
        return [self.net]

    def progress_fields(self, stats: dict[str, float]) -> dict[str, float]:  # noqa: ARG002
        return {"it": float(self.iteration)}

    def summary(self, stats: dict[str, float]) -> dict:  # noqa: ARG002
        return {"fake_iteration": self.iteration}


@pytest.fixture
def signals_restored(monkeypatch):
    """A stop leaves the StopFlag's handlers installed and the signal recorded (the process is meant to
    end): put both back for the rest of the test session."""
    import charctl.signals

    monkeypatch.setattr(charctl.signals, "_received", [])
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    yield
    for s, handler in old.items():
        signal.signal(s, handler)


def _run(path, resumed: bool = False) -> Run:
    return Run(dir=path, experiment="fake", cfg=None, resumed=resumed)


def _train(path, learner: FakeLearner, resumed: bool = False, **settings) -> dict:
    run = _run(path, resumed)
    try:
        return run_on_policy(learner, run, RunnerSettings(**settings))
    finally:
        run.close()


def _state(path, name: str = "last.pt") -> dict:
    from charctl.checkpoints import load_checkpoint

    return load_checkpoint(path / "checkpoints" / name, "fake")


def _metrics(path) -> dict:
    return json.loads((path / "metrics.json").read_text())


def _tb_steps(path) -> dict[str, list[int]]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(path / "tb"), size_guidance={"scalars": 0})
    acc.Reload()
    return {tag: [e.step for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}


BUDGETS = {  # (settings, the stop message's "at ...") for each kind of budget
    "iterations": ({"total_iterations": 10, "iteration_name": "step", "budget_key": "train.steps"}, "step 3/10"),
    "samples": ({"total_samples": 40}, "iteration 3"),  # cgail / srb: unchanged wording
}


@pytest.mark.parametrize("budget", list(BUDGETS))
def test_stop_signal_checkpoints_the_finished_iteration_and_resume_continues(
    budget, tmp_path, signals_restored, capsys
):
    settings, at = BUDGETS[budget]
    learner = FakeLearner(events={3: "SIGTERM"}, log_stride=2)  # iteration 3 logs nothing: the summary still comes
    with pytest.raises(Interrupted) as exc:
        _train(tmp_path, learner, checkpoint_every=100, **settings)
    assert exc.value.exit_code == 143
    assert str(exc.value) == f"interrupted at {at}: checkpoint written; continue with --resume {tmp_path}"
    state = _state(tmp_path)  # written by the stop (checkpoint_every is 100)
    assert (state["iteration"], state["samples"]) == (3, 12) and "torch_rng" in state
    assert _metrics(tmp_path) == {"interrupted": True, "iterations": 3, "samples": 12, "fake_iteration": 3}

    capsys.readouterr()
    resumed = FakeLearner(log_stride=2)
    metrics = _train(tmp_path, resumed, resumed=True, checkpoint_every=100, **settings)
    assert "training: 40/40 samples (100%)" in capsys.readouterr().err  # the bar counts samples either way
    assert resumed.seen[0] == (3, 12) and len(resumed.seen) == 7  # iterations 4..10, counted on from the checkpoint
    assert (metrics["iterations"], metrics["samples"], metrics["fake_iteration"]) == (10, 40, 10)
    assert metrics["wall_s"] >= 0 and metrics["samples_per_s"] > 0
    assert _metrics(tmp_path) == metrics
    assert _state(tmp_path)["iteration"] == 10

    key = settings.get("budget_key", "train.total_samples")
    total = settings.get("total_iterations", settings.get("total_samples"))
    with pytest.raises(CharctlError) as exc:  # a resume of a finished run
        _train(tmp_path, FakeLearner(), resumed=True, **settings)
    assert str(exc.value) == f"{tmp_path} already reached {key}={total}; raise it to continue ({key}=...)"
    # ...and a refused resume records nothing: its overrides reach resumes.txt only once training goes on
    run = Run(dir=tmp_path, experiment="fake", cfg=None, resumed=True, resume_overrides=["a.b=1"])
    with pytest.raises(CharctlError, match="already reached"):
        run_on_policy(FakeLearner(), run, RunnerSettings(**settings))
    run.close()
    assert not (tmp_path / "resumes.txt").exists()


# the signals of one stop, in the order they arrive, and the exit code (the first signal's: a second one only
# says that the stop is under way)
STOPS = [("SIGINT", 130), ("SIGINT+SIGINT", 130), ("SIGTERM", 143), ("SIGTERM+SIGINT", 143)]


@pytest.mark.parametrize("signals, code", STOPS, ids=[s for s, _ in STOPS])
def test_one_or_two_signals_finish_the_iteration_with_the_first_signals_exit_code(
    signals, code, tmp_path, signals_restored, capsys
):
    learner = FakeLearner(events={2: signals})
    with pytest.raises(Interrupted) as exc:
        _train(tmp_path, learner, total_iterations=10, iteration_name="step", checkpoint_every=100)
    assert exc.value.exit_code == code
    assert str(exc.value) == f"interrupted at step 2/10: checkpoint written; continue with --resume {tmp_path}"
    assert len(learner.seen) == 2 and _state(tmp_path)["iteration"] == 2  # the iteration finished, no other began
    assert [p for p in tmp_path.rglob("*") if ".tmp" in p.name] == []
    err = capsys.readouterr().err
    assert "stopping: finishing this iteration" in err and ("still stopping" in err) == ("+" in signals)


# every experiment's `charctl train`, long enough not to end before the stop: its overrides, the signals sent
# in its first iteration and the exit code
WIRED = {
    "com-cnn": (["scale=smoke", "train.steps=3000", "train.checkpoint_every=1000"], "SIGTERM", 143),
    "cgail": (["scale=smoke", "train.total_samples=200000", "train.checkpoint_every=1000"], "SIGINT+SIGINT", 130),
    "srb": (["scale=smoke", "train.total_samples=2000000", "train.checkpoint_every=1000"], "SIGTERM+SIGINT", 143),
    "hopper-ga": (["scale=smoke", "ga.generations=2000"], "SIGINT+SIGINT", 130),
}


@pytest.mark.parametrize("experiment", list(WIRED))
def test_every_experiment_trains_on_the_runner_and_stops_like_it(
    experiment, tmp_path, signals_restored, charctl_main, monkeypatch
):
    """`charctl train EXP` (main() in this process) hands its learner to run_on_policy, so a stop during the
    first iteration (its progress bar shown) ends it as the tests above show for any learner: the first
    signal's exit code, no traceback and no "done:", the last stderr line "interrupted ... --resume RUN",
    a checkpoint that loads as EXP's, no temp file. (tests/test_faults.py sends the signals from another
    process, to com-cnn.)"""
    import charctl.rl.runner as runner
    from charctl.checkpoints import load_checkpoint

    overrides, signals, code = WIRED[experiment]
    learners = []
    run_on_policy_itself = runner.run_on_policy

    def run_with_signals_in_the_first_iteration(learner, run, settings):
        learners.append(learner)
        iterate = learner.iterate

        def iterate_signalled():
            if learner.iteration == 0:
                for name in signals.split("+"):
                    os.kill(os.getpid(), getattr(signal, name))
            return iterate()

        learner.iterate = iterate_signalled
        return run_on_policy_itself(learner, run, settings)

    monkeypatch.setattr(runner, "run_on_policy", run_with_signals_in_the_first_iteration)
    out = tmp_path / "out"
    res = charctl_main("train", experiment, *overrides, f"output_root={out}")
    assert len(learners) == 1, "the experiment did not train through charctl.rl.runner.run_on_policy"
    assert res.returncode == code, f"exit {res.returncode}:\n{res.stdout}\n{res.stderr}"
    before_stop = res.stderr.split("stopping:")[0]  # the signals came with the loop (and its progress bar) running
    assert " samples (" in before_stop or " gen (" in before_stop, res.stderr
    assert "Traceback" not in res.stdout + res.stderr and "done:" not in res.stdout
    last = [line for line in res.stderr.splitlines() if line.strip()][-1]
    assert last.startswith("interrupted") and "--resume" in last, last
    (run_dir,) = sorted(p for p in (out / experiment).glob("*") if (p / "config.yaml").is_file())
    assert str(run_dir) in last
    state = load_checkpoint(run_dir / "checkpoints" / "last.pt", experiment)  # weights_only, experiment checked
    assert state is not None and learners[0].iteration == 1
    assert [p for p in run_dir.rglob("*") if ".tmp" in p.name] == []


@pytest.mark.parametrize("event, what", [("nan", "train/loss = nan"), ("inf-weight", "parameter Linear.weight")])
def test_non_finite_stat_or_parameter_stops_with_one_line_and_keeps_the_last_checkpoint(event, what, tmp_path):
    learner = FakeLearner(events={5: event})
    with pytest.raises(Diverged) as exc:
        _train(tmp_path, learner, total_iterations=10, iteration_name="step", checkpoint_every=2)
    message = str(exc.value)
    assert "\n" not in message and message.startswith(f"training diverged at step 5 ({what})")
    assert f"the last finite checkpoint {tmp_path / 'checkpoints' / 'last.pt'} was kept" in message
    state = _state(tmp_path)
    assert state["iteration"] == 4 and bool(torch.isfinite(state["net"]["weight"]).all())
    metrics = _metrics(tmp_path)
    assert metrics == {"diverged": True, "error": message, "iterations": 5, "samples": 20}


def test_divergence_before_the_first_checkpoint_says_that_none_was_written(tmp_path):
    """cgail / srb with ppo.lr=10 diverge in their first iteration (tests/test_faults.py): the line then says
    that no checkpoint was kept, and none is left behind."""
    with pytest.raises(Diverged) as exc:
        _train(tmp_path, FakeLearner(events={1: "nan"}), total_iterations=10, iteration_name="step")
    message = str(exc.value)
    assert message.startswith("training diverged at step 1 (train/loss = nan); no checkpoint had been written yet")
    assert not (tmp_path / "checkpoints" / "last.pt").exists()
    assert _metrics(tmp_path) == {"diverged": True, "error": message, "iterations": 1, "samples": 4}


def test_samples_per_iteration_is_read_after_each_iteration_and_kept_checkpoints_follow_it(tmp_path, capsys):
    """A GA's generations evaluate different numbers of individuals: the runner counts what each
    iteration reports, logs at that count and keeps checkpoints when it crosses `keep_every`."""
    learner = FakeLearner(sizes=(7, 3, 5))
    metrics = _train(tmp_path, learner, total_iterations=6, iteration_name="generation", keep_every=10, bar_unit="gen")
    assert "training: 6/6 gen (100%)" in capsys.readouterr().err  # the bar counts generations
    counts = [7, 10, 15, 22, 25, 30]
    assert [s for _, s in learner.seen] == [0, *counts[:-1]]
    assert metrics["iterations"] == 6 and metrics["samples"] == 30
    assert _tb_steps(tmp_path)["train/loss"] == counts  # logged at the sample count
    kept = sorted(p.name for p in (tmp_path / "checkpoints").glob("samples_*.pt"))
    assert kept == ["samples_000000010.pt", "samples_000000022.pt", "samples_000000030.pt"]  # past 10, 20, 30
    assert _state(tmp_path, "samples_000000022.pt")["iteration"] == 4
    assert "sim/blowup_rate" in _tb_steps(tmp_path)  # tracked by default (PPO learners step a simulator) ...
    _train(tmp_path / "plain", FakeLearner(), total_iterations=2, track_blowups=False)
    assert set(_tb_steps(tmp_path / "plain")) == {"train/loss"}  # ... not for a learner without one


def test_settings_need_exactly_one_budget_and_a_bar_they_can_fill():
    for bad in ({}, {"total_samples": 10, "total_iterations": 2}):
        with pytest.raises(ValueError, match="exactly one"):
            RunnerSettings(**bad)
    with pytest.raises(ValueError, match="iteration budget"):
        RunnerSettings(total_samples=10, bar_unit="gen")
