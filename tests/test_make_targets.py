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
    ("target", "seed", "window"), [("repro-cgail-3skill-seed2", 2, 0), ("repro-cgail-3skill-window", 1, 3)]
)
def test_the_run_h_variants_train_run_hs_command_with_the_keys_their_sections_name(target, seed, window):
    (argv,) = _train_overrides(target)
    cfg = compose_config("cgail", argv, Config)
    assert (cfg.seed, cfg.reward.goal_reference_window, cfg.env.switch_prob) == (seed, window, 0.01)
    assert (cfg.env.phase_obs, cfg.disc.style_head, cfg.train.total_samples) == (True, "per_skill", 40_000_000)
