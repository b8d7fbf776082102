"""srb training: batched SRB rollouts -> PPO (charctl.rl) with the paper's hyper-parameters.

Per iteration: `rollout_steps` control steps of `num_envs` environments (paper §8: m = 1024
samples per update), one policy forward per step for the whole batch, GAE(0.995, 0.95), then
PPO epochs over minibatches of 256, then the observation normaliser absorbs the rollout (so the
log-probabilities of acting and of the update use the same statistics). Time-limit truncations
bootstrap with gamma * V(s_final) (folded into the reward, see charctl.rl.storage.compute_gae);
terminations do not.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import torch

from charctl.experiments.srb.env import ACT_DIM, OBS_DIM, SRBEnv
from charctl.rl.ppo import PPO, ActorCritic, PPOConfig
from charctl.rl.storage import RolloutStorage


def ppo_config(cfg) -> PPOConfig:
    """The PPOConfig dataclass from the (OmegaConf) ppo section."""
    from omegaconf import OmegaConf

    return PPOConfig(**OmegaConf.to_container(cfg.ppo, resolve=True)) if not isinstance(cfg.ppo, PPOConfig) else cfg.ppo


@dataclass
class Agent:
    """Policy/value networks, optimiser and counters: everything a checkpoint holds."""

    model: ActorCritic
    ppo: PPO
    iteration: int = 0
    samples: int = 0
    wall_time: float = 0.0
    history: dict = field(default_factory=lambda: {"iteration": [], "samples": [], "episode_length": [], "episode_return": [], "reward": []})

    def signature(self, cfg) -> dict:
        return {"obs_dim": OBS_DIM, "act_dim": ACT_DIM, "hidden": list(cfg.ppo.hidden), "activation": str(cfg.ppo.activation)}

    def state(self) -> dict:
        return {"ppo": self.ppo.state_dict(), "iteration": self.iteration, "samples": self.samples,
                "wall_time": self.wall_time, "history": self.history}

    def load(self, state: dict) -> None:
        self.ppo.load_state_dict(state["ppo"])
        self.iteration, self.samples = int(state["iteration"]), int(state["samples"])
        self.wall_time = float(state.get("wall_time", 0.0))
        self.history = state.get("history", self.history)


def build_agent(cfg) -> Agent:
    torch.manual_seed(int(cfg.seed))
    pcfg = ppo_config(cfg)
    model = ActorCritic(OBS_DIM, ACT_DIM, pcfg)
    gen = torch.Generator().manual_seed(int(cfg.seed) + 1)
    return Agent(model=model, ppo=PPO(model, pcfg, generator=gen))


def load_policy(run) -> tuple[Agent, dict]:
    """The trained agent of a run directory (for evaluation / export)."""
    agent = build_agent(run.cfg)
    state = run.load_checkpoint(agent.signature(run.cfg))
    agent.load(state)
    agent.model.eval()
    return agent, state


def policy_actions(model: ActorCritic, obs: np.ndarray, deterministic: bool = True) -> np.ndarray:
    with torch.no_grad():
        a, _, _ = model.act(torch.as_tensor(obs, dtype=torch.float32), deterministic=deterministic)
    return a.numpy().astype(float)


@dataclass
class RolloutStats:
    rewards: list = field(default_factory=list)
    lengths: list = field(default_factory=list)
    returns: list = field(default_factory=list)
    terminated: int = 0
    truncated: int = 0


def collect_rollout(agent: Agent, env: SRBEnv, storage: RolloutStorage, obs: np.ndarray, gamma: float) -> tuple[np.ndarray, RolloutStats]:
    """Fill `storage` with one rollout; returns the next observation and episode statistics."""
    model = agent.model
    stats = RolloutStats()
    storage.clear()
    for _ in range(storage.steps):
        obs_t = torch.as_tensor(obs, dtype=torch.float32)
        action, logp, value = model.act(obs_t)
        obs, reward, terminal, truncated, info = env.step(action.numpy().astype(float))
        reward_t = torch.as_tensor(reward, dtype=torch.float32)
        idx = info["done_idx"]
        if idx.size:
            trunc = truncated[idx]
            if trunc.any():  # bootstrap time-limit truncations: r += gamma V(s_final)
                with torch.no_grad():
                    v_final = model.value(torch.as_tensor(info["final_obs"][trunc], dtype=torch.float32))
                reward_t[torch.as_tensor(idx[trunc])] += gamma * v_final
            stats.lengths.extend(info["episode_length"].tolist())
            stats.returns.extend(info["episode_return"].tolist())
            stats.terminated += int(terminal[idx].sum())
            stats.truncated += int(trunc.sum())
        done = torch.as_tensor(terminal | truncated, dtype=torch.float32)
        storage.add(obs_t, None, action, logp, value, reward_t, done)
        stats.rewards.append(float(reward.mean()))
    with torch.no_grad():
        last_v = model.value(torch.as_tensor(obs, dtype=torch.float32))
    storage.finish(last_v, gamma, agent.ppo.cfg.lam)
    return obs, stats


def train(cfg, run) -> dict:
    from charctl.progress import TrainingProgress
    from charctl.runs import StopFlag

    torch.set_num_threads(int(cfg.train.torch_threads))
    agent = build_agent(cfg)
    if run.resumed:
        agent.load(run.load_checkpoint(agent.signature(cfg)))
    tc = cfg.train
    env = SRBEnv(cfg, int(tc.num_envs), seed=int(cfg.seed) + 1000 * agent.iteration)
    storage = RolloutStorage(int(tc.rollout_steps), int(tc.num_envs), OBS_DIM, ACT_DIM)
    per_iter = int(tc.num_envs) * int(tc.rollout_steps)
    total = int(tc.total_samples)
    obs = env.observe()
    gamma = float(cfg.ppo.gamma)
    t_rollout = t_update = 0.0
    samples_start = agent.samples
    start = time.perf_counter()
    last_len = last_ret = float("nan")
    with StopFlag() as stop, TrainingProgress(total, "srb (SRB + QP, PPO)") as bar:
        bar.update(agent.samples)
        while agent.samples < total and not stop.requested:
            t0 = time.perf_counter()
            obs, stats = collect_rollout(agent, env, storage, obs, gamma)
            t1 = time.perf_counter()
            losses = agent.ppo.update(storage)
            agent.model.obs_norm.update(storage.obs)  # after the update: acting and PPO saw the same statistics
            t2 = time.perf_counter()
            t_rollout += t1 - t0
            t_update += t2 - t1
            agent.iteration += 1
            agent.samples += per_iter
            agent.wall_time += t2 - t0
            if stats.lengths:
                last_len, last_ret = float(np.mean(stats.lengths)), float(np.mean(stats.returns))
            mean_r = float(np.mean(stats.rewards))
            h = agent.history
            for k, v in (("iteration", agent.iteration), ("samples", agent.samples), ("episode_length", last_len),
                         ("episode_return", last_ret), ("reward", mean_r)):
                h[k].append(v)
            run.log_scalars({"rollout/reward_per_step": mean_r, "rollout/episode_length": last_len, "rollout/episode_return": last_ret,
                             "rollout/terminated": stats.terminated, "rollout/truncated": stats.truncated,
                             "perf/samples_per_s": per_iter / max(t2 - t0, 1e-9), **losses}, agent.samples)
            bar.update(per_iter, len=last_len, ret=last_ret, r=mean_r)
            if agent.iteration % int(tc.checkpoint_every) == 0:
                run.save_checkpoint(agent.state(), agent.signature(cfg))
    run.save_checkpoint(agent.state(), agent.signature(cfg))
    elapsed = time.perf_counter() - start
    new_samples = agent.samples - samples_start
    metrics = {
        "iterations": agent.iteration, "samples": agent.samples, "episode_length": last_len, "episode_return": last_ret,
        "reward_per_step": agent.history["reward"][-1] if agent.history["reward"] else float("nan"),
        "reward_per_step_last25": float(np.nanmean(agent.history["reward"][-25:])) if agent.history["reward"] else float("nan"),
        "wall_time_s": agent.wall_time, "session_wall_s": elapsed,
        "samples_per_s": new_samples / max(elapsed, 1e-9),
        "rollout_samples_per_s": new_samples / max(t_rollout, 1e-9), "update_s_per_iteration": t_update / max(agent.iteration - (samples_start // per_iter), 1),
        "qp_solves": env.stats["qp_solves"], "qp_failures": env.stats["qp_failures"],
        "late_touchdowns": env.stats["late_touchdowns"], "early_touchdowns": env.stats["early_touchdowns"],
        "stopped_early": bool(stop.requested),
    }
    run.write_metrics(metrics)
    write_curve(run, agent.history)
    return metrics


def moving_average(x: np.ndarray, window: int) -> np.ndarray:
    """Trailing mean over `window` points (NaNs ignored), same length as x."""
    x = np.asarray(x, dtype=float)
    ok = np.isfinite(x)
    c = np.concatenate([[0.0], np.cumsum(np.where(ok, x, 0.0))])
    n = np.concatenate([[0], np.cumsum(ok)])
    idx = np.arange(1, x.size + 1)
    lo = np.maximum(idx - window, 0)
    count = n[idx] - n[lo]
    return np.where(count > 0, (c[idx] - c[lo]) / np.maximum(count, 1), np.nan)


def write_curve(run, history: dict) -> None:
    """training_curve.png: episode length and reward per step against samples (raw + 25-iteration mean)."""
    if not history["samples"]:
        return
    from charctl.viz.plots import new_figure, save_figure

    fig, axes = new_figure(1, 2, figsize=(10, 3.6))
    x = np.array(history["samples"], dtype=float)
    for ax, key, label, color in ((axes[0], "episode_length", "mean episode length (steps)", "tab:blue"),
                                  (axes[1], "reward", "reward per step", "tab:orange")):
        y = np.array(history[key], dtype=float)
        ax.plot(x, y, lw=0.6, alpha=0.35, color=color)
        ax.plot(x, moving_average(y, 25), lw=1.6, color=color)
        ax.set_xlabel("samples"), ax.set_ylabel(label), ax.grid(alpha=0.3)
    fig.suptitle("srb training (thin: per iteration, thick: 25-iteration mean)")
    save_figure(fig, run.path("training_curve.png"))
