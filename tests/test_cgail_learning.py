"""Slow learning checks for cgail (run with `make test-slow`; ~3 min on 2 cores).

Two skills (walk, right kick), the small preset's networks, 300k samples. The issue asks that the
style reward and the classifier's accuracy on policy samples rise. Measured on this machine
(README / docs/cgail.md): the accuracy rises (0.65-0.82 -> 0.98) but r_S does NOT recover within
this budget (it falls from ~0.19 to ~0.04-0.07 as the discriminator wins and is still at its
minimum at the end; with 1.5e6 samples the AMP baseline's r_S recovers, cGAIL's barely). The r_S
test is therefore expected to fail at this scale; it is kept as the honest check of the claim.
"""

import numpy as np
import pytest

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def scalars(tmp_path_factory):
    from charctl.commands.train import train_command
    from charctl.eval.tb import read_scalars

    root = tmp_path_factory.mktemp("cgail_learning")
    overrides = ["scale=small", "use_skills=[walk,right_kick]", "train.total_samples=300000", f"output_root={root}", "seed=1"]
    (run_dir,) = train_command("cgail", overrides)
    return read_scalars(run_dir / "tb")


def test_policy_class_accuracy_rises(scalars):
    _, acc = scalars["train/class_acc_policy"]
    n = max(3, len(acc) // 10)
    assert acc[-n:].mean() > acc[:n].mean() + 0.05, f"policy class accuracy did not rise: {acc[:n].mean():.3f} -> {acc[-n:].mean():.3f}"


def test_episode_length_rises(scalars):
    _, ep = scalars["train/episode_length"]
    n = max(3, len(ep) // 10)
    assert ep[-n:].mean() > ep[:n].mean() + 3, f"episode length did not rise: {ep[:n].mean():.1f} -> {ep[-n:].mean():.1f}"


def test_style_reward_recovers(scalars):
    _, rs = scalars["train/r_style"]
    smooth = np.convolve(rs, np.ones(10) / 10, mode="valid")
    assert smooth[-1] > smooth.min() + 0.02, f"r_S never recovered: min {smooth.min():.3f}, last {smooth[-1]:.3f}"
