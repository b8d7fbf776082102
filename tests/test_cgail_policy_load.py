"""Inference loads a cgail policy without the training machinery: policy.py (eval, export, play) imports
none of the training modules, `load_trained_run` builds no optimiser, demonstration pairs or replay
buffer, and the networks it loads are those a training agent loads from the same checkpoint."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
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


def _recorded_run(tmp_path: Path, section: str = "", key: str = "", value=None) -> Path:
    """A copy of pretrained/cgail-3skill-fidelity's config.yaml (which lists every key removed on 2026-12-03
    at its neutral value) in a run folder of its own, with `section.key` set to `value` when given."""
    import yaml

    cfg = yaml.safe_load((PRETRAINED / "cgail-3skill-fidelity" / "config.yaml").read_text())
    if key:
        cfg[section][key] = value
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    return run


def test_a_recorded_config_with_the_removed_keys_at_their_neutral_values_opens(tmp_path):
    """The removed knobs at the values that behave as the code that remains are dropped when the run is opened
    (its config.yaml is left as it was); env.curriculum_samples has no effect with the curriculum off, nor
    env.ready_wait_steps / ready_after_pass with the ready radius 0, nor the own starts' capacity, gate and floor with
    their weight 0 or the return's gate without a return, so any value of them is dropped."""
    import yaml
    from omegaconf import OmegaConf

    from charctl.experiments.cgail.config import LATE_SWITCH_KEYS, READY_START_KEYS, REMOVED_KEYS, Config
    from charctl.runs import open_run

    run = _recorded_run(tmp_path, "env", "curriculum_samples", 500_000)
    written = yaml.safe_load((run / "config.yaml").read_text())
    # a run recorded between the ready start's addition and its removal lists its keys: off, or inert with it off
    written["env"].update(ready_radius=0.0, ready_wait_steps=6, ready_after_pass=False, ready_with_return=False)
    # and a run recorded with the late-switch keys: weights 0, the inert ones at any value
    written["env"].update(own_start_weight=0.0, own_start_capacity=512, own_start_by_success=True, own_start_floor=0.4)
    written["env"].update(clip_return_seconds=0.0, clip_return_after_coverage=0.5, switch_prob_after_returns=0.0)
    (run / "config.yaml").write_text(yaml.safe_dump(written, sort_keys=False))
    before = (run / "config.yaml").read_text()
    recorded = yaml.safe_load(before)
    for key in [*REMOVED_KEYS, *READY_START_KEYS, *LATE_SWITCH_KEYS]:  # the recorded config lists every removed key
        section, leaf = key.split(".")
        assert leaf in recorded[section]
        del recorded[section][leaf]
    opened = OmegaConf.to_container(open_run(run, Config).cfg)
    default = OmegaConf.to_container(OmegaConf.structured(Config))
    assert opened.keys() == recorded.keys()
    for section, values in recorded.items():  # every other recorded value as it was
        if not isinstance(values, dict):
            assert opened[section] == values
            continue
        assert {k: opened[section][k] for k in values} == values
        added = opened[section].keys() - values.keys()  # knobs added since the run: their (neutral) defaults
        assert {k: opened[section][k] for k in added} == {k: default[section][k] for k in added}
    assert (run / "config.yaml").read_text() == before


FIRST, READY = ("2026-12-03", "8641215"), ("2026-12-07", "4c78237")  # the removals: date, last commit with them
LATE = ("2026-12-07", "6c47e68")


@pytest.mark.parametrize(
    "section, key, value, shown, removal",
    [
        ("disc", "learn_class_scale", True, "disc.learn_class_scale=true", FIRST),
        ("disc", "objective", "bce", "disc.objective=bce", FIRST),
        ("disc", "logit_reg", 0.05, "disc.logit_reg=0.05", FIRST),
        ("disc", "demo_oversample", 4, "disc.demo_oversample=4", FIRST),
        ("env", "curriculum_start_seconds", 0.5, "env.curriculum_start_seconds=0.5", FIRST),
        ("env", "ready_radius", 0.3, "env.ready_radius=0.3", READY),
        ("env", "ready_with_return", True, "env.ready_with_return=true", READY),
        ("env", "own_start_weight", 0.25, "env.own_start_weight=0.25", LATE),
        ("env", "clip_return_seconds", 0.5, "env.clip_return_seconds=0.5", LATE),
        ("env", "switch_prob_after_returns", 0.03, "env.switch_prob_after_returns=0.03", LATE),
    ],
)
def test_a_run_that_used_a_removed_option_is_refused_in_one_line(tmp_path, section, key, value, shown, removal):
    from conftest import assert_one_line_error, charctl_in_process

    run = _recorded_run(tmp_path, section, key, value)
    res = charctl_in_process("eval", str(run), "--survival", "1", "-k", "1", cwd=tmp_path)
    date, commit = removal
    line = assert_one_line_error(res, f"this run used {shown}, removed on {date}", f"at commit {commit}")
    assert str(run) in line
