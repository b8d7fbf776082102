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


def track_weights(reward_cfg, skill_names: list[str]) -> torch.Tensor:
    """(K,) float32 tracking weight w_T per skill, in the order of `skill_names` (the command indices):
    reward.w_track_skills where it names the skill, reward.w_track otherwise."""
    per_skill = dict(reward_cfg.w_track_skills)
    return torch.tensor([float(per_skill.get(n, reward_cfg.w_track)) for n in skill_names], dtype=torch.float32)


def total_reward(
    agent: Agent,
    rewards: dict,
    r_goal: torch.Tensor,
    r_track: torch.Tensor | None = None,
    cmd: torch.Tensor | None = None,
) -> torch.Tensor:
    """r = w_S r_S + w_C r_C + w_G r_G (eq 4.1), plus w_T r_track with reward.w_track (per skill with
    reward.w_track_skills: `cmd` (T, N) holds each step's command index); AMP baseline: no r_C; tracking baseline:
    r = r_track + w_G r_G (the discriminator still trains, as a style diagnostic only)."""
    rc = agent.cfg.reward
    if rc.kind == "tracking":
        return r_track + rc.w_goal * r_goal
    r = rc.w_style * rewards["r_style"] + rc.w_goal * r_goal
    if r_track is not None and rc.w_track_skills:  # per-skill w_T, indexed by each step's command
        if cmd is None:
            raise ValueError("total_reward: reward.w_track_skills needs the commands (cmd)")
        w_t = track_weights(rc, [s.name for s in agent.skills]).to(r_track.device)
        r = r + w_t[cmd] * r_track
    elif rc.w_track > 0 and r_track is not None:  # fidelity recipe: tracking reward against the pose-error reference
        r = r + rc.w_track * r_track
    if agent.conditional:
        r = r + rc.w_class * rewards["r_class"]
    return r
