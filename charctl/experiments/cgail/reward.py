"""The cgail reward in one place: the discriminator rewards of a rollout (style r_S, blended class
r_C) and the total reward that PPO maximises (eq 4.1, the AMP and tracking baselines)."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from charctl.experiments.cgail.agent import Agent
from charctl.experiments.cgail.discriminator import blended_class_reward, style_reward
from charctl.experiments.cgail.rollout import Rollout


@torch.no_grad()
def discriminator_rewards(agent: Agent, ro: Rollout) -> dict[str, torch.Tensor]:
    """r_S, r_C (blended) and class probabilities for every rollout pair, in one forward."""
    T, N = ro.pairs.shape[:2]
    d, logits = agent.disc(ro.pairs.reshape(T * N, -1), cond=ro.cond.reshape(T * N, -1))
    out = {"d": d.reshape(T, N), "r_style": style_reward(d).reshape(T, N)}
    if logits is not None:
        probs = F.softmax(logits, dim=-1)
        out["probs"] = probs.reshape(T, N, -1)
        out["r_class"] = blended_class_reward(
            probs,
            ro.cmd_a.reshape(-1),
            ro.cmd_b.reshape(-1),
            ro.w.reshape(-1),
            agent.num_skills,
            agent.cfg.reward.class_form,
        ).reshape(T, N)
    return out


def total_reward(
    agent: Agent, rewards: dict, r_goal: torch.Tensor, r_track: torch.Tensor | None = None
) -> torch.Tensor:
    """r = w_S r_S + w_C r_C + w_G r_G (eq 4.1), plus w_T r_track with reward.w_track; AMP baseline: no r_C;
    tracking baseline: r = r_track + w_G r_G (the discriminator still trains, as a style diagnostic only)."""
    rc = agent.cfg.reward
    if rc.kind == "tracking":
        return r_track + rc.w_goal * r_goal
    r = rc.w_style * rewards["r_style"] + rc.w_goal * r_goal
    if rc.w_track > 0 and r_track is not None:  # fidelity recipe: tracking reward against the pose-error reference
        r = r + rc.w_track * r_track
    if agent.conditional:
        r = r + rc.w_class * rewards["r_class"]
    return r
