"""`charctl eval RUN --checkpoints` for com-cnn and hopper-ga (charctl/eval/checkpoints.py, the experiments'
eval_checkpoints.py): a tiny run of each keeps several checkpoints; the table lists every one with the number
an independent evaluation of that checkpoint gives, and the best is chosen. Bad input (no kept checkpoint, one
that does not load, another mode beside --checkpoints) is a one-line error with nothing written. cgail's AMP
runs are ranked by fidelity (their classifier options refused); cgail's own end-to-end test is in
tests/test_cgail_eval.py."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from charctl.errors import CharctlError
from charctl.eval.report import fmt_cell

from conftest import TINY_COM_CNN, assert_one_line, assert_one_line_error, snapshot

torch = pytest.importorskip("torch")


# ---------------------------------------------------------------------------- tiny runs
@pytest.fixture(scope="module")
def com_cnn_run(tmp_path_factory) -> Path:
    """com-cnn at smoke scale, shrunk (2 clips, a small network, 30 steps of 16 windows): checkpoints kept
    at 160, 320 and 480 windows (the last one is last.pt too)."""
    from charctl.commands.train import train_command

    root = tmp_path_factory.mktemp("ck_com_cnn")
    (run_dir,) = train_command(
        "com-cnn",
        [
            *TINY_COM_CNN,
            "train.steps=30",
            "train.batch_size=16",
            "train.checkpoint_every=10",
            "train.keep_checkpoint_every=160",
            f"output_root={root}",
        ],
    )
    return run_dir


@pytest.fixture(scope="module")
def hopper_ga_run(tmp_path_factory) -> Path:
    """hopper-ga at smoke scale (16 individuals, 3 generations), a checkpoint kept every 8 evaluations."""
    from charctl.commands.train import train_command

    root = tmp_path_factory.mktemp("ck_hopper_ga")
    (run_dir,) = train_command(
        "hopper-ga", ["scale=smoke", "limp.cycles=2", "train.keep_checkpoint_every=8", f"output_root={root}"]
    )
    return run_dir


def kept_files(run_dir: Path) -> list[str]:
    return sorted(p.name for p in (run_dir / "checkpoints").glob("samples_*.pt"))


# ---------------------------------------------------------------------------- independent evaluations
def teacher_forced_errors_by_training_code(run_dir: Path, names: list[str]) -> dict[str, float]:
    """Held-out joint-angle error (deg) of each checkpoint by the training loop's own held-out metric
    (train.evaluate_test on the test windows), not by the evaluation code the entry point uses."""
    from charctl.checkpoints import load_checkpoint
    from charctl.experiments.com_cnn.config import Config
    from charctl.experiments.com_cnn.data import build_windows
    from charctl.experiments.com_cnn.model import build_model
    from charctl.experiments.com_cnn.train import BatchSource, evaluate_test
    from charctl.runs import open_run

    cfg = open_run(run_dir, Config).cfg
    _, test_w, body = build_windows(cfg)
    source = BatchSource(test_w, "cpu", 512)
    out = {}
    for name in names:
        model = build_model(cfg, body.pose_dim)
        model.load_state_dict(load_checkpoint(run_dir / "checkpoints" / name, "com-cnn")["model"])
        out[name] = evaluate_test(model, source, body)["joint_angle_deg"]
    return out


def best_genome_fitness(run_dir: Path, names: list[str]) -> dict[str, tuple[float, float]]:
    """(fitness of the checkpoint's best genome by model.evaluate_genomes, the fitness the checkpoint stores)."""
    from charctl.checkpoints import load_checkpoint
    from charctl.experiments.hopper_ga.config import Config
    from charctl.experiments.hopper_ga.model import evaluate_genomes
    from charctl.experiments.hopper_ga.settings import settings_from_config
    from charctl.runs import open_run

    s = settings_from_config(open_run(run_dir, Config).cfg)
    out = {}
    for name in names:
        state = load_checkpoint(run_dir / "checkpoints" / name, "hopper-ga")
        genome = state["best_genome"].numpy().astype(float)[None]
        out[name] = (float(evaluate_genomes(genome, s)["fitness"][0]), float(state["best_fitness"]))
    return out


def assert_table_lists(md: str, rows: list[dict], key: str) -> None:
    """checkpoints.md has one table line per checkpoint: its sample count, its file and the ranked number."""
    for r in rows:
        assert f"| {r['samples']:,} | {r['checkpoint']} | {fmt_cell(r[key])} |" in md, (r, md)


# ---------------------------------------------------------------------------- com-cnn
def test_com_cnn_ranks_kept_checkpoints_by_held_out_pose_error(com_cnn_run, tmp_path, charctl_main):
    assert kept_files(com_cnn_run) == ["samples_000000160.pt", "samples_000000320.pt", "samples_000000480.pt"]
    out = tmp_path / "ck"
    res = charctl_main("eval", str(com_cnn_run), "--checkpoints", "-o", str(out))
    assert res.returncode == 0, res.stdout + res.stderr
    result = json.loads((out / "checkpoints.json").read_text())
    rows = result["rows"]
    assert [(r["samples"], r["checkpoint"]) for r in rows] == [
        (160, "samples_000000160.pt"),
        (320, "samples_000000320.pt"),
        (480, "samples_000000480.pt"),  # last.pt holds the same 480 windows: listed once
    ]
    expected = teacher_forced_errors_by_training_code(com_cnn_run, [r["checkpoint"] for r in rows])
    for r in rows:
        assert r["pose_error_deg"] == pytest.approx(expected[r["checkpoint"]], rel=1e-5), r["checkpoint"]
    best = min(rows, key=lambda r: expected[r["checkpoint"]])
    assert result["chosen"]["checkpoint"] == best["checkpoint"] and result["confirm"] is None
    md = (out / "checkpoints.md").read_text()
    assert_table_lists(md, rows, "pose_error_deg")
    assert f"Chosen: {best['checkpoint']} ({best['samples']:,} training windows)" in md
    assert (out / "checkpoints.png").stat().st_size > 1000
    # a second call reuses every row (nothing is evaluated again)
    row_file = out / "samples_000000160" / "row.json"
    before = row_file.stat().st_mtime_ns
    assert charctl_main("eval", str(com_cnn_run), "--checkpoints", "-o", str(out)).returncode == 0
    assert row_file.stat().st_mtime_ns == before
    assert json.loads((out / "checkpoints.json").read_text())["rows"] == rows


def test_com_cnn_checkpoints_are_all_loaded_before_anything_is_written(com_cnn_run, tmp_path, charctl_main):
    """A kept checkpoint that does not load (the last one, after two good ones) is a one-line error naming
    it, with no folder of the good ones written; --checkpoints beside --dtw is refused too."""
    run = Path(shutil.copytree(com_cnn_run, tmp_path / "run"))
    (run / "checkpoints" / "samples_000000480.pt").write_bytes(b"not a checkpoint")
    before = snapshot(tmp_path)
    res = charctl_main("eval", str(run), "--checkpoints")
    assert_one_line_error(res, "samples_000000480.pt", "not a readable charctl checkpoint")
    assert snapshot(tmp_path) == before and not (run / "eval").exists()
    res = charctl_main("eval", str(run), "--checkpoints", "--dtw")
    assert_one_line_error(res, "--checkpoints", "--dtw")
    assert snapshot(tmp_path) == before


def test_no_kept_checkpoint_is_a_one_line_error_and_writes_nothing(com_cnn_run, hopper_ga_run, tmp_path, charctl_main):
    for source in (com_cnn_run, hopper_ga_run):
        run = Path(shutil.copytree(source, tmp_path / source.parent.name))
        for p in (run / "checkpoints").glob("*.pt"):
            p.unlink()
        before = snapshot(tmp_path)
        res = charctl_main("eval", str(run), "--checkpoints", "-o", str(tmp_path / "out"))
        assert_one_line_error(res, "no checkpoint to evaluate")
        assert snapshot(tmp_path) == before, source.parent.name


# ---------------------------------------------------------------------------- hopper-ga
def test_hopper_ga_ranks_kept_checkpoints_by_the_best_individuals_fitness(hopper_ga_run, charctl_main):
    kept = kept_files(hopper_ga_run)
    assert len(kept) >= 2, kept
    res = charctl_main("eval", str(hopper_ga_run), "--checkpoints")
    assert res.returncode == 0, res.stdout + res.stderr
    out = hopper_ga_run / "eval"
    result = json.loads((out / "checkpoints.json").read_text())
    rows = result["rows"]
    from charctl.checkpoints import load_checkpoint

    last = int(load_checkpoint(hopper_ga_run / "checkpoints" / "last.pt", "hopper-ga")["evaluations"])
    assert [r["checkpoint"] for r in rows if r["checkpoint"] != "last.pt"] == kept
    assert rows[-1]["samples"] == last and [r["samples"] for r in rows] == sorted({r["samples"] for r in rows})
    expected = best_genome_fitness(hopper_ga_run, [r["checkpoint"] for r in rows])
    for r in rows:
        model_fitness, stored = expected[r["checkpoint"]]
        assert r["eval"] == pytest.approx(model_fitness, rel=1e-12) and r["stored_eval"] == stored
        assert np.isclose(model_fitness, stored, rtol=1e-12)  # the hall of fame's stored fitness, re-evaluated
    best = min(rows, key=lambda r: expected[r["checkpoint"]][0])  # the first (fewest evaluations) of equals
    assert result["chosen"]["checkpoint"] == best["checkpoint"] and result["confirm"] is None
    md = (out / "checkpoints.md").read_text()
    assert_table_lists(md, rows, "eval")
    assert f"Chosen: {best['checkpoint']} ({best['samples']:,} evaluations)" in md
    assert (out / "checkpoints.png").is_file()


def test_hopper_ga_checkpoints_bad_options_are_one_line_errors(hopper_ga_run, tmp_path, charctl_main):
    run = Path(shutil.copytree(hopper_ga_run, tmp_path / "run"))
    shutil.rmtree(run / "eval", ignore_errors=True)
    before = snapshot(tmp_path)
    assert_one_line_error(charctl_main("eval", str(run), "--checkpoints", "--curves"), "--curves")
    assert_one_line_error(
        charctl_main("eval", str(run), "--checkpoints", "--after", "1e9"), "no checkpoint to evaluate", "from"
    )
    assert snapshot(tmp_path) == before


# ---------------------------------------------------------------------------- cgail: AMP runs
def test_cgail_amp_run_is_ranked_by_fidelity_and_refuses_the_classifier_options(tmp_path):
    """An AMP (unconditional) run has no classifier, so no Fig 6.8 diagonal: --checkpoints takes it with the
    fidelity rank (the default) and refuses --rank margin, --confusion-k and --min-diagonal in one line."""
    from charctl.experiments.cgail.eval_checkpoints import checkpoints

    run = tmp_path / "amp"
    run.mkdir()
    (run / "config.yaml").write_text("experiment: cgail\ncgail:\n  conditional: false\n")
    for options, flag in (({"rank": "margin"}, "--rank margin"), ({"confusion_k": 4}, "--confusion-k")):
        with pytest.raises(CharctlError) as exc:
            checkpoints([str(run)], options, [])
        assert_one_line(exc.value, "AMP (unconditional)", flag)
    ev = checkpoints([str(run)], {}, [])
    assert not ev.conditional and ev.rank == "fidelity" and ev.fidelity
    fid = {"coverage": {"w": 0.5}, "signature_met": {"w": True}}
    amp_row = {"min_coverage": 0.5, "worst_no_fall": 0.75, "min_diagonal": None, "fidelity": fid}
    assert ev.rank_key(amp_row) == (1, 0.5, 0.75)
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["amp", "config.yaml"]


def test_cgail_fidelity_rank_counts_the_skills_at_the_coverage_target_first(tmp_path):
    """By hand: A has two of three skills at coverage >= 0.5 (lowest 0.10), B one (lowest 0.20). The fidelity rank
    picks A (2 > 1) where the lowest coverage alone would pick B; with --min-coverage 0.7 A counts one skill,
    B none; equal counts fall to the lowest coverage, then the worst no-fall, then the diagonal. A skill whose
    named signature misses (a kick covered by its guard) is not counted, whatever its coverage."""
    from charctl.experiments.cgail.eval_checkpoints import checkpoints, rank_key

    def row(coverage, no_fall=0.9, diagonal=0.95):
        cov = dict(zip(("walk", "kick", "spin"), coverage))
        return {
            "fidelity": {"coverage": cov, "signature_met": dict.fromkeys(cov, True)},
            "min_coverage": min(coverage),
            "worst_no_fall": no_fall,
            "min_diagonal": diagonal,
        }

    a, b = row([0.9, 0.6, 0.1]), row([0.55, 0.45, 0.2])
    assert rank_key(a, "fidelity") == (2, 0.1, 0.9, 0.95) and rank_key(b, "fidelity") == (1, 0.2, 0.9, 0.95)
    assert max((a, b), key=lambda r: rank_key(r, "fidelity")) is a
    assert rank_key(a, "fidelity", 0.7)[0] == 1 and rank_key(b, "fidelity", 0.7)[0] == 0
    assert (
        max((row([0.5, 0.1, 0.3]), row([0.5, 0.2, 0.0])), key=lambda r: rank_key(r, "fidelity"))["min_coverage"] == 0.1
    )
    kicks, guard = row([0.9, 0.6, 0.6]), row([0.9, 0.6, 0.6])
    guard["fidelity"]["signature_met"]["kick"] = False  # the kick's coverage from its guard, the foot down
    assert rank_key(kicks, "fidelity")[0] == 3 and rank_key(guard, "fidelity")[0] == 2
    assert max((guard, kicks), key=lambda r: rank_key(r, "fidelity")) is kicks
    run = tmp_path / "cgail"
    run.mkdir()
    (run / "config.yaml").write_text("experiment: cgail\n")
    assert checkpoints([str(run)], {"min_coverage": 0.6}, []).min_coverage == 0.6
    with pytest.raises(CharctlError) as exc:
        checkpoints([str(run)], {"rank": "margin", "min_coverage": 0.6}, [])
    assert_one_line(exc.value, "--min-coverage", "--rank fidelity")
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["cgail", "config.yaml"]
