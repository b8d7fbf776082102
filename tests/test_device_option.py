"""The `device` option beyond training (GitHub issue #14), checked on the CPU.

- `charctl eval RUN device=cpu` (cgail DTW / confusion / switch): the override is accepted, the
  inference networks sit on the named device, and the numbers equal the default's; a device this
  machine lacks is a one-line error raised before anything is loaded or written.
- Checkpoints of the shared on-policy runner keep torch's random states: the CPU state (also for
  learners that do not store it themselves) and, when CUDA is in use, every device's CUDA state
  (`cuda_rng`, a list of ByteTensors that loads with `weights_only=True`). A checkpoint written on a
  GPU resumes on a CPU-only machine: its CUDA states are skipped with a note.
The CUDA side is faked by monkeypatching `torch.cuda`; a real GPU runs the last test.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from conftest import assert_one_line

EVAL_MODES = {
    "dtw": True,
    "confusion": True,
    "switch": ("walk", "right_kick"),
    "curves": False,
    "survival": None,
    "episodes": 2,
}


def _eval(run_dir: Path, out: Path, *overrides: str) -> dict[str, dict]:
    """`charctl eval RUN --dtw --confusion --switch walk right_kick -k 2 -o OUT [overrides]` in this
    process; returns the JSON results by file name."""
    from charctl.experiments.cgail.evaluate import evaluate

    evaluate([str(run_dir)], {**EVAL_MODES, "out": out}, list(overrides))
    return {p.name: json.loads(p.read_text()) for p in sorted(out.glob("*.json"))}


# ---------------------------------------------------------------------------- evaluation
def test_eval_device_cpu_gives_the_default_numbers(smoke_run, tmp_path):
    run = smoke_run("cgail")
    default = _eval(run, tmp_path / "default")
    on_cpu = _eval(run, tmp_path / "cpu", "device=cpu")
    assert set(default) == {"dtw.json", "confusion.json", "switch_walk_to_right_kick.json"}
    for name, result in default.items():
        assert on_cpu[name] == result, name  # bit-identical: same device, same float operations
    assert all(isinstance(v, float) for v in default["confusion.json"]["policy_diagonal"])


def test_eval_run_networks_sit_on_the_chosen_device(smoke_run):
    from charctl.experiments.cgail.rollouts import load_eval_run

    tr = load_eval_run(smoke_run("cgail"), "cpu")
    assert tr.device == "cpu"
    assert {p.device.type for m in (tr.agent.model, tr.agent.disc) for p in m.parameters()} == {"cpu"}
    assert load_eval_run(smoke_run("cgail")).device == ("cuda" if torch.cuda.is_available() else "cpu")  # auto


@pytest.mark.parametrize(
    "overrides, words",
    [
        (["device=tpu"], ["device must be auto, cpu, cuda or cuda:N", "tpu"]),
        (["env.num_envs=4"], ["output_root=", "device=", "env.num_envs=4"]),
    ],
)
def test_bad_eval_overrides_are_one_line_errors(overrides, words, tmp_path):
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.evaluate import evaluate

    out = tmp_path / "out"
    with pytest.raises(CharctlError) as exc:
        evaluate([str(tmp_path / "no-such-run"), *overrides], {**EVAL_MODES, "out": out}, overrides)
    assert_one_line(exc.value, *words)
    assert not out.exists()  # refused before any run is loaded or any file written


def test_eval_on_an_absent_cuda_device_is_a_one_line_error(tmp_path, monkeypatch):
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.evaluate import evaluate

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(CharctlError) as exc:
        evaluate([str(tmp_path)], {**EVAL_MODES, "out": tmp_path / "out"}, ["device=cuda"])
    assert_one_line(exc.value, "device=cuda", "no CUDA device", "device=cpu")


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_eval_on_cuda_matches_cpu(smoke_run, tmp_path):
    import numpy as np

    run = smoke_run("cgail")
    cpu = _eval(run, tmp_path / "cpu", "device=cpu")
    gpu = _eval(run, tmp_path / "cuda", "device=cuda")
    for key in ("policy", "data"):  # float32 on another device: equal to rounding
        assert np.allclose(gpu["confusion.json"][key], cpu["confusion.json"][key], atol=1e-3)


# ---------------------------------------------------------------------------- random states
class DrawingLearner:
    """The smallest Learner: each iteration draws 3 numbers from torch's global CPU generator and keeps
    them; it stores no random state itself (as srb), so only the runner can make resume exact."""

    samples_per_iteration = 1

    def __init__(self) -> None:
        self.iteration = 0
        self.samples = 0
        self.draws: list[torch.Tensor] = []

    def iterate(self) -> dict[str, float]:
        self.draws.append(torch.rand(3))
        return {"x": 0.0}

    def state_dict(self) -> dict:
        return {"iteration": self.iteration, "samples": self.samples}

    def load_state_dict(self, state: dict) -> None:
        self.iteration, self.samples = int(state["iteration"]), int(state["samples"])

    def signature(self) -> dict:
        return {}

    def modules(self) -> list[torch.nn.Module]:
        return []

    def progress_fields(self, stats: dict[str, float]) -> dict[str, float]:
        return {}

    def summary(self, stats: dict[str, float]) -> dict:
        return {}


def _train(run_dir: Path, iterations: int, resumed: bool = False) -> DrawingLearner:
    """`iterations` total iterations of a DrawingLearner into run_dir (a checkpoint after each)."""
    from charctl.rl.runner import RunnerSettings, run_on_policy
    from charctl.runs import Run

    learner = DrawingLearner()
    run = Run(dir=run_dir, experiment="drawing", cfg=None, resumed=resumed)
    run_on_policy(learner, run, RunnerSettings(total_samples=iterations, checkpoint_every=1, log_every=10**6))
    run.close()
    return learner


def _checkpoint(run_dir: Path) -> Path:
    return run_dir / "checkpoints" / "last.pt"


def test_resume_continues_torch_cpu_random_stream(tmp_path):
    torch.manual_seed(0)
    straight = torch.cat(_train(tmp_path / "straight", 4).draws)
    torch.manual_seed(0)
    first = _train(tmp_path / "split", 2).draws
    torch.manual_seed(12345)  # what the process did in between must not matter
    second = _train(tmp_path / "split", 4, resumed=True).draws
    assert len(first) == len(second) == 2
    assert torch.equal(torch.cat(first + second), straight)


def test_gpu_checkpoint_resumes_on_a_cpu_only_machine(tmp_path, monkeypatch, capsys):
    from charctl.checkpoints import load_checkpoint, save_checkpoint

    torch.manual_seed(0)
    straight = torch.cat(_train(tmp_path / "straight", 4).draws)
    torch.manual_seed(0)
    _train(tmp_path / "split", 2)
    state = load_checkpoint(_checkpoint(tmp_path / "split"), "drawing")
    assert "torch_rng" in state and "cuda_rng" not in state  # CUDA absent or unused here: no CUDA states
    fake_cuda = [torch.randint(0, 255, (16,), dtype=torch.uint8)]  # as written on a one-GPU machine
    save_checkpoint(_checkpoint(tmp_path / "split"), "drawing", {**state, "cuda_rng": fake_cuda})

    def no_cuda_state(*args, **kwargs):
        raise AssertionError("a CUDA random state was set on a machine without CUDA")

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.setattr(torch.cuda, "set_rng_state", no_cuda_state)
    torch.manual_seed(12345)
    capsys.readouterr()
    second = _train(tmp_path / "split", 4, resumed=True).draws
    assert torch.equal(torch.cat(second), straight[6:])  # the CPU stream still continues exactly
    assert "CUDA random states of 1 device(s) but CUDA is not available" in capsys.readouterr().out


def test_cuda_rng_states_round_trip_through_a_weights_only_checkpoint(tmp_path, monkeypatch):
    from charctl.checkpoints import load_checkpoint, save_checkpoint
    from charctl.rl.runner import restore_rng_states, with_rng_states

    gpu_states = [torch.arange(16, dtype=torch.uint8), torch.arange(16, 32, dtype=torch.uint8)]
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "is_initialized", lambda: True)
    monkeypatch.setattr(torch.cuda, "get_rng_state_all", lambda: [s.clone() for s in gpu_states])
    torch.manual_seed(7)
    own = torch.get_rng_state()
    expected = torch.rand(5)  # the learner's own torch_rng (taken before this draw) is kept, not overwritten
    state = with_rng_states({"torch_rng": own, "iteration": 3})
    assert torch.equal(state["torch_rng"], own)
    path = save_checkpoint(tmp_path / "last.pt", "drawing", state)
    back = load_checkpoint(path, "drawing")  # torch.load(..., weights_only=True)
    assert [s.dtype for s in back["cuda_rng"]] == [torch.uint8, torch.uint8]
    assert all(torch.equal(a, b) for a, b in zip(back["cuda_rng"], gpu_states))

    restored: list[tuple[torch.Tensor, int]] = []
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    monkeypatch.setattr(torch.cuda, "set_rng_state", lambda s, device: restored.append((s, device)))
    torch.manual_seed(999)
    note = restore_rng_states(back)
    assert len(restored) == 1 and restored[0][1] == 0 and torch.equal(restored[0][0], gpu_states[0])
    assert note is not None and "2 devices" in note and "has 1" in note  # one GPU here, two saved
    assert torch.equal(torch.rand(5), expected)  # and the CPU state is back


def test_no_cuda_states_when_cuda_is_unused(monkeypatch):
    from charctl.rl.runner import cuda_rng_states, with_rng_states

    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "is_initialized", lambda: False)  # device=cpu on a GPU machine

    def must_not_be_called():
        raise AssertionError("asking for CUDA states would create a CUDA context")

    monkeypatch.setattr(torch.cuda, "get_rng_state_all", must_not_be_called)
    assert cuda_rng_states() is None
    assert "cuda_rng" not in with_rng_states({})
