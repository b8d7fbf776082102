"""cgail training loop: batched rollouts -> discriminator rewards -> PPO -> discriminator update.

Per iteration: `rollout_steps` control steps of all envs (one policy forward per step for the
whole batch), then one discriminator forward over every (o_t, o_t+1) pair of the rollout for
r_S and r_C, GAE + PPO epochs, and `disc.steps_per_iter` discriminator steps on balanced
demonstration pairs vs policy pairs (half fresh, half from the replay buffer).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import threading
import time
from dataclasses import dataclass, field

import numpy as np
import torch
import torch.nn.functional as F

from charctl.experiments.cgail.discriminator import (
    Discriminator,
    ReplayBuffer,
    blended_class_reward,
    class_loss,
    gradient_penalty,
    logit_regulariser,
    style_loss,
    style_reward,
    weight_decay_term,
    wrong_skill_labels,
)
from charctl.experiments.cgail.env import CgailEnv
from charctl.experiments.cgail.skills import DemoPairs, load_skills, select_skills
from charctl.experiments.cgail.termination import LowStyleTermination
from charctl.rl.ppo import PPO, ActorCritic, make_adam
from charctl.rl.runner import AgentCounters, crossed_multiple
from charctl.rl.storage import RolloutStorage


@dataclass
class Agent:
    """Everything a checkpoint holds, built from a config."""

    cfg: object
    skills: list
    model: ActorCritic
    ppo: PPO
    disc: Discriminator
    disc_opt: torch.optim.Optimizer
    demos: DemoPairs
    replay: ReplayBuffer
    generator: torch.Generator
    iteration: int = 0
    samples: int = 0
    unstable_total: int = 0
    history: dict = field(default_factory=dict)
    device: str = "cpu"  # torch device of networks, rollout storage, replay and (off the CPU) demonstration pairs
    device_generator: torch.Generator | None = None  # off the CPU: draws demonstration pairs on the device

    @functools.cached_property
    def conditional(self) -> bool:
        """cGAIL (command-conditioned) or AMP; read once (the rollout asks every control step)."""
        return bool(self.cfg.cgail.conditional)

    @property
    def num_skills(self) -> int:
        return len(self.skills)

    def signature(self) -> dict:
        return {
            "skills": ",".join(s.name for s in self.skills),
            "conditional": self.conditional,
            "reward": str(self.cfg.reward.kind),
            "policy_hidden": list(self.cfg.ppo.hidden),
            "disc_hidden": list(self.cfg.disc.hidden),
        }


def build_agent(cfg, device: str = "cpu") -> Agent:
    """Networks, optimisers, demonstration data and replay buffer for `cfg` (seeded), on torch `device`.

    Off the CPU (device=cuda) the demonstration pairs also move to the device and are drawn there
    (`DemoPairs.sample_torch`); on the CPU everything is as it always was (numpy draws)."""
    torch.manual_seed(cfg.seed)
    skills = load_skills(select_skills(cfg), cfg.env.control_hz, cfg.disc.demo_oversample)
    K = len(skills)
    conditional = bool(cfg.cgail.conditional)
    from charctl.experiments.cgail.env import GOAL_DIM, PHASE_DIM
    from charctl.experiments.cgail.features import DISC_OBS_DIM, STATE_DIM

    state_dim = STATE_DIM + GOAL_DIM + (PHASE_DIM if cfg.reward.kind == "tracking" else 0)
    model = ActorCritic(state_dim, 28, cfg.ppo, cond_dim=K if conditional else 0).to(device)
    gen = torch.Generator().manual_seed(cfg.seed)
    ppo = PPO(model, cfg.ppo, generator=gen)
    disc = Discriminator(
        2 * DISC_OBS_DIM,
        K,
        list(cfg.disc.hidden),
        conditional=conditional,
        learn_class_scale=cfg.disc.learn_class_scale,
        style_head=cfg.disc.style_head,
    )
    demos = DemoPairs(skills)
    pairs, _ = demos.all()
    with torch.no_grad():
        disc.norm.update(torch.from_numpy(pairs))  # normalise with demonstration statistics (frozen)
    disc = disc.to(device)
    disc_opt = make_adam(discriminator_param_groups(disc, cfg.disc), lr=cfg.disc.lr)
    replay = ReplayBuffer(cfg.disc.replay_size, 2 * DISC_OBS_DIM, K, device=device)
    agent = Agent(cfg, skills, model, ppo, disc, disc_opt, demos, replay, gen, device=str(device))
    if torch.device(device).type != "cpu":
        demos.to_device(device)
        agent.device_generator = torch.Generator(device=device).manual_seed(int(cfg.seed) + 104729)
    return agent


def discriminator_param_groups(disc: Discriminator, dcfg) -> list[dict]:
    """Adam parameter groups: the class head (and its learned temperature) at `class_lr` (when set),
    everything else at `lr`."""

    def in_class_head(name: str) -> bool:
        return name.startswith("class_head.") or name == "class_log_scale"

    head = [p for n, p in disc.named_parameters() if in_class_head(n)]
    rest = [p for n, p in disc.named_parameters() if not in_class_head(n)]
    groups = [{"params": rest, "lr": dcfg.lr}]
    if head:
        groups.append({"params": head, "lr": dcfg.class_lr if dcfg.class_lr > 0 else dcfg.lr})
    return groups


def agent_state(agent: Agent, env: CgailEnv | None = None) -> dict:
    state = {
        "ppo": agent.ppo.state_dict(),
        "disc": agent.disc.state_dict(),
        "disc_opt": agent.disc_opt.state_dict(),
        "replay": agent.replay.state_dict(),
        "iteration": agent.iteration,
        "samples": agent.samples,
        "unstable_total": agent.unstable_total,
        "gen_rng": agent.generator.get_state(),
        "skills": [s.name for s in agent.skills],
        "clips": [s.clip_name for s in agent.skills],
    }
    if agent.device_generator is not None:  # demonstration pairs drawn on the device
        state["device_gen_rng"] = agent.device_generator.get_state().cpu()
    if env is not None and getattr(env, "on_device", False):
        state["env_torch_rng"] = env.generator.get_state().cpu()  # device env (env.backend=warp): torch generator
    elif env is not None:
        state["env_rng"] = env.rng.bit_generator.state
    return state


def load_agent_state(agent: Agent, state: dict, env: CgailEnv | None = None) -> None:
    agent.ppo.load_state_dict(state["ppo"])
    agent.disc.load_state_dict(state["disc"])
    agent.disc_opt.load_state_dict(state["disc_opt"])
    if "replay" in state:  # shipped (pretrained/) checkpoints leave the replay buffer out
        agent.replay.load_state_dict(state["replay"])
    agent.iteration, agent.samples = int(state["iteration"]), int(state["samples"])
    agent.unstable_total = int(state.get("unstable_total", 0))
    agent.generator.set_state(state["gen_rng"].cpu())
    if agent.device_generator is not None and "device_gen_rng" in state:
        agent.device_generator.set_state(state["device_gen_rng"].cpu())
    if env is not None and getattr(env, "on_device", False):
        if "env_torch_rng" in state:
            env.generator.set_state(state["env_torch_rng"].cpu())
    elif env is not None and "env_rng" in state:
        env.rng.bit_generator.state = state["env_rng"]


# ---------------------------------------------------------------------------- rollout
@dataclass
class Rollout:
    storage: RolloutStorage
    pairs: torch.Tensor  # (T, N, 266)
    cond: torch.Tensor  # (T, N, K) command blend c̄_t
    cmd_a: torch.Tensor  # (T, N)
    cmd_b: torch.Tensor
    w: torch.Tensor
    r_goal: torch.Tensor  # (T, N)
    r_track: torch.Tensor  # (T, N) tracking reward (zeros unless reward.kind=tracking)
    bootstrap: torch.Tensor  # (T, N) gamma * V(s_final) on truncation
    episode_lengths: list
    unstable: int
    falls: int
    style_ends: int = 0  # episodes ended by a low style reward (reward.low_style_threshold)
    pose_ends: int = 0  # episodes ended by a large pose error (reward.pose_error_threshold)


def collect_rollout(
    agent: Agent,
    env: CgailEnv,
    steps: int,
    deterministic: bool = False,
    terminate: LowStyleTermination | None = None,
) -> Rollout:
    """Step all envs `steps` times with one batched policy forward per step.

    The per-step policy forward is small (num_envs rows): it runs on one torch thread, which
    avoids thread wake-up latency that costs more than the matmul itself on a busy machine;
    MuJoCo's batch threads do the parallel work here.
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        if getattr(env, "on_device", False):  # env.backend=warp: everything stays on the device
            return _collect_rollout_device(agent, env, steps, deterministic)
        return _collect_rollout(agent, env, steps, deterministic, terminate)
    finally:
        torch.set_num_threads(threads)


def _collect_rollout(
    agent: Agent, env: CgailEnv, steps: int, deterministic: bool, terminate: LowStyleTermination | None = None
) -> Rollout:
    N, K = env.N, agent.num_skills
    dev = torch.device(agent.device)  # the CPU env's numpy arrays go to the learner's device (no-op on the CPU)
    storage = RolloutStorage(steps, N, env.state_dim, 28, K if agent.conditional else 0, device=dev)
    pairs = torch.zeros(steps, N, agent.disc.norm.mean.shape[0], device=dev)
    cond_all = torch.zeros(steps, N, K, device=dev)
    cmd_a = torch.zeros(steps, N, dtype=torch.long, device=dev)
    cmd_b = torch.zeros(steps, N, dtype=torch.long, device=dev)
    w = torch.zeros(steps, N, device=dev)
    r_goal = torch.zeros(steps, N, device=dev)
    r_track = torch.zeros(steps, N, device=dev)
    bootstrap = torch.zeros(steps, N, device=dev)
    lengths = []
    unstable = falls = style_ends = pose_ends = 0
    for t in range(steps):
        obs = torch.as_tensor(env.state, dtype=torch.float32, device=dev)
        blend = torch.as_tensor(env.command_blend(), dtype=torch.float32, device=dev)
        cond = blend if agent.conditional else None
        action, logp, value = agent.model.act(obs, cond, deterministic=deterministic)
        o_t = env.obs.copy()
        cmd_a[t], cmd_b[t], w[t], cond_all[t] = (
            torch.from_numpy(env.prev_cmd),
            torch.from_numpy(env.cmd),
            torch.from_numpy(env.w),
            blend,
        )
        steps_before = env.steps.copy()
        res = env.step(action.cpu().numpy().astype(np.float64))
        pairs[t] = torch.from_numpy(np.concatenate([o_t, res.pair_next], axis=1))
        r_goal[t] = torch.from_numpy(res.r_goal)
        r_track[t] = torch.from_numpy(res.r_track)
        done = res.terminated | res.truncated
        if terminate is not None:  # episodes whose style reward stayed low end here (no bootstrap)
            ended = terminate.update(pairs[t], blend, torch.from_numpy(done).to(dev)).cpu().numpy()
            if ended.any():
                env.reset(np.flatnonzero(ended))
                done = done | ended
                style_ends += int(ended.sum())
        if res.truncated.any():
            idx = np.flatnonzero(res.truncated)
            fs = torch.as_tensor(res.final_state[idx], dtype=torch.float32, device=dev)
            with torch.no_grad():
                v_final = agent.model.value(fs, blend[idx] if agent.conditional else None)
            bootstrap[t, torch.as_tensor(idx, device=dev)] = agent.cfg.ppo.gamma * v_final
        storage.add(
            obs,
            blend if agent.conditional else None,
            action,
            logp,
            value,
            torch.zeros(N, device=dev),
            torch.from_numpy(done).to(dev),
        )
        lengths += list(steps_before[done] + 1)
        unstable += int(res.unstable.sum())
        pose_ended = res.pose_ended if res.pose_ended is not None else np.zeros(N, dtype=bool)
        falls += int((res.terminated & ~res.unstable & ~pose_ended).sum())
        pose_ends += int(pose_ended.sum())
    return Rollout(
        storage,
        pairs,
        cond_all,
        cmd_a,
        cmd_b,
        w,
        r_goal,
        r_track,
        bootstrap,
        lengths,
        unstable,
        falls,
        style_ends,
        pose_ends,
    )


def _collect_rollout_device(agent: Agent, env, steps: int, deterministic: bool) -> Rollout:
    """`_collect_rollout` for the device env (`CgailDeviceEnv`, env.backend=warp): every buffer lives on
    the env's device and the loop never reads a value back to the host. Truncated envs' final states
    are kept and bootstrapped with one critic forward after the loop (same parameters as during the
    loop, so the same values); episode lengths and counters are read once per rollout."""
    N, K = env.N, agent.num_skills
    dev = env.device
    cond_dim = K if agent.conditional else 0
    storage = RolloutStorage(steps, N, env.state_dim, 28, cond_dim, device=dev)
    pairs = torch.zeros(steps, N, agent.disc.norm.mean.shape[0], device=dev)
    cond_all = torch.zeros(steps, N, K, device=dev)
    cmd_a = torch.zeros(steps, N, dtype=torch.long, device=dev)
    cmd_b = torch.zeros(steps, N, dtype=torch.long, device=dev)
    w = torch.zeros(steps, N, device=dev)
    r_goal = torch.zeros(steps, N, device=dev)
    r_track = torch.zeros(steps, N, device=dev)
    bootstrap = torch.zeros(steps, N, device=dev)
    final_states = torch.zeros(steps, N, env.state_dim, device=dev)
    truncated = torch.zeros(steps, N, dtype=torch.bool, device=dev)
    ended = torch.zeros(steps, N, dtype=torch.bool, device=dev)
    ep_len = torch.zeros(steps, N, dtype=torch.long, device=dev)
    unstable = torch.zeros((), dtype=torch.long, device=dev)
    falls = torch.zeros((), dtype=torch.long, device=dev)
    zeros = torch.zeros(N, device=dev)
    for t in range(steps):
        obs = env.state
        blend = env.command_blend()
        cond = blend if agent.conditional else None
        action, logp, value = agent.model.act(obs, cond, deterministic=deterministic)
        o_t = env.obs
        cmd_a[t], cmd_b[t], w[t], cond_all[t] = env.prev_cmd, env.cmd, env.w, blend
        steps_before = env.steps
        res = env.step(action)
        pairs[t] = torch.cat([o_t, res.pair_next], dim=1)
        r_goal[t], r_track[t] = res.r_goal, res.r_track
        done = res.terminated | res.truncated
        final_states[t], truncated[t], ended[t] = res.final_state, res.truncated, done
        ep_len[t] = steps_before + 1
        storage.add(obs, cond, action, logp, value, zeros, done)
        unstable += res.unstable.sum()
        falls += (res.terminated & ~res.unstable).sum()
    if bool(truncated.any()):  # the rollout's only host reads: this, the lengths and the two counters
        with torch.no_grad():
            v_final = agent.model.value(final_states[truncated], cond_all[truncated] if agent.conditional else None)
        bootstrap[truncated] = agent.cfg.ppo.gamma * v_final
    lengths = ep_len[ended].tolist()
    return Rollout(
        storage, pairs, cond_all, cmd_a, cmd_b, w, r_goal, r_track, bootstrap, lengths, int(unstable), int(falls)
    )


@torch.no_grad()
def discriminator_rewards(agent: Agent, ro: Rollout) -> dict[str, torch.Tensor]:
    """r_S, r_C (blended) and class probabilities for every rollout pair, in one forward."""
    T, N = ro.pairs.shape[:2]
    d, logits = agent.disc(ro.pairs.reshape(T * N, -1), cond=ro.cond.reshape(T * N, -1))
    out = {"d": d.reshape(T, N), "r_style": style_reward(d, agent.cfg.disc.objective).reshape(T, N)}
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


# ---------------------------------------------------------------------------- discriminator update
def update_discriminator(agent: Agent, ro: Rollout, rng: np.random.Generator) -> dict[str, float]:
    cfg = agent.cfg.disc
    K = agent.num_skills
    class_on_policy = bool(agent.cfg.cgail.class_on_policy)
    n_wrong = int(cfg.batch_size * cfg.wrong_skill_fakes) if K > 1 else 0
    fresh_pairs = ro.pairs.reshape(-1, ro.pairs.shape[-1])
    fresh_cond = ro.cond.reshape(-1, K)
    stats: dict[str, float] = {}
    dev = fresh_pairs.device
    for _ in range(cfg.steps_per_iter):
        if agent.device_generator is not None:  # off the CPU: demonstration pairs are drawn on the device
            demo, labels = agent.demos.sample_torch(cfg.batch_size, agent.device_generator)
        else:
            demo, labels = agent.demos.sample(cfg.batch_size, rng)
            demo = torch.from_numpy(demo)
            labels = torch.from_numpy(labels)
        demo, labels = demo.to(dev), labels.to(dev)
        n_pol = cfg.batch_size - n_wrong
        n_replay = int(n_pol * cfg.replay_fraction) if agent.replay.size > 0 else 0
        idx = torch.randint(0, fresh_pairs.shape[0], (n_pol - n_replay,), generator=agent.generator).to(dev)
        pol, pol_c = fresh_pairs[idx], fresh_cond[idx]
        if n_replay:
            rp, rc = agent.replay.sample(n_replay, agent.generator)
            pol, pol_c = torch.cat([pol, rp]), torch.cat([pol_c, rc])
        demo_onehot = F.one_hot(labels, K).float()
        demo_n = agent.disc.norm(demo)
        d_data, c_data = agent.disc(demo_n, normalized=True, cond=demo_onehot)
        d_pol, c_pol = agent.disc(pol, cond=pol_c)
        d_fake = d_pol
        if n_wrong:  # demonstration pairs scored for another skill: fakes for that skill's logit
            wrong = wrong_skill_labels(labels[:n_wrong], K, agent.generator)
            d_wrong, _ = agent.disc(demo_n[:n_wrong], normalized=True, cond=F.one_hot(wrong, K).float())
            d_fake = torch.cat([d_pol, d_wrong])
        l_style = style_loss(d_data, d_fake, cfg.objective)
        l_gp = gradient_penalty(agent.disc, demo_n, cfg.w_gp, cond=demo_onehot)
        loss = l_style + l_gp
        if cfg.logit_reg > 0:
            loss = loss + cfg.logit_reg * logit_regulariser(agent.disc)
        if cfg.weight_decay > 0:
            loss = loss + cfg.weight_decay * weight_decay_term(agent.disc)
        l_cls = torch.zeros((), device=dev)
        if agent.conditional:
            kind = agent.cfg.cgail.class_loss
            l_cls = class_loss(c_data, demo_onehot, kind)
            if class_on_policy:
                l_cls = l_cls + class_loss(c_pol, pol_c, kind)
            loss = loss + cfg.w_class_loss * l_cls
        agent.disc_opt.zero_grad(set_to_none=True)
        loss.backward()
        agent.disc_opt.step()
        with torch.no_grad():
            step_stats = {
                "losses/disc_style": float(l_style),
                "losses/disc_gp": float(l_gp),
                "losses/disc_class": float(l_cls),
                "train/disc_acc_data": float((d_data > 0).float().mean()),
                "train/disc_acc_policy": float((d_pol < 0).float().mean()),
                **({"train/disc_acc_wrong_skill": float((d_fake[n_pol:] < 0).float().mean())} if n_wrong else {}),
            }
            if agent.conditional:
                hit = (c_data.argmax(-1) == labels).float()
                step_stats["train/class_acc_data"] = float(hit.mean())
                # mean probability of the clip's own label on data pairs: the data-side Fig 6.8 diagonal
                step_stats["train/class_prob_data"] = float(c_data.softmax(-1).gather(-1, labels[:, None]).mean())
                if agent.disc.class_log_scale is not None:
                    step_stats["train/class_scale"] = float(agent.disc.class_log_scale.exp())
                for k, sk in enumerate(agent.skills):
                    m = labels == k
                    if m.any():
                        step_stats[f"class_acc_data/{sk.name}"] = float(hit[m].mean())
        for k, v in step_stats.items():
            stats[k] = stats.get(k, 0.0) + v / cfg.steps_per_iter
    agent.replay.add(fresh_pairs, fresh_cond)
    return stats


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


# ---------------------------------------------------------------------------- the learner
def _synchronize(device: str) -> None:
    """Wait for queued CUDA work (no-op on the CPU), so wall-clock phase timings are attributed correctly."""
    if torch.device(device).type == "cuda":
        torch.cuda.synchronize(device)


def episode_limit_steps(env_cfg, samples: int) -> int:
    """Truncation length (control steps) of training episodes after `samples` samples: the
    curriculum's start length growing linearly to `episode_seconds` over `curriculum_samples`
    (env.curriculum_*), or `episode_seconds` throughout when the curriculum is off."""
    full = env_cfg.episode_seconds
    start = env_cfg.curriculum_start_seconds or full
    seconds = start + (full - start) * min(1.0, samples / env_cfg.curriculum_samples)
    return max(1, int(round(seconds * env_cfg.control_hz)))


class CgailLearner(AgentCounters):
    """One cgail iteration for the shared runner (charctl.rl.runner): rollout, rewards, PPO,
    discriminator. Counters live on the agent so checkpoints keep their layout."""

    def __init__(self, cfg):
        from charctl.config import resolve_device
        from charctl.sim.warp_batch import resolve_backend

        torch.set_num_threads(int(cfg.train.torch_threads))
        self.cfg = cfg
        self.device = resolve_device(str(cfg.device))  # auto -> cuda when available, else cpu
        self.backend = resolve_backend(str(getattr(cfg.env, "backend", "cpu")), self.device)  # cpu | warp
        self.agent = build_agent(cfg, self.device)
        if self.backend == "warp":  # MuJoCo Warp on the same device: rollout never leaves it
            from charctl.experiments.cgail.env_torch import CgailDeviceEnv

            self.env = CgailDeviceEnv(
                self.agent.skills,
                cfg.env,
                seed=cfg.seed,
                conditional=self.agent.conditional,
                tracking=cfg.reward.kind == "tracking",
                device=self.device,
            )
        else:
            self.env = CgailEnv(
                self.agent.skills,
                cfg.env,
                seed=cfg.seed,
                conditional=self.agent.conditional,
                tracking=cfg.reward.kind == "tracking",
                pose_error_threshold=cfg.reward.pose_error_threshold,
                pose_error_grace_steps=cfg.reward.pose_error_grace_steps,
                reference_reward=cfg.reward.w_track > 0,
            )
        self.samples_per_iteration = cfg.train.rollout_steps * self.env.N
        self.episode_lengths: list = []
        self.rng = np.random.default_rng(cfg.seed + 7919)
        self.overlap = bool(cfg.train.overlap_update) and self.backend == "cpu"
        # overlap: the rollout acts with this copy (the policy as of the last finished update) while the
        # worker thread updates self.agent.model; `pending` is the rollout the next update consumes
        self.acting = dataclasses.replace(self.agent, model=copy.deepcopy(self.agent.model)) if self.overlap else None
        self.pending: Rollout | None = None
        rc = cfg.reward
        self.terminate = (
            LowStyleTermination(
                self.agent.disc, self.env.N, rc.low_style_threshold, rc.low_style_steps, cfg.disc.objective
            )
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
        self.env.max_steps = episode_limit_steps(self.cfg.env, self.agent.samples)
        return collect_rollout(actor, self.env, self.cfg.train.rollout_steps, terminate=self.terminate)

    def _rewards(self, ro: Rollout) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
        """Discriminator rewards and the total reward of `ro`, written into its storage with the returns
        and advantages (bootstrapped with the critic that acted)."""
        agent, env, cfg = self.agent, self.env, self.cfg
        rew = discriminator_rewards(agent, ro)
        reward = total_reward(agent, rew, ro.r_goal, ro.r_track) + ro.bootstrap
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
            "train/episode_limit": float(env.max_steps),
            "train/unstable_resets_total": float(agent.unstable_total),
            "train/falls": float(ro.falls),
            "train/style_terminations": float(ro.style_ends),
            "train/pose_terminations": float(ro.pose_ends),
            "train/unstable_rate": float(ro.unstable) / n,
            "sim/unstable_resets": float(ro.unstable),
        }
        if agent.conditional and hasattr(env, "fall_rate"):
            stats.update({f"fall_rate/{sk.name}": float(r) for sk, r in zip(agent.skills, env.fall_rate)})
        if agent.conditional:
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
    kind = "cGAIL" if learner.agent.conditional else "AMP"
    if cfg.reward.kind == "tracking":
        kind = f"tracking, {kind}"
    settings = RunnerSettings(
        total_samples=int(cfg.train.total_samples),
        checkpoint_every=int(cfg.train.checkpoint_every),
        keep_every=int(cfg.train.keep_checkpoint_every),
        log_every=int(cfg.train.log_every),
        description=f"cgail ({kind}, {learner.agent.num_skills} skills)",
    )
    return run_on_policy(learner, run, settings)
