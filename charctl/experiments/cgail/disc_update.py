"""The cgail discriminator update: `disc.steps_per_iter` gradient steps per iteration on balanced
demonstration pairs vs policy pairs (half fresh from the rollout, half from the replay buffer; with
disc.wrong_skill_fakes also demonstration pairs scored for another skill), and the classifier's accuracy
on policy pairs. The networks and losses themselves live in discriminator.py."""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from charctl.experiments.cgail.agent import Agent
from charctl.experiments.cgail.discriminator import (
    class_loss,
    gradient_penalty,
    style_loss,
    wrong_skill_labels,
)
from charctl.experiments.cgail.rollout import Rollout


def update_discriminator(agent: Agent, ro: Rollout, rng: np.random.Generator) -> dict[str, float]:
    """`disc.steps_per_iter` discriminator steps against the policy pairs of `ro`, then those pairs into the
    replay buffer; the mean of the steps' statistics. Demonstration pairs are drawn with `rng` on the CPU
    (with the agent's device generator off it), policy pairs and wrong-skill labels with `agent.generator`."""
    cfg = agent.cfg.disc
    K = agent.num_skills
    n_wrong = int(cfg.batch_size * cfg.wrong_skill_fakes) if K > 1 else 0
    fresh_pairs = ro.pairs.reshape(-1, ro.pairs.shape[-1])
    fresh_cond = ro.cond.reshape(-1, K)
    stats: dict[str, float] = {}
    for _ in range(cfg.steps_per_iter):
        demo, labels = _demonstration_batch(agent, rng, fresh_pairs.device)
        pol, pol_c = _policy_batch(agent, fresh_pairs, fresh_cond, cfg.batch_size - n_wrong)
        out = _discriminator_losses(agent, demo, labels, pol, pol_c, n_wrong)
        agent.disc_opt.zero_grad(set_to_none=True)
        out["loss"].backward()
        agent.disc_opt.step()
        with torch.no_grad():
            step_stats = _step_statistics(agent, out, labels, n_wrong)
        for k, v in step_stats.items():
            stats[k] = stats.get(k, 0.0) + v / cfg.steps_per_iter
    agent.replay.add(fresh_pairs, fresh_cond)
    return stats


def _demonstration_batch(
    agent: Agent, rng: np.random.Generator, dev: torch.device
) -> tuple[torch.Tensor, torch.Tensor]:
    """`disc.batch_size` demonstration pairs (balanced over skills) and their clip labels, on `dev`."""
    n = agent.cfg.disc.batch_size
    if agent.device_generator is not None:  # off the CPU: demonstration pairs are drawn on the device
        demo, labels = agent.demos.sample_torch(n, agent.device_generator)
    else:
        demo, labels = agent.demos.sample(n, rng)
        demo = torch.from_numpy(demo)
        labels = torch.from_numpy(labels)
    return demo.to(dev), labels.to(dev)


def _policy_batch(
    agent: Agent, fresh_pairs: torch.Tensor, fresh_cond: torch.Tensor, n_pol: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """`n_pol` policy pairs and their command blends: fresh ones of the rollout and, once the replay buffer
    holds some, a `disc.replay_fraction` share drawn from it."""
    dev = fresh_pairs.device
    n_replay = int(n_pol * agent.cfg.disc.replay_fraction) if agent.replay.size > 0 else 0
    idx = torch.randint(0, fresh_pairs.shape[0], (n_pol - n_replay,), generator=agent.generator).to(dev)
    pol, pol_c = fresh_pairs[idx], fresh_cond[idx]
    if n_replay:
        rp, rc = agent.replay.sample(n_replay, agent.generator)
        pol, pol_c = torch.cat([pol, rp]), torch.cat([pol_c, rc])
    return pol, pol_c


def _discriminator_losses(
    agent: Agent, demo: torch.Tensor, labels: torch.Tensor, pol: torch.Tensor, pol_c: torch.Tensor, n_wrong: int
) -> dict[str, torch.Tensor]:
    """The discriminator loss of one batch ("loss"), its parts ("style", "gp", "class") and the scores
    the step statistics read ("d_data", "c_data", "d_pol", "d_fake")."""
    cfg, K = agent.cfg.disc, agent.num_skills
    demo_onehot = F.one_hot(labels, K).float()
    demo_n = agent.disc.norm(demo)
    d_data, c_data = agent.disc(demo_n, normalized=True, cond=demo_onehot)
    d_pol, c_pol = agent.disc(pol, cond=pol_c)
    d_fake = d_pol
    if n_wrong:  # demonstration pairs scored for another skill: fakes for that skill's logit
        wrong = wrong_skill_labels(labels[:n_wrong], K, agent.generator)
        d_wrong, _ = agent.disc(demo_n[:n_wrong], normalized=True, cond=F.one_hot(wrong, K).float())
        d_fake = torch.cat([d_pol, d_wrong])
    l_style = style_loss(d_data, d_fake)
    l_gp = gradient_penalty(agent.disc, demo_n, cfg.w_gp, cond=demo_onehot)
    loss = l_style + l_gp
    l_cls = torch.zeros((), device=demo.device)
    if agent.conditional:
        kind = agent.cfg.cgail.class_loss
        l_cls = class_loss(c_data, demo_onehot, kind)
        if bool(agent.cfg.cgail.class_on_policy):
            l_cls = l_cls + class_loss(c_pol, pol_c, kind)
        loss = loss + cfg.w_class_loss * l_cls
    parts = {"loss": loss, "style": l_style, "gp": l_gp, "class": l_cls}
    return {**parts, "d_data": d_data, "c_data": c_data, "d_pol": d_pol, "d_fake": d_fake}


def _step_statistics(
    agent: Agent, out: dict[str, torch.Tensor], labels: torch.Tensor, n_wrong: int
) -> dict[str, float]:
    """One discriminator step's losses and accuracies: data vs policy (and wrong-skill) pairs, and with the
    class head its accuracy and mean own-label probability on data pairs, overall and per skill."""
    d_data, d_pol, d_fake, c_data = out["d_data"], out["d_pol"], out["d_fake"], out["c_data"]
    n_pol = agent.cfg.disc.batch_size - n_wrong
    step_stats = {
        "losses/disc_style": float(out["style"]),
        "losses/disc_gp": float(out["gp"]),
        "losses/disc_class": float(out["class"]),
        "train/disc_acc_data": float((d_data > 0).float().mean()),
        "train/disc_acc_policy": float((d_pol < 0).float().mean()),
        **({"train/disc_acc_wrong_skill": float((d_fake[n_pol:] < 0).float().mean())} if n_wrong else {}),
    }
    if agent.conditional:
        hit = (c_data.argmax(-1) == labels).float()
        step_stats["train/class_acc_data"] = float(hit.mean())
        # mean probability of the clip's own label on data pairs: the data-side Fig 6.8 diagonal
        step_stats["train/class_prob_data"] = float(c_data.softmax(-1).gather(-1, labels[:, None]).mean())
        for k, sk in enumerate(agent.skills):
            m = labels == k
            if m.any():
                step_stats[f"class_acc_data/{sk.name}"] = float(hit[m].mean())
    return step_stats


def class_accuracy_on_policy(agent: Agent, ro: Rollout, probs: torch.Tensor) -> dict[str, float]:
    """Accuracy of the classifier on policy pairs outside transitions (w = 1), overall and per skill."""
    pred = probs.argmax(-1)
    steady = ro.w >= 1.0
    out = {}
    correct = (pred == ro.cmd_b) & steady
    out["train/class_acc_policy"] = float(correct.sum() / steady.sum().clamp(min=1))
    for k, s in enumerate(agent.skills):
        m = steady & (ro.cmd_b == k)
        if m.any():
            out[f"class_acc_policy/{s.name}"] = float(((pred == k) & m).sum() / m.sum())
    return out
