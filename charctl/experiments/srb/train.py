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
from charctl.rl.runner import AgentCounters
from charctl.rl.storage import RolloutStorage


def ppo_config(section) -> PPOConfig:
    """The PPOConfig dataclass from the (OmegaConf) `ppo` section of the config."""
    from omegaconf import OmegaConf

    return section if isinstance(section, PPOConfig) else PPOConfig(**OmegaConf.to_container(section, resolve=True))


@dataclass
class Agent:
    """Policy/value networks, optimiser and counters: everything a checkpoint holds."""

    model: ActorCritic
    ppo: PPO
    iteration: int = 0
    samples: int = 0
    wall_time: float = 0.0
    history: dict = field(
        default_factory=lambda: {
            "iteration": [],
            "samples": [],
            "episode_length": [],
            "episode_return": [],
            "reward": [],
        }
    )

    def signature(self, cfg) -> dict:
        return {
            "obs_dim": OBS_DIM,
            "act_dim": ACT_DIM,
            "hidden": list(cfg.ppo.hidden),
            "activation": str(cfg.ppo.activation),
        }

    def state(self) -> dict:
        return {
            "ppo": self.ppo.state_dict(),
            "iteration": self.iteration,
            "samples": self.samples,
            "wall_time": self.wall_time,
            "history": self.history,
            "ppo_gen_rng": self.ppo.generator.get_state() if self.ppo.generator is not None else None,
        }

    def load(self, state: dict) -> None:
        self.ppo.load_state_dict(state["ppo"])
        if state.get("ppo_gen_rng") is not None and self.ppo.generator is not None:
            self.ppo.generator.set_state(state["ppo_gen_rng"])  # minibatch permutations continue, not repeat
        self.iteration, self.samples = int(state["iteration"]), int(state["samples"])
        self.wall_time = float(state.get("wall_time", 0.0))
        self.history = state.get("history", self.history)


def build_agent(cfg) -> Agent:
    torch.manual_seed(int(cfg.seed))
    pcfg = ppo_config(cfg.ppo)
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


def collect_rollout(
    agent: Agent, env: SRBEnv, storage: RolloutStorage, obs: np.ndarray, gamma: float
) -> tuple[np.ndarray, RolloutStats]:
    """Fill `storage` with one rollout; returns the next observation and episode statistics."""
    model = agent.model
    stats = RolloutStats()
    storage.clear()
    for _ in range(storage.steps):
        obs_t = torch.as_tensor(obs, dtype=torch.float32, device=storage.obs.device)
        action, logp, value = model.act(obs_t)
        obs, reward, terminal, truncated, info = env.step(action.cpu().numpy().astype(float))
        reward_t = torch.as_tensor(reward, dtype=torch.float32, device=obs_t.device)
        idx = info["done_idx"]
        if idx.size:
            trunc = truncated[idx]
            if trunc.any():  # bootstrap time-limit truncations: r += gamma V(s_final)
                with torch.no_grad():
                    final = torch.as_tensor(info["final_obs"][trunc], dtype=torch.float32, device=obs_t.device)
                    v_final = model.value(final)
                reward_t[torch.as_tensor(idx[trunc], device=obs_t.device)] += gamma * v_final
            stats.lengths.extend(info["episode_length"].tolist())
            stats.returns.extend(info["episode_return"].tolist())
            stats.terminated += int(terminal[idx].sum())
            stats.truncated += int(trunc.sum())
        done = torch.as_tensor(terminal | truncated, dtype=torch.float32, device=obs_t.device)
        storage.add(obs_t, None, action, logp, value, reward_t, done)
        stats.rewards.append(float(reward.mean()))
    with torch.no_grad():
        last_v = model.value(torch.as_tensor(obs, dtype=torch.float32, device=storage.obs.device))
    storage.finish(last_v, gamma, agent.ppo.cfg.lam)
    return obs, stats


class SrbLearner(AgentCounters):
    """One srb iteration for the shared runner (charctl.rl.runner): SRB + QP rollout, then PPO."""

    def __init__(self, cfg, run):
        torch.set_num_threads(int(cfg.train.torch_threads))
        self.cfg, self.run = cfg, run
        self.agent = build_agent(cfg)
        tc = cfg.train
        from charctl.config import resolve_device

        self.device = resolve_device(str(cfg.device))  # networks and rollout storage; the SRB env stays numpy
        self.agent.model.to(self.device)  # in place: the optimiser keeps the same parameters
        self.storage = RolloutStorage(int(tc.rollout_steps), int(tc.num_envs), OBS_DIM, ACT_DIM, device=self.device)
        self.samples_per_iteration = int(tc.num_envs) * int(tc.rollout_steps)
        self.env: SRBEnv | None = None
        self.obs: np.ndarray | None = None
        self.last_len = self.last_ret = float("nan")
        self.t_rollout = self.t_update = 0.0
        self.iterations_this_session = 0

    def _ensure_env(self) -> None:
        """The env is seeded from the iteration count, so it is built after a resume."""
        if self.env is None:
            tc = self.cfg.train
            self.env = SRBEnv(self.cfg, int(tc.num_envs), seed=int(self.cfg.seed) + 1000 * self.agent.iteration)
            self.obs = self.env.observe()

    def state_dict(self) -> dict:
        return self.agent.state()

    def load_state_dict(self, state: dict) -> None:
        self.agent.load(state)

    def signature(self) -> dict:
        return self.agent.signature(self.cfg)

    def modules(self) -> list[torch.nn.Module]:
        return [self.agent.model]

    def iterate(self) -> dict[str, float]:
        self._ensure_env()
        agent = self.agent
        t0 = time.perf_counter()
        self.obs, stats = collect_rollout(agent, self.env, self.storage, self.obs, float(self.cfg.ppo.gamma))
        t1 = time.perf_counter()
        losses = agent.ppo.update(self.storage)
        agent.model.obs_norm.update(self.storage.obs)  # after the update: acting and PPO saw the same statistics
        t2 = time.perf_counter()
        self.t_rollout += t1 - t0
        self.t_update += t2 - t1
        self.iterations_this_session += 1
        agent.wall_time += t2 - t0
        if stats.lengths:
            self.last_len, self.last_ret = float(np.mean(stats.lengths)), float(np.mean(stats.returns))
        mean_r = float(np.mean(stats.rewards))
        h = agent.history
        for k, v in (
            ("iteration", agent.iteration + 1),
            ("samples", agent.samples + self.samples_per_iteration),
            ("episode_length", self.last_len),
            ("episode_return", self.last_ret),
            ("reward", mean_r),
        ):
            h[k].append(v)
        # episode statistics are NaN until the first episode ends: logged only once they exist
        episode = {"rollout/episode_length": self.last_len, "rollout/episode_return": self.last_ret}
        return {
            "rollout/reward_per_step": mean_r,
            **{k: v for k, v in episode.items() if np.isfinite(v)},
            "rollout/terminated": float(stats.terminated),
            "rollout/truncated": float(stats.truncated),
            "perf/samples_per_s": self.samples_per_iteration / max(t2 - t0, 1e-9),
            **losses,
        }

    def progress_fields(self, stats: dict[str, float]) -> dict[str, float]:
        return {"len": self.last_len, "ret": self.last_ret, "r": stats["rollout/reward_per_step"]}

    def summary(self, stats: dict[str, float]) -> dict:
        h, env = self.agent.history, self.env
        write_curve(self.run, h)
        return {
            "episode_length": self.last_len,
            "episode_return": self.last_ret,
            "reward_per_step": h["reward"][-1] if h["reward"] else float("nan"),
            "reward_per_step_last25": float(np.nanmean(h["reward"][-25:])) if h["reward"] else float("nan"),
            "train_wall_s": self.agent.wall_time,
            "rollout_samples_per_s": self.iterations_this_session
            * self.samples_per_iteration
            / max(self.t_rollout, 1e-9),
            "update_s_per_iteration": self.t_update / max(self.iterations_this_session, 1),
            "qp_solves": env.stats["qp_solves"],
            "qp_failures": env.stats["qp_failures"],
            "late_touchdowns": env.stats["late_touchdowns"],
            "early_touchdowns": env.stats["early_touchdowns"],
        }


def train(cfg, run) -> dict:
    """Train the srb policy into `run` with the shared on-policy runner."""
    from charctl.rl.runner import RunnerSettings, run_on_policy

    tc = cfg.train
    settings = RunnerSettings(
        total_samples=int(tc.total_samples),
        checkpoint_every=int(tc.checkpoint_every),
        description="srb (SRB + QP, PPO)",
    )
    return run_on_policy(SrbLearner(cfg, run), run, settings)


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
    for ax, key, label, color in (
        (axes[0], "episode_length", "mean episode length (steps)", "tab:blue"),
        (axes[1], "reward", "reward per step", "tab:orange"),
    ):
        y = np.array(history[key], dtype=float)
        ax.plot(x, y, lw=0.6, alpha=0.35, color=color)
        ax.plot(x, moving_average(y, 25), lw=1.6, color=color)
        ax.set_xlabel("samples"), ax.set_ylabel(label), ax.grid(alpha=0.3)
    fig.suptitle("srb training (thin: per iteration, thick: 25-iteration mean)")
    save_figure(fig, run.path("training_curve.png"))
