"""Load a trained cgail run and roll its policy out (evaluation, export, play, push tests)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from charctl.errors import CharctlError
from charctl.experiments.cgail.agent import Agent, build_agent, load_policy_state
from charctl.experiments.cgail.config import method_label
from charctl.experiments.cgail.drive import mean_action
from charctl.experiments.cgail.env import EVALUATION_STARTS, CgailEnv
from charctl.motion import rotations as R


@dataclass
class TrainedRun:
    run_dir: Path
    cfg: object
    agent: Agent

    @property
    def skill_names(self) -> list[str]:
        return [s.name for s in self.agent.skills]

    @property
    def label(self) -> str:
        return method_label(self.cfg)

    def skill_index(self, name: str) -> int:
        if name not in self.skill_names:
            raise CharctlError(
                f"unknown skill {name!r} for {self.run_dir}; its skills are {', '.join(self.skill_names)}"
            )
        return self.skill_names.index(name)

    def make_env(self, num_envs: int, seed: int = 0, rules: dict | None = None, **env_overrides) -> CgailEnv:
        """A CPU env of the run's skills and `env` config (`env_overrides` replacing keys). Evaluation passes no
        `rules` and judges a policy by its falls only; a diagnostic that replays the training rules passes
        `env_rules.env_rules(cfg.reward, ...)`."""
        from omegaconf import OmegaConf

        evaluation = EVALUATION_STARTS if rules is None else {}
        env_cfg = OmegaConf.merge(self.cfg.env, {"num_envs": num_envs, **evaluation, **env_overrides})
        rules = {"tracking": self.cfg.reward.kind == "tracking"} if rules is None else rules
        return CgailEnv(self.agent.skills, env_cfg, seed=seed, conditional=self.agent.conditional, **rules)

    def held_env(
        self, commands, episode_seconds: float, seed: int = 0, rules: dict | None = None, **env_overrides
    ) -> CgailEnv:
        """A `make_env` of one env per entry of `commands` (skill indices), each commanded with its skill and held
        (no random switches; the caller may still switch), reset at its clip's frame 0 with the clip's heading (no
        random yaw): how the evaluations, the export and the diagnostics start a skill. `episode_seconds` the
        episode limit (s); `rules` and `env_overrides` as `make_env`."""
        commands = np.asarray(commands, dtype=np.int64).reshape(-1)
        overrides = {"switch_prob": 0.0, "episode_seconds": episode_seconds, **env_overrides}
        env = self.make_env(len(commands), seed=seed, rules=rules, **overrides)
        env.forced_command = commands
        env.start_frame = 0
        env.random_yaw = False
        env.reset(np.arange(len(commands)))
        return env

    def mean_action(self, env: CgailEnv) -> np.ndarray:
        """(N, 28) mean actions of the policy on the env's current state (`drive.mean_action`), float64."""
        return mean_action(self.agent, env)


def load_trained_run(run_dir: str | Path, checkpoint: str | None = None) -> TrainedRun:
    """Rebuild the agent of a cgail run directory and load a checkpoint of RUN/checkpoints/ (weights_only):
    `checkpoint` (a file name, e.g. samples_020000000.pt from train.keep_checkpoint_every) or last.pt.
    Only what inference needs is built and loaded: the policy, the discriminator and the skills (no
    optimisers, demonstration pairs or replay buffer)."""
    from charctl.checkpoints import checkpoint_file_name
    from charctl.experiments.cgail.config import Config
    from charctl.runs import open_run, run_experiment

    run_dir = Path(run_dir)
    exp = run_experiment(run_dir)
    if exp != "cgail":
        raise CharctlError(f"{run_dir} is a {exp!r} run, not a cgail run")
    run = open_run(run_dir, Config)
    torch.set_num_threads(max(1, int(run.cfg.train.torch_threads)))
    agent = build_agent(run.cfg, training=False)
    load_policy_state(agent, run.load_checkpoint(agent.signature(), name=checkpoint_file_name(checkpoint)))
    agent.model.eval()
    agent.disc.eval()
    return TrainedRun(run_dir, run.cfg, agent)


def resolve_run_dirs(targets: list[str], overrides: list[str], command: str) -> list[Path]:
    """Run directories from `targets`; 'cgail' stands for the latest run under the configured
    output_root. `output_root=DIR` is the only override eval/export take (runs keep their config)."""
    from charctl.experiments import latest_run_dir

    other = [o for o in overrides if o.split("=", 1)[0] != "output_root"]
    if other:
        raise CharctlError(f"cgail {command} takes no config overrides (got {' '.join(other)})")
    return [latest_run_dir("cgail", overrides) if t == "cgail" else Path(t) for t in targets]


def local_joint_rotations(env: CgailEnv) -> np.ndarray:
    """(N, 15, 4) local rotations of the simulated characters (body 0: root world rotation)."""
    from charctl.motion.skeleton import load_skeleton

    skel = load_skeleton()
    world = env.sim.body_quat_xyzw
    local = world.copy()
    local[:, 1:] = R.multiply(R.conjugate(world[:, skel.parents[1:]]), world[:, 1:])
    return local
