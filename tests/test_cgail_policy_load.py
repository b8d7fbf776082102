"""Inference loads a cgail policy without the training machinery: policy.py (eval, export, play) imports
none of the training modules, `load_trained_run` builds no optimiser, demonstration pairs or replay
buffer, and the networks it loads are those a training agent loads from the same checkpoint."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import torch

from conftest import cli_env

REPO = Path(__file__).resolve().parents[1]
PRETRAINED = REPO / "pretrained"
TRAINING_MODULES = ("train", "rollout", "reward", "disc_update")


def test_policy_module_does_not_import_the_training_modules():
    modules = tuple(f"charctl.experiments.cgail.{m}" for m in TRAINING_MODULES)
    code = f"import sys, charctl.experiments.cgail.policy; print(sorted(m for m in {modules!r} if m in sys.modules))"
    # cwd=REPO: `python -c` puts the working directory first on sys.path, so this checkout's charctl is imported
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=cli_env(), cwd=REPO, timeout=120
    )
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[]"


def test_load_trained_run_builds_no_optimiser_and_no_training_data(monkeypatch):
    from charctl.experiments.cgail.policy import load_trained_run

    built = []
    init = torch.optim.Optimizer.__init__

    def counting_init(self, *args, **kwargs):
        built.append(type(self).__name__)
        init(self, *args, **kwargs)

    monkeypatch.setattr(torch.optim.Optimizer, "__init__", counting_init)
    tr = load_trained_run(PRETRAINED / "amp-walk")
    assert built == []
    agent = tr.agent
    assert not agent.training
    assert (agent.ppo, agent.disc_opt, agent.demos, agent.replay, agent.generator) == (None,) * 5
    assert agent.samples > 0 and tr.skill_names == ["walk"]


def test_inference_agent_loads_the_networks_of_a_training_agent():
    """Same checkpoint into `build_agent(training=False)` + `load_policy_state` and into the training agent
    + `load_agent_state`: equal policy and discriminator (normaliser included) and equal mean actions."""
    from charctl.checkpoints import load_checkpoint
    from charctl.experiments.cgail.agent import build_agent, load_agent_state
    from charctl.experiments.cgail.policy import TrainedRun, load_trained_run

    folder = PRETRAINED / "amp-walk"
    tr = load_trained_run(folder)
    full = build_agent(tr.cfg)
    load_agent_state(full, load_checkpoint(folder / "checkpoints" / "last.pt", "cgail"))
    full.model.eval()
    full.disc.eval()
    for mine, theirs in ((tr.agent.model, full.model), (tr.agent.disc, full.disc)):
        want = theirs.state_dict()
        got = mine.state_dict()
        assert got.keys() == want.keys()
        assert all(torch.equal(got[k], want[k]) for k in want)
    assert (tr.agent.iteration, tr.agent.samples) == (full.iteration, full.samples)
    env = tr.make_env(4, seed=0)
    np.testing.assert_array_equal(tr.mean_action(env), TrainedRun(folder, tr.cfg, full).mean_action(env))
