"""The cgail agent: its networks and (for training) optimisers, demonstrations and replay buffer, built
from a config, and the checkpoint state they save and load.

`build_agent(cfg, training=False)` builds only what inference needs (policy, discriminator, skills) and
`load_policy_state` loads a checkpoint into it: evaluation, export and play (policy.py) use these and
never import the training modules (train.py, rollout.py, disc_update.py).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import torch

from charctl.experiments.cgail.discriminator import Discriminator, ReplayBuffer
from charctl.experiments.cgail.env import CgailEnv
from charctl.experiments.cgail.skills import DemoPairs, load_skills, select_skills
from charctl.rl.ppo import PPO, ActorCritic, make_adam


@dataclass
class Agent:
    """Everything a checkpoint holds, built from a config. An inference agent
    (`build_agent(training=False)`) has the networks and skills only: its training state is None."""

    cfg: object
    skills: list
    model: ActorCritic
    disc: Discriminator
    ppo: PPO | None = None
    disc_opt: torch.optim.Optimizer | None = None
    demos: DemoPairs | None = None
    replay: ReplayBuffer | None = None
    generator: torch.Generator | None = None
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

    @property
    def training(self) -> bool:
        """True when the agent holds its training state (optimisers, demonstrations, replay buffer)."""
        return self.ppo is not None

    def signature(self) -> dict:
        return {
            "skills": ",".join(s.name for s in self.skills),
            "conditional": self.conditional,
            "reward": str(self.cfg.reward.kind),
            "policy_hidden": list(self.cfg.ppo.hidden),
            "disc_hidden": list(self.cfg.disc.hidden),
        }


def build_agent(cfg, device: str = "cpu", training: bool = True) -> Agent:
    """Networks, optimisers, demonstration data and replay buffer for `cfg` (seeded), on torch `device`.

    Off the CPU (device=cuda) the demonstration pairs also move to the device and are drawn there
    (`DemoPairs.sample_torch`); on the CPU everything is as it always was (numpy draws).
    `training=False`: the policy, the discriminator and the skills only (no optimiser, demonstration
    pairs or replay buffer), for loading a checkpoint with `load_policy_state`; the networks are built
    from the same seed in the same order, so the global torch generator ends in the same state."""
    from charctl.experiments.cgail.features import DISC_OBS_DIM
    from charctl.experiments.cgail.rules import phase_in_state
    from charctl.experiments.cgail.rules import state_dim as policy_state_width

    torch.manual_seed(cfg.seed)
    skills = load_skills(select_skills(cfg), cfg.env.control_hz, cfg.env.shoulder_frame)
    K = len(skills)
    conditional = bool(cfg.cgail.conditional)
    state_dim = policy_state_width(phase_in_state(cfg))
    model = ActorCritic(state_dim, 28, cfg.ppo, cond_dim=K if conditional else 0).to(device)
    if not training:
        disc = _discriminator(cfg, 2 * DISC_OBS_DIM, K).to(device)  # its normaliser comes from the checkpoint
        return Agent(cfg, skills, model, disc, device=str(device))
    gen = torch.Generator().manual_seed(cfg.seed)
    ppo = PPO(model, cfg.ppo, generator=gen, mirror=_mirror(cfg, skills))
    disc = _discriminator(cfg, 2 * DISC_OBS_DIM, K)
    demos = DemoPairs(skills)
    pairs, _ = demos.all()
    with torch.no_grad():
        disc.norm.update(torch.from_numpy(pairs))  # normalise with demonstration statistics (frozen)
    disc = disc.to(device)
    disc_opt = make_adam(discriminator_param_groups(disc, cfg.disc), lr=cfg.disc.lr)
    replay = ReplayBuffer(cfg.disc.replay_size, 2 * DISC_OBS_DIM, K, device=device)
    agent = Agent(cfg, skills, model, disc, ppo, disc_opt, demos, replay, gen, device=str(device))
    if torch.device(device).type != "cpu":
        demos.to_device(device)
        agent.device_generator = torch.Generator(device=device).manual_seed(int(cfg.seed) + 104729)
    return agent


def _mirror(cfg, skills: list):
    """The policy's left/right mirror for ppo.mirror_loss (`symmetry.policy_mirror`), or None when it is off."""
    if cfg.ppo.mirror_loss <= 0:
        return None
    from charctl.experiments.cgail.symmetry import policy_mirror

    return policy_mirror(cfg, skills)


def _discriminator(cfg, pair_dim: int, num_skills: int) -> Discriminator:
    """The discriminator of `cfg` on the CPU, its normaliser untouched."""
    return Discriminator(
        pair_dim,
        num_skills,
        list(cfg.disc.hidden),
        conditional=bool(cfg.cgail.conditional),
        style_head=cfg.disc.style_head,
    )


def discriminator_param_groups(disc: Discriminator, dcfg) -> list[dict]:
    """Adam parameter groups: the class head at `class_lr` (when set), everything else at `lr`."""
    head = [p for n, p in disc.named_parameters() if n.startswith("class_head.")]
    rest = [p for n, p in disc.named_parameters() if not n.startswith("class_head.")]
    groups = [{"params": rest, "lr": dcfg.lr}]
    if head:
        groups.append({"params": head, "lr": dcfg.class_lr if dcfg.class_lr > 0 else dcfg.lr})
    return groups


def agent_state(agent: Agent, env: CgailEnv | None = None) -> dict:
    """Checkpoint state of a training agent (and the random-number state of `env`, when given)."""
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
    if env is not None:  # numpy's generator ("env_rng") or the torch env's ("env_torch_rng")
        state.update(env.arrays.random_state())
    return state


def load_agent_state(agent: Agent, state: dict, env: CgailEnv | None = None) -> None:
    """Load `agent_state` output into a training agent (and `env`'s random-number state, when given)."""
    if not agent.training:
        raise ValueError("load_agent_state needs a training agent; load an inference agent with load_policy_state")
    if state.get("inference_only"):  # scripts/package_pretrained.py --inference-only: no optimiser states
        print("note: this checkpoint was packaged without optimiser states; PPO's and the discriminator's start fresh")
        agent.model.load_state_dict(state["ppo"]["model"])
        agent.disc.load_state_dict(state["disc"])
    else:
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
    if env is not None:
        env.arrays.set_random_state(state)


def load_policy_state(agent: Agent, state: dict) -> None:
    """Load the networks and counters of a checkpoint (`agent_state` output) into an agent of any kind,
    leaving the training state (optimisers, replay buffer, generators) alone: what inference needs."""
    agent.model.load_state_dict(state["ppo"]["model"])
    agent.disc.load_state_dict(state["disc"])
    agent.iteration, agent.samples = int(state["iteration"]), int(state["samples"])
    agent.unstable_total = int(state.get("unstable_total", 0))
