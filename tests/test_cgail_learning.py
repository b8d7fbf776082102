"""Slow learning check for cgail (run with `make test-slow`; minutes on 2 cores).

Two skills (walk, right kick), small networks, 300k samples. Over training the discriminator
first wins (r_S drops), then the policy catches up. We assert what the issue asks: the style
reward recovers from its minimum and the classifier's accuracy on policy samples rises.
"""

import numpy as np
import pytest

pytestmark = pytest.mark.slow


def test_style_reward_and_policy_class_accuracy_rise(tmp_path):
    from charctl.commands.train import train_command
    from charctl.eval.tb import read_scalars

    overrides = ["scale=small", "use_skills=[walk,right_kick]", "train.total_samples=300000", f"output_root={tmp_path}", "seed=1"]
    (run_dir,) = train_command("cgail", overrides)
    s = read_scalars(run_dir / "tb")
    _, rs = s["train/r_style"]
    _, acc = s["train/class_acc_policy"]
    smooth = np.convolve(rs, np.ones(10) / 10, mode="valid")
    assert smooth[-1] > smooth.min() + 0.02, f"r_S never recovered: min {smooth.min():.3f}, last {smooth[-1]:.3f}"
    n = max(3, len(acc) // 10)
    assert acc[-n:].mean() > acc[:n].mean(), f"policy class accuracy did not rise: {acc[:n].mean():.3f} -> {acc[-n:].mean():.3f}"
