"""A motion clip of the DeepMimic humanoid and the operations every experiment needs.

A `Clip` holds uniformly sampled frames: root position (world, metres, y-up) and the local
rotation of all 15 bodies (xyzw; body 0 is the root's world rotation, the wrists are fixed so
always identity, knees/elbows are rotations about their z axis). Everything is vectorised over
frames.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from charctl.motion import rotations as R
from charctl.motion.fk import center_of_mass, forward_kinematics
from charctl.motion.skeleton import Skeleton, load_skeleton


@dataclass(frozen=True, eq=False)
class Clip:
    """Uniformly sampled motion. T frames at `fps`; duration = (T - 1) / fps seconds."""

    name: str
    fps: float
    root_pos: np.ndarray  # (T, 3) world, metres
    local_rot: np.ndarray  # (T, B, 4) xyzw
    loop: bool = False
    label: str = ""
    source: str = ""
    skeleton: Skeleton = dataclasses.field(default_factory=load_skeleton, repr=False)

    # ------------------------------------------------------------------ basic facts
    @property
    def num_frames(self) -> int:
        return self.root_pos.shape[0]

    @property
    def dt(self) -> float:
        return 1.0 / self.fps

    @property
    def duration(self) -> float:
        return (self.num_frames - 1) / self.fps

    @property
    def times(self) -> np.ndarray:
        return np.arange(self.num_frames) / self.fps

    def replace(self, **changes) -> Clip:
        return dataclasses.replace(self, **changes)

    # ------------------------------------------------------------------ kinematics
    @functools.cached_property
    def fk(self) -> tuple[np.ndarray, np.ndarray]:
        """World body positions (T, B, 3) and rotations (T, B, 4)."""
        return forward_kinematics(self.skeleton, self.root_pos, self.local_rot)

    @property
    def body_pos(self) -> np.ndarray:
        return self.fk[0]

    @property
    def body_rot(self) -> np.ndarray:
        return self.fk[1]

    def com(self, masses: np.ndarray | None = None) -> np.ndarray:
        """Centre of mass per frame (T, 3); `masses` (B,) overrides the model masses."""
        return center_of_mass(self.skeleton, *self.fk, masses=masses)

    def heading(self) -> np.ndarray:
        """Heading angle (T,) radians about +y of the root's forward (+x) axis."""
        return R.yaw_about_y(self.local_rot[:, 0])

    # ------------------------------------------------------------------ velocities
    def root_linear_velocity(self) -> np.ndarray:
        """(T, 3) world-frame root velocity, m/s, by finite differences."""
        return finite_difference(self.root_pos, self.dt)

    def body_linear_velocity(self) -> np.ndarray:
        """(T, B, 3) world-frame body-frame-origin velocities, m/s."""
        return finite_difference(self.body_pos, self.dt)

    def local_angular_velocity(self) -> np.ndarray:
        """(T, B, 3) angular velocity of each local rotation, rad/s, expressed in the child frame.

        Index 0 is the root's angular velocity in the root body frame (MuJoCo's free-joint
        convention); others are joint velocities in the joint (child) frame.
        """
        q = self.local_rot
        fwd = R.log_map(R.multiply(R.conjugate(q[:-1]), q[1:])) * self.fps  # (T-1, B, 3)
        return _pad_differences(fwd)

    def world_angular_velocity(self) -> np.ndarray:
        """(T, B, 3) world-frame angular velocity of each body, rad/s."""
        q = self.body_rot
        fwd = R.log_map(R.multiply(q[1:], R.conjugate(q[:-1]))) * self.fps
        return _pad_differences(fwd)

    # ------------------------------------------------------------------ transforms
    def resample(self, fps: float) -> Clip:
        """Resample to `fps` (positions linear, rotations slerp); duration and end poses kept.

        The new frame count is round(duration * fps) + 1 and the last frame lands exactly on
        the clip's last frame, so the effective rate is within one frame of `fps`.
        """
        n_new = max(2, int(round(self.duration * fps)) + 1)
        src = np.linspace(0.0, self.num_frames - 1, n_new)
        i0 = np.clip(np.floor(src).astype(int), 0, self.num_frames - 2)
        w = src - i0
        pos = (1 - w)[:, None] * self.root_pos[i0] + w[:, None] * self.root_pos[i0 + 1]
        rot = R.slerp(
            self.local_rot[i0], self.local_rot[i0 + 1], np.broadcast_to(w[:, None], (n_new, self.skeleton.num_bodies))
        )
        new_fps = (n_new - 1) / self.duration if self.duration > 0 else fps
        return self.replace(fps=new_fps, root_pos=pos, local_rot=rot)

    def mirror(self) -> Clip:
        """Left/right mirror through the character's sagittal plane (world z -> -z)."""
        perm = self.skeleton.mirror_perm
        pos = self.root_pos * np.array([1.0, 1.0, -1.0])
        rot = R.mirror_z(self.local_rot[:, perm])
        name = self.name[:-7] if self.name.endswith(":mirror") else self.name + ":mirror"
        return self.replace(name=name, root_pos=pos, local_rot=rot)

    def slice(self, start: int, stop: int) -> Clip:
        return self.replace(root_pos=self.root_pos[start:stop], local_rot=self.local_rot[start:stop], loop=False)

    def canonicalize(self, frame: int = 0, facing: str = "+x") -> Clip:
        """Move frame `frame`'s root to the origin on the ground plane and turn it to face `facing`.

        `facing` is "+x" (DeepMimic) or "+z" (com-cnn's convention). Height is kept.
        """
        target = {"+x": 0.0, "+z": -np.pi / 2}[facing]  # Ry(-pi/2) maps +x to +z
        turn = R.heading_quat(np.array(target - self.heading()[frame]))
        offset = self.root_pos[frame] * np.array([1.0, 0.0, 1.0])
        pos = R.rotate(np.broadcast_to(turn, (self.num_frames, 4)), self.root_pos - offset)
        rot = self.local_rot.copy()
        rot[:, 0] = R.multiply(np.broadcast_to(turn, (self.num_frames, 4)), rot[:, 0])
        return self.replace(root_pos=pos, local_rot=rot)


def finite_difference(x: np.ndarray, dt: float) -> np.ndarray:
    """Central differences along axis 0 (one-sided at the ends), per second."""
    if x.shape[0] < 2:
        return np.zeros_like(x)
    return np.gradient(x, dt, axis=0)


def _pad_differences(fwd: np.ndarray) -> np.ndarray:
    """Turn (T-1) forward differences into (T) samples by averaging neighbours."""
    out = np.empty((fwd.shape[0] + 1,) + fwd.shape[1:])
    out[0] = fwd[0]
    out[-1] = fwd[-1]
    out[1:-1] = 0.5 * (fwd[1:] + fwd[:-1])
    return out
