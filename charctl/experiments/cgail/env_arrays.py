"""What differs between the cgail env's two array libraries: the simulator it reads, its random numbers and how
it selects rows. `env.CgailEnv` holds the rules once and calls one of these:

* `HostArrays` (env.backend=cpu, training's default and every evaluation): numpy arrays over C MuJoCo's
  `BatchedHumanoid`, numpy's `Generator`. A subset of the envs is its integer ids (`IndexRows`) and random
  numbers are drawn for those rows only, in the order the numpy env has always drawn them (so every seeded
  evaluation and test gives the numbers it gave).
* `TorchArrays` (env.backend=warp, and env.backend=torch: C MuJoCo seen as tensors): torch tensors on the
  simulator's device, a seeded torch generator. Every draw is made for all N envs whatever the subset (the
  generator's stream does not depend on the data, and nothing is read back to the host); the rows are a mask
  (`MaskRows`) on a GPU or, on the CPU where reading a mask is free, integer ids (`compact_rows`).

Units: radians (yaw about world +y), control steps, clip frames.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from charctl.experiments.cgail import start_frames
from charctl.experiments.cgail.env_rows import IndexRows, MaskRows, pad_clip_arrays, pad_skill_tables
from charctl.experiments.cgail.rules import skill_probabilities
from charctl.sim.batch import BatchedHumanoid, SimSettings


class HostArrays:
    """numpy over C MuJoCo (`charctl.sim.batch.BatchedHumanoid`), numpy's random generator."""

    on_device = False
    compact_rows = True  # a subset is always its ids
    bool_dtype = np.bool_
    float_dtype = np.float64  # the per-env bookkeeping (ramp weights, goals, heading errors)
    net_dtype = np.float64  # the policy state and disc obs (the rollout casts them for the networks)

    def __init__(self, sim, seed: int):
        self.sim = sim
        self.rng = np.random.default_rng(seed)
        self.device = "cpu"
        self.dtype = np.float64  # the simulator's, which the features and rules run in

    # arrays
    def array(self, values, dtype) -> np.ndarray:
        return np.asarray(values, dtype=dtype)

    def zeros(self, shape, dtype) -> np.ndarray:
        return np.zeros(shape, dtype=dtype)

    def tables(self, arrays: list[np.ndarray]) -> np.ndarray:
        """(K, longest, ...) per-skill clip arrays, each padded with its last row."""
        return pad_clip_arrays(arrays)

    def to_net(self, x: np.ndarray) -> np.ndarray:
        return x

    # rows and the simulator
    def rows(self, ids) -> IndexRows:
        """The subset `ids` ((n,) integer ids in the caller's order, or an (N,) bool mask)."""
        ids = np.asarray(ids)
        return IndexRows(np.flatnonzero(ids) if ids.dtype == bool else ids.astype(np.int64, copy=False))

    def draw_rows(self, mask: np.ndarray) -> IndexRows:
        """The rows a per-env draw is made for: the masked ones."""
        return IndexRows(np.flatnonzero(mask))

    def kinematics(self, rows: IndexRows | None = None):
        from charctl.experiments.cgail.features import sim_kinematics

        return sim_kinematics(self.sim, slice(None) if rows is None else rows.ids)

    def root_quat(self, rows: IndexRows) -> np.ndarray:
        """(n, 4) xyzw root orientations of `rows`."""
        return self.sim.body_quat_rows(rows.ids)[:, 0]

    # random numbers, per row of the subset
    def skills(self, n: int, K: int, fall_rate: np.ndarray, fall_weight: float) -> np.ndarray:
        """(n,) commands: uniform, or partly fall-weighted (env.skill_fall_weight)."""
        if fall_weight <= 0 or K < 2:
            return self.rng.integers(0, K, size=n)
        return self.rng.choice(K, size=n, p=skill_probabilities(fall_rate, fall_weight))

    def symmetric(self, rows: IndexRows, half_width: float) -> np.ndarray:
        """(n,) uniform in [-half_width, half_width)."""
        return self.rng.uniform(-half_width, half_width, size=len(rows.ids))

    def switches(self, env, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """((N,) bool the envs in `mask` that switch this step, (N,) their new commands)."""
        ids = np.flatnonzero(mask)
        ids = ids[self.rng.random(ids.size) < env.cfg.switch_prob]
        switch = np.zeros(env.N, dtype=bool)
        new = env.cmd.copy()
        if ids.size:
            switch[ids] = True
            new[ids] = env._sample_skills(ids.size)
        return switch, new

    def reset_draws(self, env, rows: IndexRows):
        """(skill, frame, yaw, goal offset), each (n,), for a reset of `rows`; None when there is none."""
        n = len(rows.ids)
        if n == 0:
            return None
        skill = env._sample_skills(n)
        if env.forced_command is not None:
            forced = np.asarray(env.forced_command)[rows.ids]
            skill = np.where(forced >= 0, forced, skill)
        if env.cfg.start_failure_weight > 0:  # a share drawn towards the frames where episodes end
            u = self.rng.random(n)
            frames = start_frames.draw_start_frames(
                env.frame_failures, env._lead, env.rsi_frames, env.cfg.start_failure_weight, skill, u
            )
        else:
            frames = np.empty(n, dtype=np.int64)
            for k in np.unique(skill):  # <= K groups, vectorised inside
                m = skill == k
                frames[m] = self.rng.integers(0, env.rsi_frames[k] - 1, size=int(m.sum()))
        if env.start_frame is not None:
            frames = np.minimum(int(env.start_frame), env.rsi_frames[skill] - 1)
        yaw = self.rng.uniform(-np.pi, np.pi, size=n) if env.random_yaw else np.zeros(n)
        goal = self.symmetric(rows, math.radians(env.cfg.goal_max_angle_deg))
        return skill, frames, yaw, goal

    def random_state(self) -> dict:
        return {"env_rng": self.rng.bit_generator.state}

    def set_random_state(self, state: dict) -> None:
        if "env_rng" in state:
            self.rng.bit_generator.state = state["env_rng"]


class TorchArrays:
    """torch tensors on the simulator's device (MuJoCo Warp, or C MuJoCo through `TorchBatchedHumanoid`), a
    seeded torch generator."""

    on_device = True
    bool_dtype = torch.bool
    float_dtype = torch.float32
    net_dtype = torch.float32

    def __init__(self, sim, seed: int):
        self.sim = sim
        self.device = dev = sim.device
        self.generator = torch.Generator(device=dev).manual_seed(int(seed))
        # the simulator's float dtype: float32 on MuJoCo Warp, float64 over C MuJoCo (env.backend=torch); features
        # and rules run in it, the policy state and disc obs are float32
        self.dtype = getattr(sim, "dtype", torch.float32)
        # on the CPU (reading a mask there is free) the work for a data-dependent subset of the envs runs on those
        # rows only: the resets and the closest-frame search of the pose error; on a GPU it stays in mask form
        self.compact_rows = dev.type == "cpu"

    # arrays
    def array(self, values, dtype) -> torch.Tensor:
        return torch.as_tensor(values, dtype=dtype, device=self.device)

    def zeros(self, shape, dtype) -> torch.Tensor:
        return torch.zeros(shape, dtype=dtype, device=self.device)

    def tables(self, arrays: list[np.ndarray]) -> torch.Tensor:
        return pad_skill_tables(arrays, self.device, self.dtype)

    def to_net(self, x: torch.Tensor) -> torch.Tensor:
        return x.float()

    # rows and the simulator
    def rows(self, ids) -> IndexRows | MaskRows:
        mask = self.sim.as_mask(ids)
        return IndexRows(torch.nonzero(mask).squeeze(1)) if self.compact_rows else MaskRows(mask)

    def draw_rows(self, mask: torch.Tensor) -> MaskRows:
        """The rows a per-env draw is written to: every env, by mask (the draws are made for all N)."""
        return MaskRows(mask)

    def kinematics(self, rows: IndexRows | MaskRows | None = None):
        from charctl.experiments.cgail.warp_kinematics import sim_kinematics

        return sim_kinematics(self.sim, rows.ids if isinstance(rows, IndexRows) else None)

    def root_quat(self, rows: IndexRows | MaskRows) -> torch.Tensor:
        return rows.pick(self.sim.body_quat_xyzw[:, 0])

    # random numbers: N per draw, then the subset's rows
    def _rand(self, n: int) -> torch.Tensor:
        return torch.rand(n, generator=self.generator, device=self.device, dtype=self.dtype)

    def skills(self, n: int, K: int, fall_rate: torch.Tensor, fall_weight: float) -> torch.Tensor:
        if fall_weight <= 0 or K < 2:
            return torch.floor(self._rand(n) * K).long().clamp(min=0)
        p = skill_probabilities(fall_rate, fall_weight)
        return torch.multinomial(p, n, replacement=True, generator=self.generator)

    def symmetric(self, rows: IndexRows | MaskRows, half_width: float) -> torch.Tensor:
        return rows.pick(self._symmetric_all(half_width))

    def _symmetric_all(self, half_width: float) -> torch.Tensor:
        """(N,) uniform in [-half_width, half_width), as (2u - 1) * half_width."""
        return (2.0 * self._rand(self.sim.num_envs) - 1.0) * half_width

    def switches(self, env, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        switch = mask & (self._rand(env.N) < env.cfg.switch_prob)
        return switch, env._sample_skills(env.N)

    def reset_draws(self, env, rows: IndexRows | MaskRows):
        """As `HostArrays.reset_draws`, every draw made for all N envs (the stream does not depend on the mask)."""
        N = env.N
        skill = env._sample_skills(N)
        if env.forced_command is not None:
            forced = torch.as_tensor(env.forced_command, device=self.device)
            skill = torch.where(forced >= 0, forced, skill)
        n_rsi = env.rsi_frames[skill]
        frames = torch.floor(self._rand(N) * (n_rsi - 1)).long().clamp(min=0)
        frames = torch.minimum(frames, n_rsi - 2).clamp(min=0)  # [0, T - 1) as numpy's integers
        if env.cfg.start_failure_weight > 0:  # a share drawn towards the frames where episodes end (start_frames.py)
            u = self._rand(N).double()
            frames = start_frames.draw_start_frames(
                env.frame_failures, env._lead, env.rsi_frames, env.cfg.start_failure_weight, skill, u
            )
        if env.start_frame is not None:
            frames = torch.minimum(torch.full_like(frames, int(env.start_frame)), n_rsi - 1)
        yaw = (2.0 * self._rand(N) - 1.0) * math.pi if env.random_yaw else self.zeros(N, self.dtype)
        goal = self._symmetric_all(math.radians(env.cfg.goal_max_angle_deg))
        if isinstance(rows, IndexRows) and rows.ids.numel() == 0:
            return None  # nothing to write (the mask form writes every row's old value back)
        return rows.pick(skill), rows.pick(frames), rows.pick(yaw), rows.pick(goal)

    def random_state(self) -> dict:
        return {"env_torch_rng": self.generator.get_state().cpu()}

    def set_random_state(self, state: dict) -> None:
        if "env_torch_rng" in state:
            self.generator.set_state(state["env_torch_rng"].cpu())


def simulator(env_cfg, device=None, sim=None):
    """The simulator an env runs on: `sim` when given, else C MuJoCo (no `device`) or MuJoCo Warp on `device`."""
    if sim is not None:
        return sim
    if device is None:
        return BatchedHumanoid(env_cfg.num_envs, SimSettings.of(env_cfg))
    from charctl.sim.warp_batch import WarpBatchedHumanoid

    return WarpBatchedHumanoid(int(env_cfg.num_envs), SimSettings.of(env_cfg), device=device)


def arrays_for(sim, seed: int) -> HostArrays | TorchArrays:
    """numpy for C MuJoCo's `BatchedHumanoid`, torch for a tensor simulator (MuJoCo Warp, `TorchBatchedHumanoid`)."""
    return HostArrays(sim, seed) if isinstance(sim, BatchedHumanoid) else TorchArrays(sim, seed)
