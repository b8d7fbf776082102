"""cgail training loop: batched rollouts -> discriminator rewards -> PPO -> discriminator update.

Per iteration: `rollout_steps` control steps of all envs (one policy forward per step for the
whole batch), then one discriminator forward over every (o_t, o_t+1) pair of the rollout for
r_S and r_C, GAE + PPO epochs, and `disc.steps_per_iter` discriminator steps on balanced
demonstration pairs vs policy pairs (half fresh, half from the replay buffer).

This module is the learner that runs those phases in turn (or overlapped); the phases live beside it:
agent.py (networks, optimisers, checkpoint state), rollout.py, reward.py and disc_update.py.
"""

from __future__ import annotations

import copy
import dataclasses
import threading
import time

import numpy as np
import torch

from charctl.experiments.cgail.agent import Agent, agent_state, build_agent, load_agent_state
from charctl.experiments.cgail.config import method_label
from charctl.experiments.cgail.disc_update import class_accuracy_on_policy, update_discriminator
from charctl.experiments.cgail.env import CgailEnv
from charctl.experiments.cgail.env_rules import env_rules
from charctl.experiments.cgail.reward import discriminator_rewards, total_reward
from charctl.experiments.cgail.rollout import Rollout, collect_rollout
from charctl.experiments.cgail.termination import LowStyleTermination
from charctl.rl.runner import AgentCounters, crossed_multiple


# ---------------------------------------------------------------------------- the learner
def _torch_cpu_sim(env_cfg):
    """env.backend=torch: C MuJoCo (`BatchedHumanoid`) seen as torch tensors on the CPU, for `CgailEnv`."""
    from charctl.sim.batch import SimSettings
    from charctl.sim.torch_view import TorchBatchedHumanoid

    return TorchBatchedHumanoid(int(env_cfg.num_envs), SimSettings.of(env_cfg))


def _synchronize(device: str) -> None:
    """Wait for queued CUDA work (no-op on the CPU), so wall-clock phase timings are attributed correctly."""
    if torch.device(device).type == "cuda":
        torch.cuda.synchronize(device)


class CgailLearner(AgentCounters):
    """One cgail iteration for the shared runner (charctl.rl.runner): rollout, rewards, PPO,
    discriminator. Counters live on the agent so checkpoints keep their layout."""

    def __init__(self, cfg):
        from charctl.config import resolve_device
        from charctl.sim.warp_batch import resolve_backend

        torch.set_num_threads(int(cfg.train.torch_threads))
        self.cfg = cfg
        self.device = resolve_device(str(cfg.device))  # auto -> cuda when available, else cpu
        self.backend = resolve_backend(str(getattr(cfg.env, "backend", "cpu")), self.device)  # cpu | warp | torch
        self.agent = build_agent(cfg, self.device)
        env_args = dict(seed=cfg.seed, conditional=self.agent.conditional, **env_rules(cfg.reward))
        if self.backend == "warp":  # torch on MuJoCo Warp on the same device: rollout never leaves it
            env_args["device"] = self.device
        elif self.backend == "torch":  # torch on the CPU over C MuJoCo's arrays (no copies)
            env_args["sim"] = _torch_cpu_sim(cfg.env)
        self.env = CgailEnv(self.agent.skills, cfg.env, **env_args)  # numpy over C MuJoCo for env.backend=cpu
        self.samples_per_iteration = cfg.train.rollout_steps * self.env.N
        self.episode_lengths: list = []
        self.rng = np.random.default_rng(cfg.seed + 7919)
        self.overlap = bool(cfg.train.overlap_update) and self.backend in ("cpu", "torch")  # not on a GPU
        # overlap: the rollout acts with this copy (the policy as of the last finished update) while the
        # worker thread updates self.agent.model; `pending` is the rollout the next update consumes
        self.acting = dataclasses.replace(self.agent, model=copy.deepcopy(self.agent.model)) if self.overlap else None
        self.pending: Rollout | None = None
        rc = cfg.reward
        self.terminate = (
            LowStyleTermination(self.agent.disc, self.env.N, rc.low_style_threshold, rc.low_style_steps)
            if rc.low_style_threshold > 0
            else None
        )

    def state_dict(self) -> dict:
        """Checkpoint state. With the overlapped loop the pending rollout's updates are run first, so
        the checkpoint holds every collected sample and a resume loses nothing."""
        if self.pending is not None:
            self._update(self.pending, stale_behaviour=True)
            self.pending = None
        return agent_state(self.agent, self.env)

    def load_state_dict(self, state: dict) -> None:
        load_agent_state(self.agent, state, self.env)
        self.rng = np.random.default_rng(self.cfg.seed + 7919 * (self.agent.iteration + 1))

    def signature(self) -> dict:
        return self.agent.signature()

    def modules(self) -> list[torch.nn.Module]:
        return [self.agent.model, self.agent.disc]

    def iterate(self) -> dict[str, float]:
        """One iteration (`_iterate_in_turn` or, with train.overlap_update, `_iterate_overlapped`), plus the
        cheap fidelity scalars each time the samples cross a multiple of train.fidelity_every (no update
        is running then, so the policy is not changing under the evaluation)."""
        stats = self._iterate_overlapped() if self.overlap else self._iterate_in_turn()
        every, step = int(self.cfg.train.fidelity_every), self.samples_per_iteration
        if crossed_multiple(self.agent.samples + step, step, every):
            from charctl.experiments.cgail.fidelity import training_fidelity

            stats.update(training_fidelity(self.agent, seed=self.agent.iteration))
        return stats

    def _iterate_in_turn(self) -> dict[str, float]:
        """Rollout, rewards, PPO and discriminator updates, one after another."""
        if self.terminate is not None:
            self.terminate.sync(self.agent.disc)
        t0 = time.perf_counter()
        ro = self._rollout(self.agent)
        t1 = time.perf_counter()
        rew, reward = self._rewards(ro)
        t2 = time.perf_counter()
        update_stats, t_ppo, t_disc = self._update(ro)
        t4 = time.perf_counter()
        timing = {
            "perf/samples_per_s": self.samples_per_iteration / (t4 - t0),
            "perf/rollout_samples_per_s": self.samples_per_iteration / (t1 - t0),
            "perf/frac_rollout": (t1 - t0) / (t4 - t0),
            "perf/frac_reward": (t2 - t1) / (t4 - t0),
            "perf/frac_ppo": t_ppo / (t4 - t0),
            "perf/frac_disc": t_disc / (t4 - t0),
        }
        return self._statistics(ro, rew, reward, {**update_stats, **timing})

    def _iterate_overlapped(self) -> dict[str, float]:
        """This iteration's rollout (acting with the policy of the last finished update) in the main
        thread while a worker thread runs the PPO and discriminator updates on the previous rollout.
        MuJoCo and torch release the GIL in their kernels, so the two share the cores; the rollout's
        rewards use the discriminator after the worker's update."""
        self.acting.model.load_state_dict(self.agent.model.state_dict())
        if self.terminate is not None:  # before the worker starts updating the discriminator
            self.terminate.sync(self.agent.disc)
        pending, self.pending = self.pending, None
        result: dict = {}
        worker = None
        if pending is not None:
            worker = threading.Thread(target=self._update_into, args=(pending, result), name="cgail-update")
            worker.start()
        t0 = time.perf_counter()
        try:
            ro = self._rollout(self.acting)
        finally:  # an error or Ctrl-C in the rollout still waits for the update (no thread left behind)
            t1 = time.perf_counter()
            if worker is not None:
                worker.join()
        t_wait = time.perf_counter() - t1
        if "error" in result:
            raise result["error"]
        rew, reward = self._rewards(ro)
        self.pending = ro
        t4 = time.perf_counter()
        update_stats, t_ppo, t_disc = result.get("out", ({}, 0.0, 0.0))
        timing = {
            "perf/samples_per_s": self.samples_per_iteration / (t4 - t0),
            "perf/rollout_samples_per_s": self.samples_per_iteration / (t1 - t0),
            "perf/frac_rollout": (t1 - t0) / (t4 - t0),
            "perf/frac_wait_update": t_wait / (t4 - t0),  # the worker still busy after the rollout
            "perf/frac_reward": (t4 - t1 - t_wait) / (t4 - t0),
            "perf/frac_ppo": t_ppo / (t4 - t0),  # overlapped with the rollout: the fractions sum to > 1
            "perf/frac_disc": t_disc / (t4 - t0),
        }
        return self._statistics(ro, rew, reward, {**update_stats, **timing})

    def _rollout(self, actor: Agent) -> Rollout:
        """`train.rollout_steps` control steps of every env, acting with `actor`'s policy."""
        return collect_rollout(actor, self.env, self.cfg.train.rollout_steps, terminate=self.terminate)

    def _rewards(self, ro: Rollout) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
        """Discriminator rewards and the total reward of `ro`, written into its storage with the returns
        and advantages (bootstrapped with the critic that acted)."""
        agent, env, cfg = self.agent, self.env, self.cfg
        rew = discriminator_rewards(agent, ro)
        reward = total_reward(agent, rew, ro.r_goal, ro.r_track, ro.cmd_b) + ro.bootstrap
        ro.storage.rewards = reward
        critic = (self.acting or agent).model
        with torch.no_grad():
            dev = agent.device
            blend = torch.as_tensor(env.command_blend(), dtype=torch.float32, device=dev) if agent.conditional else None
            last_v = critic.value(torch.as_tensor(env.state, dtype=torch.float32, device=dev), blend)
        ro.storage.finish(last_v, cfg.ppo.gamma, cfg.ppo.lam)
        _synchronize(agent.device)  # phase timings on a GPU: wait for the queued kernels
        return rew, reward

    def _update(self, ro: Rollout, stale_behaviour: bool = False) -> tuple[dict[str, float], float, float]:
        """PPO on `ro`, then the observation normaliser, then the discriminator: (stats, PPO s, disc s)."""
        agent = self.agent
        t0 = time.perf_counter()
        ppo_stats = agent.ppo.update(ro.storage, stale_behaviour=stale_behaviour)
        # normaliser statistics move only after the update, so the PPO ratio starts at exactly 1
        agent.model.obs_norm.update(ro.storage.obs)
        t1 = time.perf_counter()
        disc_stats = update_discriminator(agent, ro, self.rng)
        return {**ppo_stats, **disc_stats}, t1 - t0, time.perf_counter() - t1

    def _update_into(self, ro: Rollout, result: dict) -> None:
        """`_update` for the worker thread: its output, or the exception it raised, into `result`."""
        try:
            result["out"] = self._update(ro, stale_behaviour=True)
        except BaseException as exc:  # re-raised in the main thread
            result["error"] = exc

    def _statistics(self, ro: Rollout, rew: dict, reward: torch.Tensor, extra: dict[str, float]) -> dict[str, float]:
        """The iteration's scalars: `extra` (update losses, timings) plus the rollout's rewards and counters."""
        agent, env = self.agent, self.env
        agent.unstable_total += ro.unstable
        self.episode_lengths = (self.episode_lengths + list(ro.episode_lengths))[-200:]
        n = self.samples_per_iteration
        mean_len = float(np.mean(self.episode_lengths)) if self.episode_lengths else float(self.cfg.train.rollout_steps)
        stats = {
            **extra,
            "train/r_style": float(rew["r_style"].mean()),
            "train/r_goal": float(ro.r_goal.mean()),
            "train/r_track": float(ro.r_track.mean()),
            "train/reward": float(reward.mean()),
            "train/episode_length": mean_len,
            "train/unstable_resets_total": float(agent.unstable_total),
            "train/falls": float(ro.falls),
            "train/style_terminations": float(ro.style_ends),
            "train/pose_terminations": float(ro.pose_ends),
            "train/unstable_rate": float(ro.unstable) / n,
            "sim/unstable_resets": float(ro.unstable),
        }
        if agent.conditional:  # both envs keep per-skill failure rates (env.skill_fall_weight)
            stats.update({f"fall_rate/{sk.name}": float(r) for sk, r in zip(agent.skills, env.fall_rate.tolist())})
            stats["train/r_class"] = float(rew["r_class"].mean())
            stats.update(class_accuracy_on_policy(agent, ro, rew["probs"]))
        return stats

    def progress_fields(self, stats: dict[str, float]) -> dict[str, float]:
        fields = {"r_S": stats["train/r_style"], "ep_len": stats["train/episode_length"]}
        if self.agent.conditional:
            fields["acc_pol"] = stats["train/class_acc_policy"]
        return fields

    def summary(self, stats: dict[str, float]) -> dict:
        prefixes = ("train/", "perf/", "class_acc_policy/", "class_acc_data/")
        short = {
            (k.split("/", 1)[1] if k.startswith(("train/", "perf/")) else k.replace("/", "_")): v
            for k, v in stats.items()
            if k.startswith(prefixes) and k != "perf/samples_per_s"
        }
        return {
            "skills": [s.name for s in self.agent.skills],
            "conditional": self.agent.conditional,
            "ppo_update_precision": self.agent.ppo.precision,  # ppo.update_precision=auto resolved here
            **short,
        }


# ---------------------------------------------------------------------------- main loop
def train(cfg, run) -> dict:
    """Train cgail (or its AMP baseline) into `run` with the shared on-policy runner."""
    from charctl.rl.runner import RunnerSettings, run_on_policy

    learner = CgailLearner(cfg)
    settings = RunnerSettings(
        total_samples=int(cfg.train.total_samples),
        checkpoint_every=int(cfg.train.checkpoint_every),
        keep_every=int(cfg.train.keep_checkpoint_every),
        log_every=int(cfg.train.log_every),
        description=f"cgail ({method_label(cfg)}, {learner.agent.num_skills} skills)",
    )
    return run_on_policy(learner, run, settings)
