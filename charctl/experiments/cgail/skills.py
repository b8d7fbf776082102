"""Reference data of the commandable skills: clips at the control rate, RSI states, and the
discriminator's data pairs (o_t, o_t+1) with their class labels."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from charctl.experiments.cgail.features import clip_kinematics, disc_obs
from charctl.motion.library import load_clip
from charctl.sim.humanoid import clip_to_qpos_qvel


@dataclass
class SkillData:
    """Per-skill arrays at the control rate."""

    name: str
    clip_name: str
    heading_goal: bool
    qpos: np.ndarray  # (T, nq) RSI states (root x/z moved to the origin at reset)
    qvel: np.ndarray  # (T, nv)
    obs: np.ndarray  # (T, 133) disc observations
    loop: bool
    mean_speed: float  # m/s planar root speed over the clip (target speed of the heading goal)
    local_rot: np.ndarray  # (T, 15, 4) for pose-error evaluation
    fps: float


def load_skills(skills, control_hz: float, shoulder_frame: str = "parent") -> list[SkillData]:
    """Load and resample every skill's clip to `control_hz`; qpos/qvel for the model built with `shoulder_frame`."""
    out = []
    for s in skills:
        clip = load_clip(s.clip).resample(control_hz)
        qpos, qvel = clip_to_qpos_qvel(clip, shoulder_frame)
        obs = disc_obs(clip_kinematics(clip))
        planar = np.linalg.norm(np.diff(clip.root_pos[:, [0, 2]], axis=0), axis=1).sum()
        out.append(
            SkillData(
                s.name,
                s.clip,
                bool(s.heading_goal),
                qpos,
                qvel,
                obs,
                clip.loop,
                float(planar / max(clip.duration, 1e-9)),
                clip.local_rot,
                clip.fps,
            )
        )
    return out


def preflight(cfg) -> None:
    """`charctl train`'s check before the run directory is made: the clip of every selected skill loads
    (`load_skills` loads and resamples them again)."""
    for s in select_skills(cfg):
        load_clip(s.clip)


def select_skills(cfg):
    """The configured skills, restricted to `use_skills` when given (order kept)."""
    if not cfg.use_skills:
        return list(cfg.skills)
    return [s for s in cfg.skills if s.name in set(cfg.use_skills)]


def _pairs(skill: SkillData) -> np.ndarray:
    """(o(t), o(t + 1/control_hz)) pairs at the clip's frames."""
    return np.concatenate([skill.obs[:-1], skill.obs[1:]], axis=1).astype(np.float32)


class DemoPairs:
    """All (o_t, o_t+1) pairs of the skill clips; sampling is balanced over skills."""

    def __init__(self, skills: list[SkillData]):
        self.pairs = [_pairs(s) for s in skills]
        self.labels = [np.full(len(p), k, dtype=np.int64) for k, p in enumerate(self.pairs)]
        self.num_skills = len(skills)

    def all(self) -> tuple[np.ndarray, np.ndarray]:
        return np.concatenate(self.pairs), np.concatenate(self.labels)

    def to_device(self, device) -> None:
        """Copy the pairs to torch `device` as one padded (K, max_pairs, 266) table for `sample_torch`."""
        import torch

        longest = max(len(p) for p in self.pairs)
        table = np.zeros((self.num_skills, longest, self.pairs[0].shape[1]), dtype=np.float32)
        for k, p in enumerate(self.pairs):
            table[k, : len(p)] = p
        self._table = torch.as_tensor(table, device=device)
        self._counts = torch.as_tensor([len(p) for p in self.pairs], dtype=torch.long, device=device)

    def sample_torch(self, n: int, generator):
        """`sample` on the device (after `to_device`): n pairs, skill uniform, then pair uniform within the
        skill, drawn with the torch `generator` (on the same device). Returns (pairs (n, 266), labels (n,))."""
        import torch

        dev = self._table.device
        k = torch.randint(0, self.num_skills, (n,), generator=generator, device=dev)
        u = torch.rand(n, generator=generator, device=dev)
        j = torch.minimum((u * self._counts[k]).long(), self._counts[k] - 1)
        return self._table[k, j], k

    def sample(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """n pairs: skill uniform, then frame uniform within the skill. Returns (pairs, labels)."""
        k = rng.integers(0, self.num_skills, size=n)
        out = np.empty((n, self.pairs[0].shape[1]), dtype=np.float32)
        for s in range(self.num_skills):  # loop over skills (<= 10), vectorised over samples
            m = k == s
            if m.any():
                out[m] = self.pairs[s][rng.integers(0, len(self.pairs[s]), size=int(m.sum()))]
        return out, k
