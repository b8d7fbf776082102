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

One code path for numpy (env.backend=cpu) and torch (env.backend=torch / warp, on the simulator's device): the
ring is arrays of the env's library, written and read with whole-batch operations and masks (no host round trip
on a GPU); the random numbers come from the env's generator (`env_arrays`). The ring is not checkpointed (it
refills within a few hundred control steps). Units: qpos / qvel as MuJoCo's (m, rad, m/s, rad/s; the root's
linear velocity in the world frame).
"""

from __future__ import annotations

from charctl.motion.array_compat import Array, namespace


class OwnStarts:
    """A ring of the newest `capacity` restart states, each with its skill, in the arrays `zeros` makes (numpy's
    or torch's on a device). Row `capacity` is scratch: the rows a write does not keep go there."""

    def __init__(self, capacity: int, nq: int, nv: int, num_skills: int, zeros, dtype, index_dtype):
        """`zeros(shape, dtype)` makes the ring's arrays (`env_arrays.HostArrays.zeros` / `TorchArrays.zeros`);
        `dtype` the simulator's float dtype, `index_dtype` the library's int64; skills are 0 .. `num_skills` - 1."""
        self.capacity, self.num_skills = int(capacity), int(num_skills)
        self.qpos = zeros((capacity + 1, nq), dtype)
        self.qvel = zeros((capacity + 1, nv), dtype)
        self.skill = zeros(capacity + 1, index_dtype) - 1  # -1: empty slot
        self.written = zeros((), index_dtype)  # states kept so far (the next slot is written % capacity)

    def keep(self, qpos: Array, qvel: Array, skill: Array, fresh: Array) -> None:
        """Keep the rows `fresh` ((N,) bool) of (N, nq) `qpos`, (N, nv) `qvel`, (N,) `skill`, in row order after
        the ring's newest; where more than `capacity` are fresh only the last `capacity` of them are kept."""
        xp = namespace(skill)
        ones = xp.astype(fresh, self.written.dtype)
        order = xp.cumulative_sum(ones) - 1  # each fresh row's place among this write's
        n = xp.sum(ones)
        kept = fresh & (order >= n - self.capacity)
        slot = xp.where(kept, (self.written + order) % self.capacity, self.capacity)  # the rest to scratch
        self.qpos[slot], self.qvel[slot], self.skill[slot] = qpos, qvel, skill
        self.skill[self.capacity] = -1
        self.written = self.written + n

    def draw(self, skill: Array, u_own: Array, u_slot: Array, weight: float | Array) -> tuple[Array, Array]:
        """For starts of skills (n,) `skill` with uniforms in [0, 1) (n,) `u_own`, `u_slot`: ((n,) bool which
        start from a kept state, (n,) their ring slots, meaningful where the first is set). A start takes a kept
        state of its own skill with probability `weight` (one for all, or (n,) per start) where the ring holds
        one, each of them equally likely:
        the `floor(u_slot * count)`-th kept state of that skill in slot order."""
        xp = namespace(skill)
        K = self.num_skills
        labels = xp.arange(K, dtype=skill.dtype)
        counts = xp.sum(xp.astype(self.skill[:, None] == labels[None, :], skill.dtype), axis=0)  # (K,)
        first = xp.cumulative_sum(counts) - counts  # where skill k's slots begin in sorted order
        key = xp.where(self.skill >= 0, self.skill, K)  # empty slots (and scratch) last
        by_skill = xp.argsort(key, stable=True)
        count = xp.take(counts, skill)
        pick = xp.astype(xp.floor(u_slot * xp.astype(count, u_slot.dtype)), skill.dtype)
        place = xp.take(first, skill) + xp.clip(xp.minimum(pick, count - 1), 0, None)
        slots = xp.take(by_skill, xp.clip(place, 0, self.capacity - 1))
        return (u_own < weight) & (count > 0), slots


def restarted_here(ref_grace: Array, ref_active: Array, grace: int) -> Array:
    """(N,) bool: the envs whose timed reference restarted at frame 0 in this control step, read from the grace
    counter after `rules.count_down_grace` and `rules.restart_after_ramp` (both set it to `grace` exactly there;
    every other env's is below `grace`). Needs `grace` > 0."""
    return ref_active & (ref_grace == grace)
