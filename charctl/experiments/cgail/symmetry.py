"""The humanoid's left/right mirror for the policy (ppo.mirror_loss; `charctl.rl.symmetry`).

The mirror is the reflection z -> -z of the heading frame (+x facing, y up, +z the character's right;
features.py), with every right_* body swapped for its left_* twin. Under it
- positions and linear velocities flip their z component;
- rotation matrices become M R M (M = diag(1, 1, -1)), so the 6-D features (the first two columns, x and y)
  flip their z components too; angular velocities are axial vectors, w -> -M w: x and y flip, z stays;
- a hinge angle about a parent axis x or y flips, about z it stays (M R_a(t) M = R_a(-t) for a in the mirror
  plane, R_z(t) for the normal z), so each ball joint's Euler chain mirrors hinge by hinge (the left and right
  chains share their order, humanoid.EULER_ORDER) and the knees and elbows (about z) keep their angle;
- the heading goal's (cos, sin) of a yaw about +y becomes (cos, -sin); the clip phase stays.
A skill's partner is the skill whose clip is its clip's mirror (`kick` and `kick:mirror`); only those pairs
are mirrored, since a clip that is not its own mirror frame by frame (a dance) has no mirrored command.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from charctl.errors import CharctlError
from charctl.motion.library import MIRROR_SUFFIX
from charctl.motion.skeleton import BODY_NAMES, END_EFFECTORS

if TYPE_CHECKING:
    from charctl.rl.symmetry import Mirror

FLIP_Z = (1.0, 1.0, -1.0)  # positions, linear velocities, rotation-matrix columns
FLIP_XY = (-1.0, -1.0, 1.0)  # angular velocities (axial vectors)


def twin(name: str) -> str:
    """The left/right twin of a body or joint name (itself for the centre line: root, chest, neck)."""
    for a, b in (("right_", "left_"), ("left_", "right_")):
        if name.startswith(a):
            return b + name[len(a) :]
    return name


def _block(bodies: list[str], width: int, sign: tuple[float, ...], offset: int) -> tuple[list[int], list[float]]:
    """Permutation and signs of `len(bodies)` consecutive `width`-wide rows starting at `offset`, each body
    taking its twin's values times `sign` (repeated over the width)."""
    perm, signs = [], []
    for b in bodies:
        j = bodies.index(twin(b))
        perm += [offset + j * width + k for k in range(width)]
        signs += [sign[k % len(sign)] for k in range(width)]
    return perm, signs


def state_mirror(phase: bool) -> tuple[np.ndarray, np.ndarray]:
    """(perm, sign) of the policy state (`rules.state_dim(phase)` wide; layout in features.policy_state, then
    the heading goal (2) and, with `phase`, the clip phase (2))."""
    bodies = list(BODY_NAMES)
    parts = [
        (["root"], 1, (1.0,)),  # root height
        (bodies[1:], 3, FLIP_Z),  # body positions relative to the root
        (bodies, 6, FLIP_Z),  # first two rotation-matrix columns
        (bodies, 3, FLIP_Z),  # linear velocities
        (bodies, 3, FLIP_XY),  # angular velocities
        (["com"], 3, FLIP_Z),  # COM relative to the root
        (["com_vel"], 3, FLIP_Z),
        (list(END_EFFECTORS), 3, FLIP_Z),
        (["goal"], 2, (1.0, -1.0)),  # (cos, sin) of the goal's relative yaw
    ]
    if phase:
        parts.append((["phase"], 2, (1.0, 1.0)))
    perm, sign, offset = [], [], 0
    for names, width, s in parts:
        p, g = _block(names, width, s, offset)
        perm += p
        sign += g
        offset += len(names) * width
    return np.asarray(perm, np.int64), np.asarray(sign, np.float32)


def action_mirror() -> tuple[np.ndarray, np.ndarray]:
    """(perm, sign) of the 28 PD-target actions (the actuated hinges in qpos order from index 7, with the
    shoulders' hinge chains in their parent's axes: env.shoulder_frame=parent)."""
    from charctl.sim.humanoid import EULER_ORDER, layout

    lay = layout()
    names = [None] * lay.nu
    for body in lay.joint_bodies:
        sl = lay.qpos_slices[body]
        axes = EULER_ORDER.get(body, "Z")  # knees and elbows: one hinge about z
        for k, axis in enumerate(axes):
            names[sl.start - 7 + k] = (body, axis)
    perm = [names.index((twin(b), axis)) for b, axis in names]
    sign = [1.0 if axis == "Z" else -1.0 for _, axis in names]
    return np.asarray(perm, np.int64), np.asarray(sign, np.float32)


def command_mirror(clips: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(perm (K,), paired (K,) bool) of the skills whose clips are `clips`: a skill's partner is the skill
    whose clip is its clip with ':mirror' added or removed; a skill without one maps to itself, unpaired."""

    def mirrored(c: str) -> str:
        return c[: -len(MIRROR_SUFFIX)] if c.endswith(MIRROR_SUFFIX) else c + MIRROR_SUFFIX

    perm = [clips.index(mirrored(c)) if mirrored(c) in clips else k for k, c in enumerate(clips)]
    paired = [p != k for k, p in enumerate(perm)]
    return np.asarray(perm, np.int64), np.asarray(paired, bool)


def mirror_problem(clips: list[str], conditional: bool, shoulder_frame: str) -> str | None:
    """Why ppo.mirror_loss cannot apply to these skills and settings (a one-line message), or None."""
    if not conditional:
        return "ppo.mirror_loss needs cgail.conditional=true (the mirror swaps commands of mirrored clips)"
    if shoulder_frame != "parent":
        return "ppo.mirror_loss needs env.shoulder_frame=parent (the rotated shoulder chains are not mirror images)"
    if not command_mirror(clips)[1].any():
        return (
            "ppo.mirror_loss needs two skills whose clips mirror each other (e.g. kick and kick:mirror); "
            f"the selected clips are {clips}"
        )
    return None


def policy_mirror(cfg, skills: list) -> Mirror:
    """The mirror of the policy of a run with config `cfg` and `skills` (`SkillData`, with their clip names)."""
    from charctl.experiments.cgail.rules import phase_in_state

    clips = [s.clip_name for s in skills]
    return build_mirror(clips, bool(cfg.cgail.conditional), cfg.env.shoulder_frame, phase_in_state(cfg))


def build_mirror(clips: list[str], conditional: bool, shoulder_frame: str, phase: bool) -> Mirror:
    """The policy's mirror for skills with these `clips` (raises CharctlError where `mirror_problem` says)."""
    from charctl.rl.symmetry import Mirror

    if (msg := mirror_problem(clips, conditional, shoulder_frame)) is not None:
        raise CharctlError(msg)
    return Mirror(*state_mirror(phase), *command_mirror(clips), *action_mirror())
