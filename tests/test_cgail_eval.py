"""cgail evaluation and export: DTW vs brute force, e_pose properties, every eval mode on a smoke run, export parity."""

import json

import numpy as np
import pytest
import torch

from charctl.eval.dtw import dtw_align, dtw_bruteforce, mean_aligned_cost
from charctl.eval.pose import pose_error, pose_error_matrix
from charctl.motion.library import load_clip

torch.set_num_threads(1)


@pytest.mark.parametrize("shape", [(1, 1), (3, 7), (8, 5), (12, 12)])
def test_dtw_matches_bruteforce(shape):
    rng = np.random.default_rng(sum(shape))
    cost = rng.random(shape)
    i, j, total = dtw_align(cost)
    assert total == pytest.approx(dtw_bruteforce(cost))
    assert cost[i, j].sum() == pytest.approx(total)
    assert (i[0], j[0]) == (0, 0) and (i[-1], j[-1]) == (shape[0] - 1, shape[1] - 1)
    assert np.all(np.diff(i) >= 0) and np.all(np.diff(j) >= 0)


def test_dtw_aligns_a_time_warped_copy_with_zero_cost():
    x = np.sin(np.linspace(0, 3, 20))
    y = np.repeat(x, 2)  # same signal, half speed
    cost = np.abs(x[:, None] - y[None, :])
    assert mean_aligned_cost(cost) == pytest.approx(0.0)


def test_pose_error_zero_against_itself_and_sign_invariant():
    q = load_clip("walk").local_rot[:, 1:]
    assert np.allclose(np.diag(pose_error_matrix(q, q)), 0.0, atol=1e-6)
    flipped = q.copy()
    flipped[::2] *= -1  # same rotations, opposite quaternion signs
    assert np.allclose(pose_error(q, flipped), 0.0, atol=1e-6)
    # a 0.3 rad rotation of one joint gives e_pose = 0.3
    from charctl.motion import rotations as R

    r = q.copy()
    r[:, 2] = R.multiply(r[:, 2], R.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.full(len(q), 0.3)))
    assert np.allclose(pose_error(q, r), 0.3, atol=1e-6)


@pytest.fixture(scope="module")
def smoke_runs(tmp_path_factory, smoke_run):
    import shutil
    from pathlib import Path

    from charctl.commands.train import train_command

    root = tmp_path_factory.mktemp("cgail_eval")
    cg = Path(
        shutil.copytree(smoke_run("cgail"), root / "c" / "cgail" / smoke_run("cgail").name)
    )  # test_smoke.py's run
    (amp,) = train_command("cgail", ["scale=smoke", "cgail.conditional=false", f"output_root={root}/a"])
    return cg, amp, root


def test_every_eval_mode_writes_its_files(smoke_runs):
    from charctl.commands.evaluate import eval_command

    cg, amp, root = smoke_runs
    out = root / "eval"
    eval_command(
        [str(cg), str(amp)],
        {
            "dtw": True,
            "confusion": True,
            "switch": ("walk", "right_kick"),
            "curves": True,
            "pose_error": False,
            "push": False,
            "sweep": False,
            "episodes": 2,
            "out": out,
        },
    )
    dtw = json.loads((out / "dtw.json").read_text())
    assert set(dtw["table"]) == {"walk", "right_kick"}
    assert {"cGAIL", "AMP", "paper cGAIL", "paper AMP"} <= set(dtw["table"]["walk"])
    assert dtw["table"]["walk"]["paper cGAIL"] == pytest.approx(1.456)
    assert np.isfinite(dtw["table"]["walk"]["cGAIL"]) and dtw["table"]["walk"]["cGAIL"] > 0
    conf = json.loads((out / "confusion.json").read_text())
    for key in ("policy", "data"):
        assert np.allclose(np.sum(conf[key], axis=1), 1.0, atol=1e-5)  # rows sum to 1
    sw = json.loads((out / "switch_walk_to_right_kick.json").read_text())
    assert set(sw["summary"]) == {"ramp", "no_ramp"} and sw["summary"]["no_ramp"]["ramp_frames"] == 0
    # both conditions are watched until 2 s (60 frames at 30 Hz) after the ramp has ended
    ramp = sw["summary"]["ramp"]["ramp_frames"]
    assert ramp > 0
    for name in ("ramp", "no_ramp"):
        assert len(sw["curves"][name]["probs"]) == sw["switch_frame"] + ramp + 60, name
    for f in (
        "dtw.csv",
        "confusion.png",
        "switch_walk_to_right_kick.png",
        "curves_reward.png",
        "curves_class_accuracy.png",
        "report.md",
    ):
        assert (out / f).is_file() and (out / f).stat().st_size > 0, f
    report = (out / "report.md").read_text()
    assert "Table 6.1" in report and "Fig 6.8" in report


def test_onnx_and_torchscript_match_pytorch(smoke_runs, tmp_path):
    import onnxruntime as ort

    from charctl.experiments.cgail.export import ExportedPolicy, _example_inputs, export_onnx, export_torchscript
    from charctl.experiments.cgail.policy import load_trained_run

    cg, _, _ = smoke_runs
    tr = load_trained_run(cg)
    state, cmd = _example_inputs(tr, batch=5)
    cmd = torch.eye(2)[[0, 1, 0, 1, 1]]
    with torch.no_grad():
        ref = tr.agent.model.mean_action(state, cmd).numpy()
        np.testing.assert_allclose(ExportedPolicy(tr)(state, cmd).numpy(), ref, atol=1e-6)
    sess = ort.InferenceSession(str(export_onnx(tr, tmp_path / "p.onnx")))
    out = sess.run(None, {"state": state.numpy(), "command": cmd.numpy()})[0]
    np.testing.assert_allclose(out, ref, atol=1e-5)
    ts = torch.jit.load(str(export_torchscript(tr, tmp_path / "p.pt")))
    np.testing.assert_allclose(ts(state, cmd).detach().numpy(), ref, atol=1e-5)


def test_schedule_export_bvh(smoke_runs, tmp_path):
    from charctl.commands.export import export_command
    from charctl.motion.bvh import read_bvh

    cg, _, _ = smoke_runs
    export_command(str(cg), [], {"bvh": tmp_path / "r.bvh", "commands": "walk:0,right_kick:0.5", "seconds": 1.0})
    m = read_bvh(tmp_path / "r.bvh")
    assert m.num_frames == 31 and "left_wrist" in m.names


def test_bad_schedule_and_wrong_run_are_one_line_errors(smoke_runs, tmp_path):
    from charctl.errors import CharctlError
    from charctl.experiments.cgail.export import parse_schedule
    from charctl.experiments.cgail.policy import load_trained_run

    with pytest.raises(CharctlError, match="unknown skill"):
        parse_schedule("wlk:0", ["walk", "run"])
    with pytest.raises(CharctlError, match="skill:seconds"):
        parse_schedule("walk", ["walk"])
    (tmp_path / "config.yaml").write_text("experiment: srb\n")
    with pytest.raises(CharctlError, match="not a cgail run"):
        load_trained_run(tmp_path)


def test_eval_checkpoints_picks_by_margin_and_lists_every_kept_checkpoint(smoke_run_copy, charctl_main):
    """`charctl eval RUN --checkpoints --rank margin` (was scripts/eval_checkpoints.py): margin = the smaller
    of (worst no-fall - target) and (min diagonal - target); on the smoke run it evaluates the kept
    checkpoints and last.pt once each (last.pt is the 1024 one, listed once) and writes the table, JSON and plot."""
    from charctl.checkpoints import kept_checkpoints
    from charctl.experiments.cgail.eval_checkpoints import margin

    assert abs(margin(0.85, 0.95, 0.8, 0.9) - 0.05) < 1e-12
    assert abs(margin(0.95, 0.85, 0.8, 0.9) + 0.05) < 1e-12
    src = smoke_run_copy("cgail")
    from charctl.commands.train import train_command

    train_command("cgail", ["train.total_samples=1024", "train.keep_checkpoint_every=512"], resume=src)
    assert [n for n, _ in kept_checkpoints(src, "cgail")] == [1024]
    argv = ["eval", str(src), "--checkpoints", "--survival", "0.5", "-k", "2", "--confusion-k", "1", "--rank", "margin"]
    res = charctl_main(*argv)
    assert res.returncode == 0, res.stdout + res.stderr
    report = json.loads((src / "eval" / "checkpoints.json").read_text())
    assert [r["samples"] for r in report["rows"]] == [1024]
    assert report["chosen"]["checkpoint"] == "samples_000001024.pt" and report["confirm"]["seed"] == 7
    assert (src / "eval" / "checkpoints.png").is_file() and (src / "eval" / "checkpoints.md").is_file()
    survival = src / "eval" / "samples_000001024" / "survival.json"
    before = survival.stat().st_mtime_ns
    assert charctl_main(*argv).returncode == 0  # same settings: the kept result is reused, nothing is evaluated again
    assert survival.stat().st_mtime_ns == before
    assert json.loads((src / "eval" / "checkpoints.json").read_text())["rows"] == report["rows"]


def test_eval_checkpoints_ranks_an_amp_run_by_fidelity(smoke_runs, tmp_path, charctl_main):
    """An AMP (unconditional) run has no classifier, so no Fig 6.8 diagonal; `--checkpoints` ranks its kept
    checkpoints by fidelity (the default rank) and the table has no diagonal column."""
    _, amp, _ = smoke_runs
    out = tmp_path / "ck"
    argv = ["eval", str(amp), "--checkpoints", "--survival", "0.5", "-k", "1", "--fidelity-k", "1", "-o", str(out)]
    res = charctl_main(*argv)
    assert res.returncode == 0, res.stdout + res.stderr
    report = json.loads((out / "checkpoints.json").read_text())
    (row,) = report["rows"]  # the smoke run keeps last.pt only
    assert row["checkpoint"] == "last.pt" and row["diagonal"] is None and "margin" not in row
    assert row["min_coverage"] == min(row["fidelity"]["coverage"].values())
    assert report["chosen"]["checkpoint"] == "last.pt" and report["confirm"]["seed"] == 7
    md = (out / "checkpoints.md").read_text()
    head = "| samples | worst no-fall | skills performed (coverage >= 0.5, signature) | min coverage |"
    assert head in md and "diagonal |" not in md
    assert set(row["fidelity"]["signature_met"]) == set(row["fidelity"]["coverage"])
