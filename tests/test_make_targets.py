"""Every `charctl train cgail` line of mk/cgail.mk's targets composes to a valid config as make would run it
(`make -n`, the make variables expanded), and the 3-skill targets of docs/cgail.md's run lineage train the keys their
sections name on top of the small preset (run H's recipe)."""

import re
import shlex
import shutil
import subprocess

import pytest

from charctl.config import compose_config
from charctl.experiments.cgail.config import Config

from conftest import REPO

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="needs make")

TARGETS = sorted(set(re.findall(r"^((?:repro|demo)-cgail[\w-]*):", (REPO / "mk" / "cgail.mk").read_text(), re.M)))


def _train_overrides(target: str) -> list[list[str]]:
    """The override lists of the target's fresh `charctl train cgail` lines (not `--resume`, not a multirun, not the
    CUDA ones), as `make -n` prints them."""
    out = subprocess.run(
        ["make", "-s", "-n", "-o", "install", target, "CGAIL_SEED=1"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    runs = []
    for line in out.splitlines():
        if "charctl train cgail" not in line:
            continue
        argv = shlex.split(line.split("charctl train cgail", 1)[1].split(" && ")[0].split(";")[0])
        if "--resume" in argv or "-m" in argv or "device=cuda" in argv:
            continue
        runs.append(argv)
    return runs


@pytest.mark.parametrize("target", TARGETS)
def test_every_fresh_training_line_composes(target):
    for argv in _train_overrides(target):
        compose_config("cgail", argv, Config)  # raises CharctlError on a bad key or value


@pytest.mark.parametrize(
    ("target", "own", "gated", "floor", "returning", "after", "window"),
    [
        ("repro-cgail-3skill-seed2", 0.0, False, 0.0, 0.0, 0.0, 0),  # run H's command at seed 2
        ("repro-cgail-3skill-window", 0.0, False, 0.0, 0.0, 0.0, 3),
        ("repro-cgail-3skill-own-window", 0.25, False, 0.0, 0.0, 0.0, 3),
        ("repro-cgail-3skill-own-window-gated", 0.25, True, 0.0, 0.0, 0.0, 3),
        ("repro-cgail-3skill-own-window-floor", 0.25, True, 0.4, 0.0, 0.0, 3),
        ("repro-cgail-3skill-return", 0.25, True, 0.4, 0.5, 0.0, 3),
        ("repro-cgail-3skill-return-gated", 0.25, True, 0.4, 0.5, 0.5, 3),
        ("repro-cgail-3skill-return-gated-switch", 0.25, True, 0.4, 0.5, 0.5, 3),
    ],
)
def test_the_lineage_targets_train_the_keys_their_sections_name(target, own, gated, floor, returning, after, window):
    (argv,) = _train_overrides(target)
    cfg = compose_config("cgail", argv, Config)
    env = cfg.env
    assert (env.own_start_weight, env.own_start_by_success, env.own_start_floor) == (own, gated, floor)
    assert (env.clip_return_seconds, env.clip_return_after_coverage, cfg.reward.goal_reference_window) == (
        returning,
        after,
        window,
    )
    assert (cfg.env.phase_obs, cfg.disc.style_head, cfg.train.total_samples) == (True, "per_skill", 40_000_000)
    assert (cfg.env.switch_prob, cfg.env.switch_prob_after_returns) == (0.01, 0.03 if target.endswith("-switch") else 0)


def test_the_ten_skill_late_switch_target_adds_the_three_skill_keys_to_the_ten_skill_command():
    """repro-cgail-10skill-late-switch = repro-cgail-10skill-track-skills's config with the late-switch env keys of
    repro-cgail-3skill-return-gated-switch (and its own output folder and checkpoint spacing)."""
    (ten,) = _train_overrides("repro-cgail-10skill-late-switch")
    (track,) = _train_overrides("repro-cgail-10skill-track-skills")
    (late,) = _train_overrides("repro-cgail-3skill-return-gated-switch")
    cfg, base, three = (compose_config("cgail", a, Config) for a in (ten, track, late))
    keys = ("own_start_weight", "own_start_by_success", "own_start_floor", "clip_return_seconds")
    keys += ("clip_return_after_coverage", "switch_prob_after_returns")
    assert {k: cfg.env[k] for k in keys} == {k: three.env[k] for k in keys} != {k: base.env[k] for k in keys}
    for k in keys:
        base.env[k] = three.env[k]
    base.output_root, base.train.keep_checkpoint_every = cfg.output_root, cfg.train.keep_checkpoint_every
    assert cfg == base and cfg.use_skills == [] and cfg.train.total_samples == 150_000_000
