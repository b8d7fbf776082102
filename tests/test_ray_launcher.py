"""Multirun jobs on Ray (`charctl train EXP -m ... --launcher ray`) and `charctl tune` (Ray Tune + ASHA).

Fast (`make test`): the search-space parser on hand-written specs, the option and metric checks, the
run-directory and metric-stream hooks of charctl.runs, a job failing at run time with its one line,
and one Ray session for the module (2 CPUs) in which a three-job hopper-ga smoke multirun runs two
valid jobs side by side (both write their artefacts) and reports the invalid one alone with its
message. Slow (`make test-slow`): a 4-trial smoke tune that writes its tables, plot and best.yaml,
and Ctrl-C on a CLI driver joined to the module's cluster: every job writes its checkpoint.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from charctl.errors import CharctlError
from charctl.launch.search_space import Dim, format_value, parse_dim, parse_overrides, split_args

from conftest import REPO, assert_one_line, assert_one_line_error, cli_env, with_fault_hooks

ray = pytest.importorskip("ray")


# ---------------------------------------------------------------------------- search space (no Ray)
@pytest.mark.parametrize(
    ("text", "kind", "values", "low", "high"),
    [
        ("choice(2,3)", "choice", ("2", "3"), 0, 0),
        ("choice(walk)", "choice", ("walk",), 0, 0),
        ("choice([walk],[walk,run],'a,b')", "choice", ("[walk]", "[walk,run]", "'a,b'"), 0, 0),
        ("range(1,4)", "randint", (), 1, 4),
        ("range(-3, 0)", "randint", (), -3, 0),
        ("range(0.1,0.9)", "uniform", (), 0.1, 0.9),
        ("range(0,1.5)", "uniform", (), 0, 1.5),
        ("loguniform(1e-5,1e-3)", "loguniform", (), 1e-5, 1e-3),
        ("loguniform(2,50)", "loguniform", (), 2.0, 50.0),
    ],
)
def test_search_specs_parse(text, kind, values, low, high):
    dim = parse_dim("ga.x", text)
    assert (dim.kind, dim.values, dim.low, dim.high) == (kind, values, low, high)
    assert dim.name == "ga.x"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("choice()", "empty argument"),
        ("choice(a,,b)", "empty argument"),
        ("choice(a,a)", "lists 'a' twice"),
        ("choice([a,b)", "unclosed bracket"),
        ("choice(a],b)", "unbalanced ']'"),
        ("choice([a,b]", "missing the closing ')'"),
        ("choice(a)b)", "unbalanced ')'"),
        ("choice('a,b)", "unclosed"),
        ("range(1)", "takes two bounds"),
        ("range(1,10,2)", "takes two bounds"),
        ("range(3,3)", "lower bound must be below"),
        ("range(5,1)", "lower bound must be below"),
        ("range(a,2)", "'a' is not a number"),
        ("range(0,inf)", "finite"),
        ("loguniform(0,1)", "must be positive"),
        ("loguniform(-1,1)", "must be positive"),
        ("loguniform(1e-3,1e-5)", "lower bound must be below"),
        ("uniform(0,1)", "unknown search function 'uniform'"),
        ("randint(0,4)", "unknown search function 'randint'"),
    ],
)
def test_malformed_search_specs_are_one_line_errors(text, message):
    with pytest.raises(CharctlError) as err:
        parse_dim("ppo.lr", text)
    assert_one_line(err.value, f"ppo.lr={text}", message)


def test_overrides_split_into_fixed_and_searched():
    fixed, dims = parse_overrides(["scale=smoke", "ppo.lr=loguniform(1e-5,1e-3)", "+notes=hello(world)", "seed=3"])
    assert fixed == ["scale=smoke", "+notes=hello(world)", "seed=3"]  # not a search function: a fixed value
    assert [(d.key, d.kind) for d in dims] == [("ppo.lr", "loguniform")]
    with pytest.raises(CharctlError, match="searched twice"):
        parse_overrides(["a=choice(1,2)", "a=range(0,3)"])
    with pytest.raises(CharctlError, match="fixes a key that is also searched"):
        parse_overrides(["a=choice(1,2)", "a=3"])
    with pytest.raises(CharctlError, match="key=value"):
        parse_overrides(["lonely"])


def test_sampled_values_become_override_text():
    assert format_value(3) == "3"
    assert format_value(0.000123456789) == "0.000123457"
    assert format_value(1e-5) == "1e-05"
    assert format_value("[walk,run]") == "[walk,run]"
    assert Dim("+x", "uniform", low=0, high=1).override(0.25) == "+x=0.25"
    assert Dim("x", "randint", low=1, high=4).extremes() == ["1", "3"]  # the upper bound is excluded
    assert Dim("x", "loguniform", low=1e-5, high=1e-3).extremes() == ["1e-05", "0.001"]
    assert split_args(" a , [b,c] ,{d: 1, e: 2}", "w") == ["a", "[b,c]", "{d: 1, e: 2}"]


# ---------------------------------------------------------------------------- options, metrics (no Ray)
def test_tune_metric_defaults_to_the_experiments_first_declared_one():
    from charctl.commands.tune import resolve_metric
    from charctl.experiments import EXPERIMENTS, load

    for name in EXPERIMENTS:
        declared = dict(load(name).tune_metrics)
        assert declared and set(declared.values()) <= {"max", "min"}, name
    declared = dict(load("hopper-ga").tune_metrics)
    assert resolve_metric("hopper-ga", declared, None, None) == ("fitness/best_so_far", "min")
    assert resolve_metric("hopper-ga", declared, "fitness/mean", "max") == ("fitness/mean", "max")
    assert resolve_metric("hopper-ga", declared, "best/gamma", "min") == ("best/gamma", "min")
    with pytest.raises(CharctlError, match="give --mode"):
        resolve_metric("hopper-ga", declared, "best/gamma", None)
    with pytest.raises(CharctlError, match="--mode must be max or min"):
        resolve_metric("hopper-ga", declared, None, "up")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["tune", "hopper-ga", "scale=smoke"], "nothing to search"),
        (["tune", "hopper-ga", "beta=range(0.5,0.1)"], "lower bound must be below"),
        (["tune", "hopper-ga", "beta=choice(0.2,0.5)", "--trials", "0"], "--trials must be >= 1"),
        (["tune", "hopper-ga", "beta=choice(0.2,0.5)", "--metric", "best/E"], "give --mode"),
        (["tune", "hopper-ga", "no_such.key=choice(1,2)"], "no_such.key=1"),
        (["tune", "hopper-ga", "seed=range(-2,3)"], "seed must be >= 0"),
        (["train", "hopper-ga", "--address", "auto"], "--address needs --launcher ray"),
        (["train", "hopper-ga", "--launcher", "slurm"], "unknown launcher 'slurm'"),
        (["train", "hopper-ga", "--gpus-per-job", "1"], "need --launcher ray"),
        (["train", "hopper-ga", "--launcher", "ray", "--cpus-per-job", "0"], "--cpus-per-job must be > 0"),
        (["train", "hopper-ga", "--resume", "outputs/x", "--launcher", "ray"], "drop --launcher ray"),
    ],
)
def test_bad_launcher_and_tune_input_is_one_line_before_ray_starts(charctl_main, args, message):
    res = charctl_main(*args)
    assert_one_line_error(res, message)


def test_job_labels_show_what_differs():
    from charctl.launch.ray_jobs import job_labels

    jobs = [["scale=smoke", "seed=0", "beta=0"], ["scale=smoke", "seed=1", "beta=0"]]
    assert job_labels(jobs) == ["seed=0", "seed=1"]
    assert job_labels([["scale=smoke"]]) == ["scale=smoke"]


# ---------------------------------------------------------------------------- charctl.runs hooks (no Ray)
def test_runs_started_in_the_same_second_get_their_own_folders(tmp_path):
    from charctl.config import compose_config
    from charctl.experiments import load
    from charctl.runs import new_run

    cfg = compose_config("hopper-ga", ["scale=smoke", f"output_root={tmp_path}"], load("hopper-ga").config_class())
    dirs = {new_run(cfg).dir for _ in range(3)}
    assert len(dirs) == 3 and all((d / "config.yaml").is_file() for d in dirs)


def test_metric_stream_gets_every_logged_scalar_and_the_final_metrics(tmp_path, monkeypatch):
    from charctl.runs import METRICS_STREAM_ENV, Run

    stream = tmp_path / "stream.jsonl"
    monkeypatch.setenv(METRICS_STREAM_ENV, str(stream))
    run = Run(dir=tmp_path / "run", experiment="hopper-ga", cfg=None)
    run.log_scalars({"fitness/best": 0.5, "bad": float("nan")}, step=1)
    run.log_scalars({"fitness/best": 0.4}, step=2)
    run.write_metrics({"best_eval": 0.4, "finished": True, "name": "x", "curve": [1, 2]})
    run.close()
    lines = [json.loads(line) for line in stream.read_text().splitlines()]
    assert [(r["step"], r["final"], r["scalars"]) for r in lines] == [
        (1, False, {"fitness/best": 0.5}),
        (2, False, {"fitness/best": 0.4}),
        (2, True, {"best_eval": 0.4}),
    ]
    assert lines[0]["run_dir"] == str(tmp_path / "run")


def test_a_job_failing_at_run_time_reports_its_one_line(tmp_path):
    """A value that passes validation but fails inside the run (here: the disk fills up at the first
    checkpoint) ends the child with charctl's one line and exit code, kept as the job's message."""
    from charctl.launch.job import ChildJob, JobSpec

    spec = JobSpec(
        "hopper-ga",
        ("scale=smoke", f"output_root={tmp_path}"),
        cwd=str(REPO),
        env=with_fault_hooks({"CHARCTL_FAULT_CHECKPOINT_ENOSPC": "0", "OMP_NUM_THREADS": "1"}),
    )
    job = ChildJob(spec)
    job.start()
    assert job.wait(300) is not None
    outcome = job.finish()
    assert outcome.state == "failed" and outcome.exit_code == 2
    assert outcome.message.startswith("error: cannot write checkpoint") and "No space left" in outcome.message
    assert outcome.run_dir and (Path(outcome.run_dir) / "job.log").is_file()


# ---------------------------------------------------------------------------- on Ray
@pytest.fixture(scope="module")
def ray_cluster():
    """One local Ray instance (2 CPUs) for the module; the launcher reuses it in this process and
    CLI drivers join it with --address."""
    import logging

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level=logging.ERROR)
    try:
        yield ray.get_runtime_context().gcs_address
    finally:
        ray.shutdown()


@pytest.fixture(scope="module")
def multirun(ray_cluster, tmp_path_factory):
    """`-m seed=0,1,-1` on Ray: two valid smoke jobs and one invalid value."""
    from charctl.config import expand_multirun
    from charctl.launch.ray_jobs import run_on_ray

    out = tmp_path_factory.mktemp("ray-multirun")
    jobs = expand_multirun(["scale=smoke", "seed=0,1,-1", f"output_root={out}"])
    t0 = time.perf_counter()
    results = run_on_ray("hopper-ga", jobs)
    return results, time.perf_counter() - t0


def test_two_multirun_jobs_run_side_by_side_with_their_artefacts(multirun):
    results, _ = multirun
    ok = [r for r in results if r.state == "done"]
    assert [r.overrides[1] for r in ok] == ["seed=0", "seed=1"], [(r.state, r.message) for r in results]
    for r in ok:
        run = Path(r.run_dir)
        for name in ("config.yaml", "metrics.json", "checkpoints/last.pt", "fitness_curve.png", "job.log"):
            assert (run / name).is_file(), f"{run}: no {name}"
        assert r.message.startswith("done: best_eval=")
    assert ok[0].run_dir != ok[1].run_dir
    assert max(r.started for r in ok) < min(r.ended for r in ok), "the two jobs did not overlap"


def test_an_invalid_job_fails_alone_with_its_message(multirun):
    from charctl.launch.ray_jobs import summary_error

    results, _ = multirun
    bad = results[2]
    assert (bad.state, bad.started, bad.run_dir) == ("failed", 0.0, "")
    assert bad.message == "invalid config for hopper-ga: seed must be >= 0, got -1"
    assert [r.state for r in results[:2]] == ["done", "done"]
    err = summary_error(results)
    assert_one_line(err, "1 of 3 job(s) did not finish", "seed=-1", "seed must be >= 0")


@pytest.mark.slow
def test_tune_four_smoke_trials_write_tables_plot_and_best_yaml(ray_cluster, tmp_path, capsys):
    import yaml

    from charctl.commands.tune import TuneOptions, tune_command
    from charctl.launch.tune_setup import SearchSettings

    out = tune_command(
        "hopper-ga",
        ["scale=smoke", "ga.mutpb=range(0.1,0.9)", "ga.mut_eta=loguniform(2,50)", "ga.tournament=choice(2,3)"]
        + [f"output_root={tmp_path}"],
        TuneOptions(settings=SearchSettings(trials=4)),
    )
    assert out.parent == tmp_path / "tune" / "hopper-ga"
    trials = json.loads((out / "trials.json").read_text())
    assert len(trials) == 4
    assert all(t["state"] in ("done", "stopped") for t in trials), trials
    assert all(t["metric"] is not None and t["reports"] >= 1 for t in trials)
    for t in trials:  # every trial's run directory is under the tune folder, with its checkpoint
        assert Path(t["run_dir"]).parent.parent == out / "runs"
        assert (Path(t["run_dir"]) / "checkpoints" / "last.pt").is_file()
    for name in ("trials.md", "trials.csv", "tune.png"):
        assert (out / name).stat().st_size > 0
    best = yaml.safe_load((out / "best.yaml").read_text())
    first = min((t for t in trials if t["state"] == "done"), key=lambda t: t["metric"])
    assert best["scale"] == "smoke" and best["ga.tournament"] == int(first["values"]["ga.tournament"])
    assert best["ga.mutpb"] == pytest.approx(float(first["values"]["ga.mutpb"]))
    printed = capsys.readouterr().out
    assert "rerun: charctl train hopper-ga scale=smoke ga.mutpb=" in printed


@pytest.mark.slow
def test_ctrl_c_on_the_driver_stops_every_job_with_its_checkpoint(ray_cluster, tmp_path):
    cmd = [sys.executable, "-c", "from charctl.cli import main; main()", "train", "hopper-ga", "scale=smoke"]
    cmd += ["ga.generations=100000", "-m", "seed=0,1", f"output_root={tmp_path}"]
    cmd += ["--launcher", "ray", "--address", ray_cluster]
    proc = subprocess.Popen(cmd, cwd=REPO, env=cli_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        runs: list[Path] = []
        while time.monotonic() < deadline and proc.poll() is None:
            runs = [p for p in (tmp_path / "hopper-ga").glob("*") if (p / "checkpoints" / "last.pt").is_file()]
            if len(runs) == 2:
                break
            time.sleep(1)
        assert len(runs) == 2, "the two jobs did not both start"
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, out + err
    assert "Traceback" not in out + err
    assert err.strip().splitlines()[-1].startswith("interrupted: 2 job(s) stopped with a checkpoint")
    for run in runs:
        log = (run / "job.log").read_text()
        assert "interrupted at generation" in log and "--- exit code 130" in log
        assert (run / "checkpoints" / "last.pt").is_file()
        assert not list((run / "checkpoints").glob("*.tmp*"))
    assert os.path.isdir(tmp_path / "hopper-ga")
