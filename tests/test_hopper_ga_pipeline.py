"""hopper-ga end to end: small GAs (briskness, runtimes, resume) and the CLI (train with the Ray
runtime, which must find the local runtime's genome; export BVH + mp4; the eval report; one-line
errors)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from omegaconf import OmegaConf

from charctl.experiments.hopper_ga.config import Config
from charctl.experiments.hopper_ga.ga import evolve
from charctl.experiments.hopper_ga.runtime import make_evaluator
from charctl.experiments.hopper_ga.settings import settings_from_config

from conftest import assert_one_line_error, charctl_in_process, run_charctl


def small_cfg(**over):
    cfg = OmegaConf.structured(Config)
    cfg.ga.population, cfg.ga.generations = 12, 3
    for k, v in over.items():
        OmegaConf.update(cfg, k, v)
    return cfg


def run_ga(cfg, seed: int = 0):
    s = settings_from_config(cfg)
    with make_evaluator(cfg.runtime, s) as ev:
        return evolve(cfg.ga, seed, s.low, s.high, ev)


def test_larger_beta_gives_larger_energy_rate():
    """eq 14: the best individual's E_r is pulled towards beta / (1 - beta)."""
    runs = {
        b: run_ga(small_cfg(**{"speed": 5.0, "beta": b, "ga.population": 40, "ga.generations": 12})) for b in (0.0, 0.7)
    }
    e0, e7 = runs[0.0].history["E_r"][-1], runs[0.7].history["E_r"][-1]
    assert e7 > e0 + 0.5, (e0, e7)
    assert abs(e7 - 0.7 / 0.3) < abs(e0 - 0.7 / 0.3)
    for st in runs.values():  # the GA improves on its random start (elitism: never worse)
        assert st.history["best"][-1] <= st.history["best"][0]
        assert np.all(np.diff(st.history["best_so_far"]) <= 0)


def test_same_seed_same_best_genome_local_and_process():
    """(Ray is compared with local in the CLI test below, to start it only once.)"""
    results = {kind: run_ga(small_cfg(**{"runtime.kind": kind, "runtime.workers": 2})) for kind in ("local", "process")}
    ref = results["local"]
    assert np.isfinite(ref.best_fitness)
    for kind, st in results.items():
        np.testing.assert_array_equal(st.best_genome, ref.best_genome, err_msg=kind)
        assert st.history["best"] == ref.history["best"], kind
        np.testing.assert_array_equal(st.population, ref.population, err_msg=kind)


def test_resume_from_a_checkpoint_continues_the_same_trajectory(tmp_path):
    """Stop after 2 generations, write the checkpoint (weights_only format), load it, continue to
    4: the same populations and curve as 4 generations in one go."""
    from charctl.checkpoints import load_checkpoint, save_checkpoint
    from charctl.experiments.hopper_ga.ga import GAState

    cfg4 = small_cfg(**{"ga.generations": 4})
    s = settings_from_config(cfg4)
    straight = run_ga(cfg4)
    with make_evaluator(cfg4.runtime, s) as ev:
        half = evolve(small_cfg(**{"ga.generations": 2}).ga, 0, s.low, s.high, ev)
        path = save_checkpoint(tmp_path / "last.pt", "hopper-ga", half.to_checkpoint(), {"genes": len(s.low)})
        state = GAState.from_checkpoint(load_checkpoint(path, "hopper-ga", {"genes": len(s.low)}))
        resumed = evolve(cfg4.ga, 0, s.low, s.high, ev, state=state)
    assert resumed.generation == straight.generation == 4
    assert resumed.history["best"] == straight.history["best"]
    np.testing.assert_array_equal(resumed.population, straight.population)
    np.testing.assert_array_equal(resumed.best_genome, straight.best_genome)


def test_training_on_the_shared_runner_resumes_the_same_trajectory(tmp_path):
    """`train` (the GA learner on charctl.rl.runner): 2 generations, then --resume to 4, evolves exactly what
    `evolve` does in one go; iterations count generations and samples count evaluations."""
    from charctl.experiments.hopper_ga.train import train
    from charctl.runs import Run

    cfg2, cfg4 = (small_cfg(**{"ga.generations": g, "limp.cycles": 2}) for g in (2, 4))
    train(cfg2, Run(dir=tmp_path, experiment="hopper-ga", cfg=cfg2))
    resumed = Run(dir=tmp_path, experiment="hopper-ga", cfg=cfg4, resumed=True)
    train(cfg4, resumed)
    resumed.close()
    straight = run_ga(cfg4)
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["generations_done"] == metrics["iterations"] == 4 and metrics["finished"]
    # the resume re-evaluates the checkpoint's population once (12 individuals) to rebuild its metrics
    assert metrics["samples"] == metrics["evaluations"] == straight.evaluations + 12
    assert metrics["best_eval"] == straight.best_fitness
    genes = json.loads((tmp_path / "best_genome.json").read_text())["genes"]
    np.testing.assert_array_equal(np.array(list(genes.values())), straight.best_genome)


def test_cli_train_with_ray_export_and_report(tmp_path):
    out = tmp_path / "runs"
    res = run_charctl(
        "train",
        "hopper-ga",
        "scale=smoke",
        "speed=5",
        "beta=0.5",
        "runtime.kind=ray",
        f"output_root={out}",
        timeout=240,
    )
    assert res.returncode == 0, res.stdout + res.stderr
    (run_dir,) = list((out / "hopper-ga").iterdir())
    for name in (
        "config.yaml",
        "best_genome.json",
        "metrics.json",
        "fitness_curve.png",
        "com_path.png",
        "strip.png",
        "checkpoints/last.pt",
    ):
        assert (run_dir / name).is_file(), name
    assert list((run_dir / "tb").glob("events.*"))
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["runtime"] == "ray" and metrics["generations_done"] == 3 and metrics["E_r"] > 0
    assert 0 < metrics["stance_time_s"] < 1 and metrics["cadence_spm"] > 0
    # the Ray run found exactly the genome the local runtime finds with the same seed
    from charctl.config import compose_config

    local = run_ga(compose_config("hopper-ga", ["scale=smoke", "speed=5", "beta=0.5"], Config))
    ray_best = json.loads((run_dir / "best_genome.json").read_text())["genes"]
    np.testing.assert_array_equal(np.array(list(ray_best.values())), local.best_genome)

    res = charctl_in_process(  # `charctl export RUN ...` in this process: the run came from the CLI above
        "export",
        str(run_dir),
        "--bvh",
        str(tmp_path / "run.bvh"),
        "--video",
        str(tmp_path / "run.mp4"),
        "--seconds",
        "0.2",
    )
    assert res.returncode == 0, res.stdout + res.stderr
    from charctl.motion.bvh import read_bvh

    bvh = read_bvh(tmp_path / "run.bvh")
    assert len(bvh.names) == 11 and bvh.num_frames >= 12
    assert (tmp_path / "run.mp4").stat().st_size > 1000

    from charctl.experiments.hopper_ga.evaluate import evaluate

    evaluate(
        [str(run_dir)], {"curves": True, "out": tmp_path / "report"}, []
    )  # what `charctl eval RUN --curves -o DIR` calls
    report = (tmp_path / "report" / "report.md").read_text()
    assert "| 5 | 0.5 |" in report and "fitness_curve.png" in report


@pytest.mark.parametrize(
    "args, must",
    [
        (["train", "hopper-ga", "beta=1.0"], "beta"),
        (["train", "hopper-ga", "runtime.kind=gpu"], "runtime.kind"),
        (["train", "hopper-ga", "ga.populaton=5"], "ga.populaton"),
        (["export", "hopper-ga", "--onnx", "x.onnx"], "--onnx"),
    ],
)
def test_cli_bad_input_is_one_line(args, must, tmp_path):
    """Through charctl.cli.main in this process (test_faults.py runs `train hopper-ga` and `export hopper-ga`
    bad input as real processes)."""
    extra = [f"output_root={tmp_path}"] if args[0] == "train" else []
    assert_one_line_error(charctl_in_process(*args, *extra, cwd=tmp_path), must)
