"""Fault injection through the real CLI (a `charctl` subprocess per case, as a user runs it).

- bad input (>= 30 cases over the five experiments and the clip tools): exit 2, exactly one
  `error:` line on stderr, no traceback, nothing new on disk (no run directory, no output file).
  The first case of each command (`train cgail`, `train cgail -m`, `eval RUN`, `export bvh`, ...) and
  every case that sets its own environment run as a subprocess; the others call `charctl.cli.main` in
  the test process (same parsing, validation and one-line errors, without an interpreter start-up each);
- Ctrl-C once or twice and SIGTERM from another process: exit 130 / 143, "interrupted at ...", a loadable
  checkpoint, also when the second Ctrl-C lands inside the checkpoint write (on com-cnn: the same stop of
  every experiment is the shared runner's, tested once, with each experiment's wiring, in test_runner.py);
- SIGKILL at five random moments of a run (one inside a slowed checkpoint write), then `--resume`:
  the right final sample count, no duplicate TensorBoard steps, no temp files;
- a full disk (ENOSPC injected into the checkpoint writer): one line, the previous checkpoint intact;
- a diverging run: non-zero exit, the last checkpoint finite, metrics.json strict JSON.

The checkpoint faults (CHARCTL_FAULT_CHECKPOINT_DELAY, CHARCTL_FAULT_CHECKPOINT_ENOSPC) live in
tests/fault_hooks/sitecustomize.py, which `cli_env` puts on the subprocess's PYTHONPATH. cgail / srb
cases whose behaviour depends on the shared on-policy runner (charctl/rl/runner.py) run like every
other case.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import time
from pathlib import Path

import pytest

from conftest import AMP_RUN, CHARCTL, REPO, assert_one_line_error, charctl_in_process, cli_env, run_charctl, snapshot

LIMIT = 900  # seconds: an upper bound for any one command (the suite takes ~2 min on 2 idle cores)


# ---------------------------------------------------------------------------- helpers
def unwritable_dir(tmp_path: Path) -> Path:
    """A folder nobody may write into. Root ignores permission bits, so root gets a /sys path
    (mkdir there fails with EPERM, files with EACCES)."""
    if os.geteuid() == 0:
        return Path("/sys/charctl-fault-test")
    ro = tmp_path / "read-only"
    ro.mkdir(exist_ok=True)
    ro.chmod(0o555)
    return ro


def strict_json(path: Path):
    """json.loads that refuses NaN / Infinity (what every non-Python parser does)."""

    def refuse(name):
        raise ValueError(f"{path}: non-standard JSON constant {name}")

    return json.loads(Path(path).read_text(), parse_constant=refuse)


def run_dirs(root: Path, experiment: str) -> list[Path]:
    return sorted(p for p in (root / experiment).glob("*") if (p / "config.yaml").is_file())


def temp_files(run_dir: Path) -> list[Path]:
    return [p for p in run_dir.rglob("*") if ".tmp" in p.name]


def load_state(run_dir: Path, experiment: str) -> dict:
    from charctl.checkpoints import load_checkpoint

    return load_checkpoint(run_dir / "checkpoints" / "last.pt", experiment)


def assert_finite_state(state) -> None:
    import torch

    def walk(x, key="state"):
        if isinstance(x, torch.Tensor) and x.is_floating_point():
            assert bool(torch.isfinite(x).all()), f"non-finite tensor in the checkpoint at {key}"
        elif isinstance(x, float):
            assert x == x and abs(x) != float("inf"), f"non-finite number in the checkpoint at {key}"
        elif isinstance(x, dict):
            for k, v in x.items():
                walk(v, f"{key}.{k}")
        elif isinstance(x, (list, tuple)):
            for i, v in enumerate(x):
                walk(v, f"{key}[{i}]")

    walk(state)


def tensorboard_steps(run_dir: Path) -> dict[str, list[int]]:
    """Scalar steps per tag as TensorBoard shows them (purged restarts applied)."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(run_dir / "tb"), size_guidance={"scalars": 0})
    acc.Reload()
    return {tag: [e.step for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}


class Live:
    """A charctl training process whose stderr is read line by line (to time signals)."""

    def __init__(self, *args: str, cwd: Path, env: dict | None = None):
        self.proc = subprocess.Popen(
            [str(CHARCTL), *args],
            cwd=cwd,
            env=env or cli_env(),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        self.err: list[str] = []

    def wait_for_progress(self, timeout: float = LIMIT) -> None:
        """Until the progress bar's first line: the training loop (and its signal handling) runs."""
        deadline = time.time() + timeout
        for line in self.proc.stderr:
            self.err.append(line)
            if " samples (" in line or " gen (" in line:
                return
            if time.time() > deadline:
                break
        raise AssertionError("training never started:\n" + "".join(self.err))

    def wait_for_line(self, text: str, timeout: float = LIMIT) -> None:
        """Until a stderr line containing `text` (e.g. the stop handler's message)."""
        deadline = time.time() + timeout
        for line in self.proc.stderr:
            self.err.append(line)
            if text in line:
                return
            if time.time() > deadline:
                break
        raise AssertionError(f"no line with {text!r}:\n" + "".join(self.err))

    def signal(self, sig: int) -> None:
        self.proc.send_signal(sig)

    def finish(self, timeout: float = LIMIT) -> subprocess.CompletedProcess:
        out, err = self.proc.communicate(timeout=timeout)
        err = "".join(self.err) + err
        return subprocess.CompletedProcess(self.proc.args, self.proc.returncode, out, err)


def wait_until(predicate, timeout: float = 60, every: float = 0.01) -> bool:
    deadline = time.time() + timeout
    while time.time() < deadline:
        if predicate():
            return True
        time.sleep(every)
    return False


# ---------------------------------------------------------------------------- shared runs
@pytest.fixture(scope="module")
def cgail_run(smoke_run) -> Path:
    """A finished smoke cgail run (skills walk, right_kick) for export / eval / play cases: the session's
    `charctl train cgail scale=smoke` (conftest.smoke_run, made once through the console script), which
    these cases only read; each checks that nothing new appears in it."""
    return smoke_run("cgail")


@pytest.fixture(scope="module")
def zero_quaternion_file(tmp_path_factory) -> Path:
    from charctl.motion.library import motions_dir

    frames = json.loads((motions_dir() / "humanoid3d_walk.txt").read_text())["Frames"]
    frames[3][8:12] = [0.0, 0.0, 0.0, 0.0]  # the chest quaternion of frame 3
    path = tmp_path_factory.mktemp("clips") / "zero_quat.txt"
    path.write_text(json.dumps({"Loop": "wrap", "Frames": frames}))
    return path


# ---------------------------------------------------------------------------- bad input
# (id, arguments, words the error line must contain, extra environment). Placeholders: {out}
# output_root inside the sandbox, {tmp} the sandbox, {ro} an unwritable folder, {file} a plain
# file, {cgail} a finished cgail smoke run, {zeroq} a DeepMimic file with an all-zero quaternion, {amp} the shipped
# unconditional three-skill run (pretrained/amp-3skill).
BAD_INPUTS = [
    # cgail
    ("cgail-num-envs-0", "train cgail scale=smoke env.num_envs=0 output_root={out}", ["env.num_envs", ">= 1"], {}),
    ("cgail-rollout-0", "train cgail scale=smoke train.rollout_steps=0 output_root={out}", ["train.rollout_steps"], {}),
    ("cgail-device-tpu", "train cgail scale=smoke device=tpu output_root={out}", ["device", "tpu"], {}),
    ("cgail-device-cuda", "train cgail scale=smoke device=cuda output_root={out}", ["device=cuda", "CUDA"], {}),
    ("cgail-lr-nan", "train cgail scale=smoke ppo.lr=nan output_root={out}", ["ppo.lr", "finite"], {}),
    ("cgail-root-is-file", "train cgail scale=smoke output_root={file}", ["output_root", "file"], {}),
    ("cgail-root-unwritable", "train cgail scale=smoke output_root={ro}/runs", ["output_root", "{ro}"], {}),
    ("cgail-multirun-bad-job", "train cgail -m scale=smoke env.num_envs=8,0 output_root={out}", ["env.num_envs"], {}),
    ("cgail-eval-k-0", "eval {cgail} --dtw -k 0", ["-k", ">= 1"], {}),
    ("cgail-eval-k-neg", "eval {cgail} --dtw -k -3", ["-k", "-3"], {}),
    (
        "cgail-export-unknown-skill",
        "export {cgail} --onnx {tmp}/p.onnx --commands walk:0,run:3",
        ["run", "walk, right_kick"],
        {},
    ),
    (
        "cgail-export-amp-switch",
        "export {amp} --bvh {tmp}/a.bvh --commands walk:0,right_kick:2",
        ["AMP run", "no command input", "--commands SKILL:0"],
        {},
    ),
    ("cgail-export-read-only", "export {cgail} --torchscript {ro}/p.pt", ["{ro}/p.pt"], {}),
    ("cgail-export-seconds-neg", "export {cgail} --video {tmp}/v.mp4 --seconds -1", ["--seconds", "> 0"], {}),
    (
        "cgail-play-dead-display",
        "play {cgail}",
        ["display", "export", "--video", "walk:0,right_kick:3"],
        {"DISPLAY": ":99", "MUJOCO_GL": None, "PYOPENGL_PLATFORM": None},
    ),
    # srb
    (
        "srb-total-samples-neg",
        "train srb scale=smoke train.total_samples=-5 output_root={out}",
        ["train.total_samples", "-5"],
        {},
    ),
    ("srb-num-envs-0", "train srb scale=smoke train.num_envs=0 output_root={out}", ["train.num_envs"], {}),
    ("srb-lr-neg", "train srb scale=smoke ppo.lr=-1 output_root={out}", ["ppo.lr", "> 0"], {}),
    ("srb-rollout-0", "train srb scale=smoke train.rollout_steps=0 output_root={out}", ["train.rollout_steps"], {}),
    ("srb-eval-k-0", "eval srb --push -k 0", ["-k"], {}),
    # com-cnn
    ("com-cnn-lr-neg", "train com-cnn scale=smoke train.lr=-1 output_root={out}", ["train.lr", "> 0"], {}),
    (
        "com-cnn-history-short",
        "train com-cnn -m scale=smoke data.history=15,90 model.kernel=10 output_root={out}",
        ["history 15 is too short"],
        {},
    ),
    ("com-cnn-steps-0", "train com-cnn scale=smoke train.steps=0 output_root={out}", ["train.steps"], {}),
    ("com-cnn-batch-neg", "train com-cnn scale=smoke train.batch_size=-1 output_root={out}", ["train.batch_size"], {}),
    ("com-cnn-device-cuda3", "train com-cnn scale=smoke device=cuda:3 output_root={out}", ["device=cuda:3"], {}),
    ("com-cnn-export-seconds-neg", "export com-cnn --seconds -1 --bvh {tmp}/g.bvh", ["--seconds"], {}),
    ("com-cnn-export-crouch-nan", "export com-cnn --crouch-at nan --bvh {tmp}/g.bvh", ["--crouch-at", "finite"], {}),
    # motion-matching
    ("mm-speed-0", "train motion-matching scale=smoke paths.speed=0 output_root={out}", ["paths.speed"], {}),
    (
        "mm-sweep-starts-0",
        "eval motion-matching --sweep scale=smoke sweep.starts=0 output_root={out}",
        ["sweep.starts"],
        {},
    ),
    (
        "mm-export-read-only",
        "export motion-matching scale=smoke output_root={out} --bvh {ro}/x.bvh",
        ["{ro}/x.bvh"],
        {},
    ),
    (
        "mm-export-fps-0",
        "export motion-matching scale=smoke output_root={out} --fps 0 --bvh {tmp}/x.bvh",
        ["--fps"],
        {},
    ),
    ("mm-device-cuda", "train motion-matching scale=smoke device=cuda output_root={out}", ["CPU only"], {}),
    # hopper-ga
    ("hopper-population-0", "train hopper-ga scale=smoke ga.population=0 output_root={out}", ["ga.population"], {}),
    ("hopper-beta", "train hopper-ga scale=smoke beta=1.5 output_root={out}", ["beta"], {}),
    ("hopper-workers-0", "train hopper-ga scale=smoke runtime.workers=0 output_root={out}", ["runtime.workers"], {}),
    ("hopper-device-cuda", "train hopper-ga scale=smoke device=cuda output_root={out}", ["CPU only"], {}),
    ("hopper-export-seconds-neg", "export hopper-ga --seconds -1 --bvh {tmp}/h.bvh", ["--seconds"], {}),
    # clips and files
    ("clip-fps-nan", "export bvh walk --fps nan -o {tmp}/w.bvh", ["--fps", "finite"], {}),
    ("clip-fps-neg", "export bvh walk --fps -30 -o {tmp}/w.bvh", ["--fps", "> 0"], {}),
    ("clip-read-only", "export bvh walk -o {ro}/w.bvh", ["{ro}/w.bvh"], {}),
    ("clip-output-is-folder", "export bvh walk -o {tmp}", ["folder"], {}),
    (
        "clip-ffmpeg-fails",
        "export video walk --fps 5 -o {tmp}/w.mp4",
        ["{tmp}/w.mp4", "ffmpeg"],
        {"IMAGEIO_FFMPEG_EXE": "/bin/false"},
    ),
    ("clip-zero-quaternion", "data show {zeroq}", ["zero_quat.txt", "frame 3", "columns 8-11"], {}),
    ("clip-unknown", "data show humanoid3d_wlk", ["unknown clip", "walk"], {}),
]
NEEDS_CGAIL_RUN = {case[0] for case in BAD_INPUTS if "{cgail}" in case[1]}


def _subprocess_cases() -> set[str]:
    """The cases run as a `charctl` subprocess: the first of each command (its words before the overrides,
    and whether it is a multirun) - a fresh interpreter whose start-up for that command must print nothing
    but the one error line - and every case with its own environment (read at start-up: MUJOCO_GL,
    DISPLAY, IMAGEIO_FFMPEG_EXE). The rest run in the test process (conftest.charctl_in_process)."""
    seen: set[tuple] = set()
    out: set[str] = set()
    for name, template, _, extra_env in BAD_INPUTS:
        words = template.split()
        command = (words[0], words[1], "-m" in words)
        if extra_env or command not in seen:
            out.add(name)
        seen.add(command)
    return out


IN_SUBPROCESS = _subprocess_cases()


def _run_bad_input(case, root: Path, cgail: Path | None, zeroq: Path) -> dict:
    name, template, words, extra_env = case
    sandbox = root / name
    sandbox.mkdir()
    plain_file = sandbox / "a_file"
    plain_file.write_text("not a folder\n")
    values = {
        "out": sandbox / "out",
        "tmp": sandbox,
        "ro": unwritable_dir(root),
        "file": plain_file,
        "cgail": cgail,
        "zeroq": zeroq,
        "amp": AMP_RUN,
    }
    env = cli_env()
    for k, v in extra_env.items():
        if v is None:
            env.pop(k, None)
        else:
            env[k] = v
    watched = (
        [sandbox] + ([cgail] if cgail and "{cgail}" in template else []) + ([AMP_RUN] if "{amp}" in template else [])
    )
    before = snapshot(*watched)
    args = [a.format(**values) for a in template.split()]
    if name in IN_SUBPROCESS:
        res = run_charctl(*args, cwd=sandbox, env=env, timeout=LIMIT)
    else:
        res = charctl_in_process(*args, cwd=sandbox)
    return {
        "res": res,
        "new": sorted(snapshot(*watched) - before),
        "words": [w.format(**values) for w in words],
        "sandbox": sandbox,
    }


@pytest.fixture(scope="module")
def bad_input_results(request, tmp_path_factory, zero_quaternion_file) -> dict:
    """Every selected bad-input case, each in its own sandbox folder: the subprocess cases concurrently
    (they are independent, and a charctl start-up is mostly imports), the in-process ones meanwhile in
    this thread (they change the working directory and sys.stdout, so one at a time)."""
    from concurrent.futures import ThreadPoolExecutor

    selected = {
        item.callspec.id
        for item in request.session.items
        if getattr(item, "originalname", "") == "test_bad_input" and hasattr(item, "callspec")
    }
    cases = [c for c in BAD_INPUTS if c[0] in selected]
    cgail = request.getfixturevalue("cgail_run") if any(c[0] in NEEDS_CGAIL_RUN for c in cases) else None
    root = tmp_path_factory.mktemp("bad-input")
    with ThreadPoolExecutor(max_workers=4) as pool:
        running = {
            c[0]: pool.submit(_run_bad_input, c, root, cgail, zero_quaternion_file)
            for c in cases
            if c[0] in IN_SUBPROCESS
        }
        results = {c[0]: _run_bad_input(c, root, cgail, zero_quaternion_file) for c in cases if c[0] not in running}
        results.update({name: future.result() for name, future in running.items()})
    return results


@pytest.mark.parametrize("case", BAD_INPUTS, ids=[c[0] for c in BAD_INPUTS])
def test_bad_input(case, bad_input_results):
    name = case[0]
    if "cuda" in case[1] and not name.startswith(("mm-", "hopper-")):
        import torch

        if torch.cuda.is_available():
            pytest.skip("this machine has CUDA")
    r = bad_input_results[name]
    res = r["res"]
    assert res.returncode == 2, f"exit {res.returncode}:\n{res.stdout}\n{res.stderr}"
    assert_one_line_error(res, *r["words"])
    assert r["new"] == [], f"files appeared: {r['new']}"
    assert not (r["sandbox"] / "MUJOCO_LOG.TXT").exists()


def test_enough_bad_inputs_over_every_experiment():
    assert len(BAD_INPUTS) >= 30
    for exp in ("cgail", "srb", "com-cnn", "motion-matching", "hopper-ga"):
        assert sum(f" {exp} " in f" {c[1]} " for c in BAD_INPUTS) >= 3, exp


# ---------------------------------------------------------------------------- signals
# Signals from another process to a real `charctl train`, on one experiment: the stop itself is the shared
# runner's, tested once for every signal sequence, and every experiment's wiring to it, in tests/test_runner.py.
# (experiment, overrides that make the run long enough to be interrupted)
LONG_RUNS = {
    "com-cnn": ["scale=smoke", "train.steps=3000", "train.checkpoint_every=1000"],
}
SLOW = pytest.mark.slow
SIGNAL_CASES = [
    ("com-cnn", ("SIGINT", "SIGINT"), 130),
    ("com-cnn", ("SIGTERM",), 143),
    pytest.param("com-cnn", ("SIGINT",), 130, marks=SLOW),
    pytest.param("com-cnn", ("SIGTERM", "SIGINT"), 143, marks=SLOW),
]


def _signal_id(case) -> str:
    experiment, signals, _ = case.values if hasattr(case, "values") else case
    return f"{experiment}-{'+'.join(signals)}"


@pytest.mark.parametrize("experiment,signals,code", SIGNAL_CASES, ids=[_signal_id(c) for c in SIGNAL_CASES])
def test_interrupt_writes_checkpoint_and_exit_code(experiment, signals, code, tmp_path):
    out = tmp_path / "out"
    live = Live("train", experiment, *LONG_RUNS[experiment], f"output_root={out}", cwd=tmp_path)
    live.wait_for_progress()
    time.sleep(0.3)
    for i, s in enumerate(signals):
        live.signal(getattr(signal, s))
        if i == 0 and len(signals) > 1:
            # Python runs the handlers of signals pending together in signal-number order (SIGINT before
            # SIGTERM): the next one goes only after the first was handled, so the order is the test's
            live.wait_for_line("stopping:")
        time.sleep(0.05)
    res = live.finish()
    assert res.returncode == code, f"exit {res.returncode}:\n{res.stdout}\n{res.stderr}"
    assert "Traceback" not in res.stdout + res.stderr
    assert "done:" not in res.stdout
    last = [line for line in res.stderr.splitlines() if line.strip()][-1]
    assert last.startswith("interrupted") and "--resume" in last, last
    (run_dir,) = run_dirs(out, experiment)
    assert str(run_dir) in last
    load_state(run_dir, experiment)  # loads (weights_only, experiment checked)
    assert temp_files(run_dir) == []


def test_second_ctrl_c_inside_the_checkpoint_write(tmp_path):
    """The second Ctrl-C arrives while the (slowed) checkpoint is being written: the write completes,
    the checkpoint loads, the exit code stays 130."""
    out = tmp_path / "out"
    env = cli_env(CHARCTL_FAULT_CHECKPOINT_DELAY="1.0")
    live = Live("train", "com-cnn", *LONG_RUNS["com-cnn"], f"output_root={out}", cwd=tmp_path, env=env)
    live.wait_for_progress()
    live.signal(signal.SIGTERM)
    ckpt_dir = None

    def writing() -> bool:
        nonlocal ckpt_dir
        dirs = run_dirs(out, "com-cnn")
        ckpt_dir = dirs[-1] / "checkpoints" if dirs else None
        return bool(ckpt_dir and any(".tmp" in p.name for p in ckpt_dir.glob("*")))

    assert wait_until(writing, timeout=LIMIT), "the checkpoint write never started"
    live.signal(signal.SIGINT)
    res = live.finish()
    assert res.returncode == 143, res.stderr
    assert "Traceback" not in res.stderr
    state = load_state(ckpt_dir.parent, "com-cnn")
    assert state["step"] > 0
    assert temp_files(ckpt_dir.parent) == []


# ---------------------------------------------------------------------------- SIGKILL and resume
def test_sigkill_at_random_moments_then_resume(tmp_path):
    """Three SIGKILLs (the second inside a slowed checkpoint write), each followed by --resume; the
    last resume finishes: all samples counted once, no duplicate TensorBoard step, no temp file."""
    rng = random.Random(12)
    steps, batch, every = 150, 32, 10
    out = tmp_path / "out"
    overrides = [
        "scale=smoke",
        f"train.steps={steps}",
        f"train.batch_size={batch}",
        f"train.checkpoint_every={every}",
        "train.eval_every=25",
        f"output_root={out}",
    ]
    env = cli_env(CHARCTL_FAULT_CHECKPOINT_DELAY="0.15")
    run_dir = None
    for kill in range(3):
        args = ["train", "com-cnn", *overrides] if run_dir is None else ["train", "com-cnn", "--resume", str(run_dir)]
        live = Live(*args, cwd=tmp_path, env=env)
        live.wait_for_progress()
        if run_dir is None:
            (run_dir,) = run_dirs(out, "com-cnn")
        ckpt = run_dir / "checkpoints" / "last.pt"
        assert wait_until(ckpt.is_file, timeout=LIMIT)
        if kill == 1:  # inside a checkpoint write: the temp file is half written
            assert wait_until(lambda d=run_dir: bool(temp_files(d)), timeout=LIMIT)
        else:
            time.sleep(rng.uniform(0.0, 0.8))
        os.killpg(live.proc.pid, signal.SIGKILL)
        live.proc.wait(timeout=30)
        assert live.proc.returncode == -signal.SIGKILL
        if kill == 1:
            assert temp_files(run_dir), "the kill should have left a temp file behind"
        state = load_state(run_dir, "com-cnn")  # last.pt always loads
        assert 0 < state["step"] <= steps
    res = run_charctl("train", "com-cnn", "--resume", str(run_dir), cwd=tmp_path, timeout=LIMIT)
    assert res.returncode == 0, res.stderr
    metrics = strict_json(run_dir / "metrics.json")
    assert metrics["step"] == steps and metrics["samples"] == steps * batch
    assert temp_files(run_dir) == []
    tb = tensorboard_steps(run_dir)
    assert tb["train/loss"][-1] == steps * batch
    for tag, tag_steps in tb.items():
        assert len(tag_steps) == len(set(tag_steps)), f"duplicate TensorBoard steps in {tag}: {tag_steps}"
        assert tag_steps == sorted(tag_steps), tag


# ---------------------------------------------------------------------------- full disk
def test_full_disk_keeps_the_previous_checkpoint(tmp_path):
    out = tmp_path / "out"
    env = cli_env(CHARCTL_FAULT_CHECKPOINT_ENOSPC="1")  # the first checkpoint is written, the second fails
    res = run_charctl(
        "train",
        "com-cnn",
        "scale=smoke",
        "train.steps=60",
        "train.checkpoint_every=20",
        f"output_root={out}",
        cwd=tmp_path,
        env=env,
        timeout=LIMIT,
    )
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stdout + res.stderr
    errors = [line for line in res.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, res.stderr
    assert "No space left on device" in errors[0] and "previous checkpoint is kept" in errors[0]
    (run_dir,) = run_dirs(out, "com-cnn")
    assert str(run_dir / "checkpoints" / "last.pt") in errors[0]
    assert load_state(run_dir, "com-cnn")["step"] == 20
    assert temp_files(run_dir) == []


# ---------------------------------------------------------------------------- divergence
# (experiment, overrides, a checkpoint exists before the divergence). cgail / srb with ppo.lr=10 diverge in
# their first iteration, before any checkpoint: the error must then say that none was kept.
DIVERGING = [
    ("com-cnn", ["scale=smoke", "train.lr=1e4", "train.checkpoint_every=10"], True),
    pytest.param("cgail", ["scale=smoke", "ppo.lr=10", "train.total_samples=4096"], False),
    pytest.param("srb", ["scale=smoke", "ppo.lr=10", "train.checkpoint_every=1"], False),
]


@pytest.mark.parametrize(
    "experiment,overrides,has_checkpoint",
    DIVERGING,
    ids=["com-cnn-lr-1e4", "cgail-ppo-lr-10", "srb-ppo-lr-10"],
)
def test_diverging_run_stops_with_a_finite_checkpoint(experiment, overrides, has_checkpoint, tmp_path):
    out = tmp_path / "out"
    res = run_charctl("train", experiment, *overrides, f"output_root={out}", cwd=tmp_path, timeout=LIMIT)
    assert res.returncode not in (0, 130, 143), f"exit {res.returncode}:\n{res.stdout}\n{res.stderr}"
    assert "Traceback" not in res.stdout + res.stderr
    errors = [line for line in res.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "diverged" in errors[0], res.stderr
    (run_dir,) = run_dirs(out, experiment)
    if has_checkpoint or (run_dir / "checkpoints" / "last.pt").is_file():
        assert_finite_state(load_state(run_dir, experiment))  # the last checkpoint on disk is finite ...
        assert f"{run_dir / 'checkpoints' / 'last.pt'} was kept" in errors[0]  # ... and the line says so
    else:
        assert "no checkpoint" in errors[0], errors[0]
    metrics = strict_json(run_dir / "metrics.json")
    assert metrics.get("diverged") is True
    assert temp_files(run_dir) == []


@pytest.mark.slow
def test_huge_discriminator_lr_never_writes_non_finite_results(tmp_path):
    """disc.lr=10 (the issue's second diverging setting): at smoke scale the spectrally normalised
    discriminator may stay finite and the run finish; either way nothing non-finite is written: a
    divergence is the one-line stop above, a finished run has a finite checkpoint and strict metrics."""
    out = tmp_path / "out"
    res = run_charctl(
        "train",
        "cgail",
        "scale=smoke",
        "disc.lr=10",
        "train.total_samples=16384",
        f"output_root={out}",
        cwd=tmp_path,
        timeout=LIMIT,
    )
    assert "Traceback" not in res.stdout + res.stderr
    (run_dir,) = run_dirs(out, "cgail")
    if res.returncode != 0:
        errors = [line for line in res.stderr.splitlines() if line.startswith("error:")]
        assert len(errors) == 1 and "diverged" in errors[0], res.stderr
    if (run_dir / "checkpoints" / "last.pt").is_file():
        assert_finite_state(load_state(run_dir, "cgail"))
    strict_json(run_dir / "metrics.json")


# ---------------------------------------------------------------------------- in-process units
def test_metrics_are_strict_json(tmp_path):
    import numpy as np
    from omegaconf import OmegaConf

    from charctl.runs import new_run

    run = new_run(OmegaConf.create({"experiment": "demo", "output_root": str(tmp_path)}))
    path = run.write_metrics(
        {"loss": float("nan"), "best": np.float32("inf"), "curve": np.array([1.0, -np.inf]), "ok": 1.5}
    )
    assert strict_json(path) == {"loss": None, "best": None, "curve": [1.0, None], "ok": 1.5}


def test_stale_temp_files_are_removed_on_the_next_start(tmp_path):
    from omegaconf import OmegaConf

    from charctl.runs import new_run, open_run

    run = new_run(OmegaConf.create({"experiment": "demo", "output_root": str(tmp_path)}))
    gone = subprocess.Popen(["true"])  # a process that has exited: its temp file is stale
    gone.wait()
    stale = run.dir / "checkpoints" / f"last.pt.tmp{gone.pid}"
    stale.parent.mkdir(parents=True, exist_ok=True)
    stale.write_bytes(b"half a checkpoint")
    alive = run.dir / "checkpoints" / f"last.pt.tmp{os.getppid()}"  # a live process's write in progress
    alive.write_bytes(b"being written")
    open_run(run.dir)
    assert not stale.exists() and alive.exists()


def test_guard_names_the_first_non_finite_value():
    import torch

    from charctl.errors import Diverged
    from charctl.guard import BlowupMonitor, check_finite, first_non_finite

    net = torch.nn.Linear(2, 2)
    assert first_non_finite({"loss": 1.0}, net) is None
    with torch.no_grad():
        net.bias[1] = float("nan")
    assert first_non_finite({"loss": 1.0}, net) == "parameter Linear.bias"
    with pytest.raises(Diverged) as exc:
        check_finite({"loss": float("inf")}, net, where="step 7")
    assert "loss = inf" in str(exc.value) and "step 7" in str(exc.value) and exc.value.exit_code == 3
    monitor = BlowupMonitor(threshold=0.1, window=3)
    assert [monitor.update(resets=20, samples=100) for _ in range(2)] == [None, None]
    warning = monitor.update(resets=20, samples=100)
    assert warning and "20.0%" in warning and monitor.rate == pytest.approx(0.2)
    assert monitor.update(resets=20, samples=100) is None  # said once while it lasts
    for _ in range(3):
        monitor.update(resets=0, samples=100)
    assert not monitor.active


def test_mujoco_warnings_go_to_the_run_log_not_the_working_directory(tmp_path):
    """MuJoCo writes MUJOCO_LOG.TXT into the current directory by default; charctl sends a run's
    warnings to <run>/mujoco.log and counts them."""
    code = (
        "import charctl, mujoco\n"
        "from charctl.mujoco_log import capture_mujoco_log, count_mujoco_warnings\n"
        f"capture_mujoco_log({str(tmp_path / 'run')!r})\n"
        "m = mujoco.MjModel.from_xml_string(\"<mujoco><worldbody><body><freejoint/><geom size='.1'/></body>"
        '</worldbody></mujoco>")\n'
        "d = mujoco.MjData(m); d.qvel[:] = 1e20\n"
        "mujoco.mj_step(m, d)\n"
        f"print(count_mujoco_warnings({str(tmp_path / 'run')!r}))\n"
    )
    (tmp_path / "run").mkdir()
    work = tmp_path / "cwd"
    work.mkdir()
    import sys

    res = subprocess.run(
        [sys.executable, "-c", code], cwd=work, capture_output=True, text=True, env=cli_env(), timeout=LIMIT
    )
    assert res.returncode == 0, res.stderr
    assert int(res.stdout.strip()) >= 1
    assert not (work / "MUJOCO_LOG.TXT").exists() and "WARNING" not in res.stdout + res.stderr


def test_exit_code_of_typer_exit_is_kept(tmp_path):
    """`standalone_mode=False` makes click return typer.Exit's code; main() must exit with it."""
    import sys

    code = (
        "import sys, typer\nimport charctl.cli as cli\n"
        "def boom():\n    raise typer.Exit(5)\n"
        "cli.app = typer.Typer(); cli.app.command()(boom)\nsys.argv = ['charctl']\ncli.main()\n"
    )
    res = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=LIMIT)
    assert res.returncode == 5, res.stderr


@pytest.mark.parametrize("logged_before_checkpoint", [False, True])
def test_resume_hides_tensorboard_steps_logged_after_the_checkpoint(tmp_path, logged_before_checkpoint):
    """A killed process logged past its last checkpoint; the resumed run logs those steps again and
    TensorBoard shows each once — also when nothing was logged before that checkpoint (tb_step None)."""
    from charctl.runs import Run

    first = Run(dir=tmp_path, experiment="com-cnn", cfg=None)
    if logged_before_checkpoint:
        first.log_scalars({"train/loss": 1.0}, 320)
    first.save_checkpoint({"step": 10})
    first.log_scalars({"train/loss": 2.0}, 640)  # after the checkpoint: the kill loses its state
    first.close()
    # A real resume is a later process. In one process within one second both event files share their
    # time and pid and differ only by torch's global writer counter, which TensorBoard orders as text
    # ("…10" before "…9"), so late in a long test session the resumed file could be read first.
    time.sleep(1.1)
    resumed = Run(dir=tmp_path, experiment="com-cnn", cfg=None, resumed=True)
    resumed.load_checkpoint()
    resumed.log_scalars({"train/loss": 3.0}, 640)
    resumed.log_scalars({"train/loss": 4.0}, 960)
    resumed.close()
    expected = [320, 640, 960] if logged_before_checkpoint else [640, 960]
    assert tensorboard_steps(tmp_path)["train/loss"] == expected
