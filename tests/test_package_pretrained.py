"""scripts/package_pretrained.py: a run folder becomes a small one that `charctl eval` still takes."""

from __future__ import annotations

import numpy as np
import torch

from charctl.eval.tb import read_scalars

from conftest import load_script


def _load_script():
    return load_script("package_pretrained")


def _package(mod, monkeypatch, src, *packages: tuple) -> None:
    """Run the script on `src` once per (dest, extra flags) in `packages`, as from the command line."""
    for dest, extra in packages:
        monkeypatch.setattr("sys.argv", ["package_pretrained.py", str(src), str(dest), *extra])
        mod.main()


def test_thinned_indices_keep_first_and_last():
    mod = _load_script()
    assert mod.thinned_indices(5, 10).tolist() == [0, 1, 2, 3, 4]
    assert mod.thinned_indices(101, 5).tolist() == [0, 25, 50, 75, 100]
    assert mod.thinned_indices(10, 2).tolist() == [0, 9]


def test_packaged_smoke_run_has_thinned_scalars_and_no_replay(smoke_run, tmp_path, monkeypatch):
    mod = _load_script()
    src = smoke_run("cgail")
    dest = tmp_path / "packaged"
    monkeypatch.setattr("sys.argv", ["package_pretrained.py", str(src), str(dest), "--max-points", "2"])
    mod.main()
    before, after = read_scalars(src / "tb"), read_scalars(dest / "tb")
    assert set(after) == set(before)
    for tag, (steps, values) in before.items():
        s2, v2 = after[tag]
        assert len(s2) == min(2, len(steps))
        assert s2[0] == steps[0] and s2[-1] == steps[-1]
        np.testing.assert_allclose(v2[-1], values[-1], rtol=1e-6)
    payload = torch.load(dest / "checkpoints" / "last.pt", map_location="cpu", weights_only=True)
    assert "replay" not in payload["state"] and "ppo" in payload["state"]


def test_packaging_a_kept_checkpoint_cuts_the_scalars_at_it(smoke_run_copy, tmp_path, monkeypatch):
    """--checkpoint samples_000000768.pt ships that checkpoint as last.pt, keeps only scalars logged at
    steps <= 768 and records the choice in metrics.json; the run's resumes.txt (override history) is kept."""
    import json

    from charctl.commands.train import train_command

    mod = _load_script()
    src = smoke_run_copy("cgail")
    train_command("cgail", ["train.total_samples=1024", "train.keep_checkpoint_every=256"], resume=src)
    dest = tmp_path / "packaged"
    argv = ["package_pretrained.py", str(src), str(dest), "--checkpoint", "samples_000000768.pt"]
    monkeypatch.setattr("sys.argv", argv)
    mod.main()
    payload = torch.load(dest / "checkpoints" / "last.pt", map_location="cpu", weights_only=True)
    assert payload["state"]["samples"] == 768 and "replay" not in payload["state"]
    steps, _ = read_scalars(dest / "tb")["train/episode_length"]
    assert max(steps) == 768 and max(read_scalars(src / "tb")["train/episode_length"][0]) == 1024
    assert json.loads((dest / "metrics.json").read_text())["packaged_checkpoint"]["samples"] == 768
    resumes = (src / "resumes.txt").read_text()  # the resume above wrote its overrides; the package keeps them
    assert "train.keep_checkpoint_every=256" in resumes and (dest / "resumes.txt").read_text() == resumes


def test_an_inference_only_package_evaluates_and_fine_tunes_with_fresh_optimisers(
    smoke_run, tmp_path, monkeypatch, capsys
):
    """--inference-only leaves out both optimiser states (the checkpoint shrinks); the package still loads for
    evaluation with the same networks, and a resume trains on from it with fresh optimisers (a note says so)."""
    from charctl.commands.train import train_command
    from charctl.experiments.cgail.policy import load_trained_run

    mod = _load_script()
    src = smoke_run("cgail")
    full, slim = tmp_path / "full", tmp_path / "slim"
    _package(mod, monkeypatch, src, (full, []), (slim, ["--inference-only"]))
    payload = torch.load(slim / "checkpoints" / "last.pt", map_location="cpu", weights_only=True)
    state = payload["state"]
    assert state["inference_only"] and "disc_opt" not in state and set(state["ppo"]) == {"model"}
    assert (slim / "checkpoints" / "last.pt").stat().st_size < 0.6 * (full / "checkpoints" / "last.pt").stat().st_size
    a, b = load_trained_run(full), load_trained_run(slim)
    for x, y in zip(a.agent.model.state_dict().values(), b.agent.model.state_dict().values(), strict=True):
        assert torch.equal(x, y)
    samples = int(state["samples"])
    train_command("cgail", [f"train.total_samples={samples + 256}"], resume=slim)
    assert "optimiser states" in capsys.readouterr().out
    resumed = torch.load(slim / "checkpoints" / "last.pt", map_location="cpu", weights_only=True)["state"]
    assert int(resumed["samples"]) > samples and "optimizer" in resumed["ppo"] and "disc_opt" in resumed


def test_bf16_moments_shrink_a_resumable_package_that_resumes_with_float32_moments(smoke_run, tmp_path, monkeypatch):
    """--bf16-moments keeps both optimiser states with Adam's moments in bfloat16 (the checkpoint shrinks by
    about a third of the full one: moments are two thirds of it, halved); the training agent's load (what
    `--resume` calls) gives both optimisers float32 moments equal to the rounded originals."""
    from charctl.experiments.cgail.agent import build_agent, load_agent_state
    from charctl.experiments.cgail.policy import load_trained_run

    mod = _load_script()
    src = smoke_run("cgail")
    full, half = tmp_path / "full", tmp_path / "half"
    _package(mod, monkeypatch, src, (full, []), (half, ["--bf16-moments"]))
    size = {d: (d / "checkpoints" / "last.pt").stat().st_size for d in (full, half)}
    assert 0.55 * size[full] < size[half] < 0.75 * size[full]
    original = torch.load(full / "checkpoints" / "last.pt", map_location="cpu", weights_only=True)["state"]
    rounded = torch.load(half / "checkpoints" / "last.pt", map_location="cpu", weights_only=True)["state"]
    moments = rounded["ppo"]["optimizer"]["state"][0]
    assert moments["exp_avg"].dtype == torch.bfloat16 and moments["step"].dtype == torch.float32
    agent = build_agent(load_trained_run(half).cfg)
    load_agent_state(agent, rounded)
    loaded = agent.ppo.optimizer.state_dict()["state"][0]["exp_avg"]
    expected = original["ppo"]["optimizer"]["state"][0]["exp_avg"].to(torch.bfloat16).float()
    assert loaded.dtype == torch.float32 and torch.equal(loaded, expected)
    disc_moment = agent.disc_opt.state_dict()["state"][0]["exp_avg_sq"]
    assert disc_moment.dtype == torch.float32
    assert torch.equal(disc_moment, original["disc_opt"]["state"][0]["exp_avg_sq"].to(torch.bfloat16).float())


def test_bf16_moments_and_inference_only_together_are_refused_before_writing(smoke_run, tmp_path, monkeypatch):
    import pytest

    mod = _load_script()
    dest = tmp_path / "packaged"
    argv = ["package_pretrained.py", str(smoke_run("cgail")), str(dest), "--bf16-moments", "--inference-only"]
    monkeypatch.setattr("sys.argv", argv)
    with pytest.raises(SystemExit, match="pass one"):
        mod.main()
    assert not dest.exists()
