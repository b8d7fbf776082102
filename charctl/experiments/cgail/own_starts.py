"""Starts from the policy's own states (env.own_start_weight; docs/cgail.md "Starts from the policy's own states").

RSI (the paper, DeepMimic) starts every episode in a clip pose. A policy trained that way can begin a non-looping
skill only from close to its clip's first frame: the ten-skill kicks and seed 2's kick start from the clip's frame
0 but not from the guard the policy itself holds after a pass or after a walk -> kick command ramp, and those
episodes end by the pose check ~0.6 s later (docs/cgail.md "It kicks once", "Run H at a second seed"), so the
transition is never trained past its first half second. Here the env keeps the physics states (qpos, qvel) at
which a timed reference restarted at frame 0 -- a non-looping clip's next pass, or the end of a command ramp
into a skill without a heading goal -- in a ring of the newest `capacity`, and starts a share of the episodes of
that skill from one of them, with its reference at frame 0 and the grace steps a restart gets. The skill of
each start is drawn as before (uniform or fall-weighted), so the skills' shares do not change.

numpy only (env.backend=cpu); the ring is not checkpointed (it refills within a few hundred control steps).
Units: qpos / qvel as MuJoCo's (m, rad, m/s, rad/s; the root's linear velocity in the world frame).
"""

from __future__ import annotations

import numpy as np


class OwnStarts:
    """A ring of the newest `capacity` restart states, each with its skill."""

    def __init__(self, capacity: int, nq: int, nv: int):
        self.qpos = np.zeros((capacity, nq))
        self.qvel = np.zeros((capacity, nv))
        self.skill = np.full(capacity, -1, dtype=np.int64)  # -1: empty slot
        self.written = 0  # states kept so far (the next slot is written % capacity)

    @property
    def capacity(self) -> int:
        return len(self.skill)

    def keep(self, qpos: np.ndarray, qvel: np.ndarray, skill: np.ndarray) -> None:
        """Add (n, nq) `qpos`, (n, nv) `qvel` of skills (n,) `skill`, the newest replacing the oldest."""
        n = len(skill)
        if n == 0:
            return
        if n > self.capacity:  # only the newest fit
            qpos, qvel, skill = qpos[-self.capacity :], qvel[-self.capacity :], skill[-self.capacity :]
            self.written += n - self.capacity
            n = self.capacity
        slots = (self.written + np.arange(n)) % self.capacity
        self.qpos[slots], self.qvel[slots], self.skill[slots] = qpos, qvel, skill
        self.written += n

    def draw(self, rng: np.random.Generator, skill: np.ndarray, weight: float) -> tuple[np.ndarray, np.ndarray]:
        """For starts of skills (n,) `skill`: ((n,) bool which start from a kept state, (m,) their ring slots).
        Each start takes a kept state of its own skill with probability `weight` where the ring holds one."""
        own = (rng.random(len(skill)) < weight) & np.isin(skill, self.skill)
        slots = np.empty(int(own.sum()), dtype=np.int64)
        chosen = skill[own]
        for k in np.unique(chosen):  # <= K groups, vectorised inside
            mine = np.flatnonzero(self.skill == k)
            m = chosen == k
            slots[m] = mine[rng.integers(0, len(mine), size=int(m.sum()))]
        return own, slots


def restarted_here(ref_grace: np.ndarray, ref_active: np.ndarray, grace: int) -> np.ndarray:
    """(N,) bool: the envs whose timed reference restarted at frame 0 in this control step, read from the grace
    counter after `rules.count_down_grace` and `rules.restart_after_ramp` (both set it to `grace` exactly there;
    every other env's is below `grace`). Needs `grace` > 0."""
    return ref_active & (ref_grace == grace)
