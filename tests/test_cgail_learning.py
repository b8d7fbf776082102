"""Slow learning checks for cgail (run with `make test-slow`; ~2 min on 2 cores).

Two skills (walk, right kick), the small preset, 300k samples: the classifier's accuracy on policy
samples and the episode length must rise, and the discriminator must not win. The last check used to
be "r_S recovers after collapsing" (with the landed preset's fast discriminator r_S fell from ~0.19 to
0.04-0.07 and stayed there, so it failed); with the balanced recipe r_S no longer collapses, so the
check is now the stricter floor: the smoothed r_S stays above 0.3 for the whole run (the old preset's
minimum was 0.04-0.07; measured with the recipe: minimum 0.55 at 300k samples).
"""

import numpy as np
import pytest

from conftest import cgail_paper_recipe

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def scalars(tmp_path_factory):
    from charctl.commands.train import train_command
    from charctl.eval.tb import read_scalars

    root = tmp_path_factory.mktemp("cgail_learning")
    overrides = [
        "scale=small",
        # the paper's reward and termination (mk/cgail.mk CGAIL_PAPER_RECIPE): these checks were written for it,
        # before the small preset took the fidelity recipe
        *cgail_paper_recipe(),
        "use_skills=[walk,right_kick]",
        "train.total_samples=300000",
        f"output_root={root}",
        "seed=1",
    ]
    (run_dir,) = train_command("cgail", overrides)
    return read_scalars(run_dir / "tb")


def test_policy_class_accuracy_rises(scalars):
    _, acc = scalars["train/class_acc_policy"]
    n = max(3, len(acc) // 10)
    assert acc[-n:].mean() > acc[:n].mean() + 0.05, (
        f"policy class accuracy did not rise: {acc[:n].mean():.3f} -> {acc[-n:].mean():.3f}"
    )


def test_episode_length_rises(scalars):
    _, ep = scalars["train/episode_length"]
    n = max(3, len(ep) // 10)
    assert ep[-n:].mean() > ep[:n].mean() + 3, (
        f"episode length did not rise: {ep[:n].mean():.1f} -> {ep[-n:].mean():.1f}"
    )


def test_style_reward_never_collapses(scalars):
    _, rs = scalars["train/r_style"]
    smooth = np.convolve(rs, np.ones(10) / 10, mode="valid")
    assert smooth.min() > 0.3, f"the discriminator won: smoothed r_S fell to {smooth.min():.3f}"
