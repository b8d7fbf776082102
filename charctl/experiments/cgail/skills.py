"""Reference data of the commandable skills: clips at the control rate, RSI states, and the
discriminator's data pairs (o_t, o_t+1) with their class labels."""

from __future__ import annotations

import dataclasses
from collections.abc import Collection
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
    # frames of the clip itself: T less the return appended by env.clip_return_seconds (T without one)
    clip_frames: int
    # with a return: the clip's own (clip_frames, nv) / (clip_frames, 133) velocities and observations (its last
    # frame's finite differences differ from those of qvel / obs, which run on into the return); None without one
    own_qvel: np.ndarray | None = None
    own_obs: np.ndarray | None = None

    def clip_only(self) -> SkillData:
        """This skill's arrays as the clip alone (without env.clip_return_seconds' return): what the evaluations
        compare a policy with. The env's reference, RSI and demonstrations use all T frames."""
        n = self.clip_frames
        qvel = self.qvel[:n] if self.own_qvel is None else self.own_qvel
        obs = self.obs[:n] if self.own_obs is None else self.own_obs
        return dataclasses.replace(
            self, qpos=self.qpos[:n], qvel=qvel, obs=obs, local_rot=self.local_rot[:n], own_qvel=None, own_obs=None
        )


def load_skills(
    skills,
    control_hz: float,
    shoulder_frame: str = "parent",
    return_seconds: float = 0.0,
    returning: Collection[str] | None = None,
) -> list[SkillData]:
    """Load and resample every skill's clip to `control_hz`; qpos/qvel for the model built with `shoulder_frame`.
    `return_seconds` > 0 appends to each non-looping clip that long a blend back to its first pose
    (`Clip.with_return`, env.clip_return_seconds), rounded to control frames; with `returning`, only to the
    skills named in it (env.clip_return_after_coverage)."""
    out = []
    for s in skills:
        clip = load_clip(s.clip).resample(control_hz)
        seconds = return_seconds if returning is None or s.name in returning else 0.0
        reference = clip.with_return(int(round(seconds * control_hz)))
        qpos, qvel = clip_to_qpos_qvel(reference, shoulder_frame)
        obs = disc_obs(clip_kinematics(reference))
        planar = np.linalg.norm(np.diff(clip.root_pos[:, [0, 2]], axis=0), axis=1).sum()
        own_qvel = own_obs = None
        if reference is not clip:  # a return appended: the clip's own velocities for `SkillData.clip_only`
            own_qvel = clip_to_qpos_qvel(clip, shoulder_frame)[1]
            own_obs = disc_obs(clip_kinematics(clip))
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
                reference.local_rot,
                clip.fps,
                clip.num_frames,
                own_qvel,
                own_obs,
            )
        )
    return out


def returning_after(
    coverage: dict[str, float], skills: list[SkillData], gate: float, returning: Collection[str]
) -> tuple[str, ...]:
    """env.clip_return_after_coverage: the skills with a way back after a training fidelity check, `coverage` per
    skill name (fidelity/<skill>/coverage): those that had one, and each non-looping skill whose coverage reached
    `gate` (a skill once switched on stays on)."""
    return tuple(s.name for s in skills if s.name in returning or (not s.loop and coverage.get(s.name, 0.0) >= gate))


def switch_prob_for(env_cfg, skills: list[SkillData], returning: Collection[str]) -> float:
    """The per-step command switch probability of a training env: env.switch_prob_after_returns once every
    non-looping skill of `skills` is in `returning` (and that knob is set), env.switch_prob otherwise."""
    after = float(env_cfg.switch_prob_after_returns)
    on = all(s.loop or s.name in returning for s in skills) and any(not s.loop for s in skills)
    return after if after > 0 and on else float(env_cfg.switch_prob)


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
