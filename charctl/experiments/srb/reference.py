"""The reference the SRB tracks (paper §4): pelvis trajectory, foot contact points and the
contact schedule derived from a clip, the cycle extension of a looping clip, and the box's inertia.

Frames: world y-up, the humanoid faces +x, right side +z. Quaternions xyzw. "Heading frame" =
the world frame turned by the root's yaw about +y (origin at the root). Units: metres, seconds,
radians, kilograms.

The paper hard-codes the frames of its own clip (right foot down at 35, up at 19; left down at 17,
up at 37). Here the schedule is derived for any clip from its foot sole points: a foot is in
stance when its lower sole point (heel or toe of the foot box) is below `contact_height` and that
point moves slower than `contact_speed`; stance/swing runs shorter than `min_phase_frames` are
merged into their neighbours (cyclically for looping clips).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from charctl.errors import CharctlError
from charctl.motion import rotations as R
from charctl.motion.skeleton import FEET

UP = np.array([0.0, 1.0, 0.0])
MAX_CYCLES = 256  # cycles of the extended reference precomputed (episodes of any realistic length)


# ---------------------------------------------------------------------------- sole points
def sole_points_local(skeleton, foot: str) -> np.ndarray:
    """(2, 3) heel and toe on the bottom face of the foot box, in the ankle body frame (metres)."""
    g = skeleton.geoms[skeleton.index(foot)]
    if g.kind != "box":
        raise CharctlError(f"the {foot} geom is a {g.kind}, expected the foot box")
    c, h = np.array(g.pos), np.array(g.size)
    return np.array([[c[0] - h[0], c[1] - h[1], c[2]], [c[0] + h[0], c[1] - h[1], c[2]]])


def sole_points_world(clip) -> np.ndarray:
    """(T, 2 feet, 2 points [heel, toe], 3) world positions of the sole points of both feet."""
    skel = clip.skeleton
    out = np.empty((clip.num_frames, 2, 2, 3))
    for j, foot in enumerate(FEET):
        b = skel.index(foot)
        local = np.broadcast_to(sole_points_local(skel, foot), (clip.num_frames, 2, 3))
        rot = np.broadcast_to(clip.body_rot[:, b, None, :], (clip.num_frames, 2, 4))
        out[:, j] = clip.body_pos[:, b, None, :] + R.rotate(rot, local)
    return out


# ---------------------------------------------------------------------------- contact schedule
def merge_short_runs(mask: np.ndarray, min_len: int, cyclic: bool) -> np.ndarray:
    """Flip runs of equal values shorter than `min_len` (shortest first) until none is left."""
    mask = mask.astype(bool).copy()
    n = mask.size
    for _ in range(n):
        runs = _runs(mask, cyclic)
        if len(runs) <= 1:
            break
        short = [r for r in runs if r[1] < min_len]
        if not short:
            break
        start, length = min(short, key=lambda r: r[1])
        idx = (start + np.arange(length)) % n
        mask[idx] = ~mask[idx]
    return mask


def _runs(mask: np.ndarray, cyclic: bool) -> list[tuple[int, int]]:
    """(start, length) of the runs of equal values; a cyclic run may wrap past the end."""
    n = mask.size
    change = np.flatnonzero(mask != np.roll(mask, 1)) if cyclic else np.flatnonzero(np.diff(mask.astype(int))) + 1
    if cyclic:
        if change.size == 0:
            return [(0, n)]
        return [(int(s), int((e - s) % n or n)) for s, e in zip(change, np.roll(change, -1))]
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [n]])
    return [(int(s), int(e - s)) for s, e in zip(starts, ends)]


def derive_contact_schedule(clip, height: float = 0.03, speed: float = 1.0, min_frames: int = 3) -> np.ndarray:
    """(T', 2) bool stance flags of the right and left foot per frame.

    For a looping clip T' = T - 1 (the last frame repeats the first pose) and the schedule is
    cyclic; otherwise T' = T. Stance = lower sole point below `height` (m) and moving slower than
    `speed` (m/s, horizontal); runs shorter than `min_frames` are merged.
    """
    pts = sole_points_world(clip)  # (T, 2, 2, 3)
    vel = np.gradient(pts, clip.dt, axis=0)
    low = np.argmin(pts[..., 1], axis=-1)  # (T, 2): heel or toe
    h = np.take_along_axis(pts[..., 1], low[..., None], axis=-1)[..., 0]
    v = np.linalg.norm(np.take_along_axis(vel[..., [0, 2]], low[..., None, None], axis=2)[:, :, 0], axis=-1)
    stance = (h < height) & (v < speed)
    n = clip.num_frames - 1 if clip.loop else clip.num_frames
    stance = stance[:n]
    return np.stack([merge_short_runs(stance[:, j], min_frames, clip.loop) for j in range(2)], axis=1)


def transitions(stance: np.ndarray, cyclic: bool = True) -> tuple[list[int], list[int]]:
    """Frames where a (T,) stance flag turns on (touch-down) and off (lift-off)."""
    prev = np.roll(stance, 1) if cyclic else np.concatenate([[stance[0]], stance[:-1]])
    return [int(i) for i in np.flatnonzero(stance & ~prev)], [int(i) for i in np.flatnonzero(~stance & prev)]


# ---------------------------------------------------------------------------- body inertia
def composite_inertia(clip, frame: int = 0) -> tuple[np.ndarray, float, np.ndarray]:
    """Composite inertia of the humanoid in one clip pose, about its COM, in the pelvis frame.

    Returns (I (3, 3) kg m^2, total mass kg, COM offset from the pelvis in the pelvis frame, m).
    Bodies' own inertias come from MuJoCo's model of the humanoid (uniform-density geoms).
    """
    import mujoco

    from charctl.sim.humanoid import load_model, local_rot_to_qpos

    model = load_model()
    data = mujoco.MjData(model)
    data.qpos[:] = local_rot_to_qpos(clip.root_pos[frame], clip.local_rot[frame])
    mujoco.mj_forward(model, data)
    ids = np.arange(1, model.nbody)
    m = model.body_mass[ids]
    com = (m[:, None] * data.xipos[ids]).sum(0) / m.sum()
    rot = data.ximat[ids].reshape(-1, 3, 3)
    own = np.einsum("bij,bj,bkj->bik", rot, model.body_inertia[ids], rot)
    r = data.xipos[ids] - com
    parallel = m[:, None, None] * (
        np.einsum("bi,bi->b", r, r)[:, None, None] * np.eye(3) - np.einsum("bi,bj->bij", r, r)
    )
    inertia_world = (own + parallel).sum(0)
    pelvis = data.xmat[1].reshape(3, 3)
    inertia = pelvis.T @ inertia_world @ pelvis
    return 0.5 * (inertia + inertia.T), float(m.sum()), pelvis.T @ (com - data.xpos[1])


def box_half_extents(inertia_diag: np.ndarray, mass: float) -> np.ndarray:
    """Half extents (m) of the uniform box with principal moments `inertia_diag` (kg m^2) and `mass`."""
    ix, iy, iz = inertia_diag
    sq = 6.0 / mass * np.array([iy + iz - ix, ix + iz - iy, ix + iy - iz])
    return 0.5 * np.sqrt(np.maximum(sq, 1e-6))


# ---------------------------------------------------------------------------- the reference
@dataclass(frozen=True, eq=False)
class Reference:
    """One cycle of the reference plus the rigid transform that maps a cycle onto the next.

    Per frame i of the cycle (C frames): root position/rotation, world linear/angular velocity,
    the 4 sole points (2 feet x [heel, toe]), the feet's ground midpoints and yaws, and the stance
    schedule. Frame f >= C lies in cycle k = f // C and equals frame f % C moved by the cycle
    transform applied k times (yaw `cycle_yaw` about +y, then `cycle_shift`), so a looping clip
    that turns a little per cycle gives a seamless, gently curving reference.
    """

    name: str
    fps: float
    root_pos: np.ndarray  # (C, 3)
    root_rot: np.ndarray  # (C, 4)
    lin_vel: np.ndarray  # (C, 3) world m/s
    ang_vel: np.ndarray  # (C, 3) world rad/s
    sole: np.ndarray  # (C, 2, 2, 3) world sole points
    stance: np.ndarray  # (C, 2) bool, [right, left]
    cycle_yaws: np.ndarray  # (K,) yaw of cycle k, radians
    cycle_shifts: np.ndarray  # (K, 3) translation of cycle k, metres
    touchdown_height: float  # lowest pelvis height at a scheduled touch-down (m)

    @property
    def cycle(self) -> int:
        return self.root_pos.shape[0]

    @property
    def dt(self) -> float:
        return 1.0 / self.fps

    @property
    def cycle_seconds(self) -> float:
        return self.cycle / self.fps

    @functools.cached_property
    def foot_mid(self) -> np.ndarray:
        """(C, 2, 3) ground midpoint of each foot's sole (y = 0)."""
        mid = self.sole.mean(axis=2)
        mid[..., 1] = 0.0
        return mid

    @functools.cached_property
    def foot_yaw(self) -> np.ndarray:
        """(C, 2) yaw (radians about +y) of each foot's heel-to-toe direction."""
        d = self.sole[:, :, 1] - self.sole[:, :, 0]
        return np.arctan2(-d[..., 2], d[..., 0])

    @functools.cached_property
    def root_yaw(self) -> np.ndarray:
        return R.yaw_about_y(self.root_rot)

    @functools.cached_property
    def foot_local(self) -> np.ndarray:
        """(C, 2, 3) foot ground midpoints in the root heading frame (relative to the root)."""
        inv = R.heading_quat(-self.root_yaw)[:, None, :].repeat(2, 1)
        return R.rotate(inv, self.foot_mid - self.root_pos[:, None, :])

    @functools.cached_property
    def sole_local(self) -> np.ndarray:
        """(C, 2, 2, 3) sole points in the root heading frame (relative to the root)."""
        inv = np.broadcast_to(R.heading_quat(-self.root_yaw)[:, None, None, :], self.sole.shape[:-1] + (4,))
        return R.rotate(inv, self.sole - self.root_pos[:, None, None, :])

    @functools.cached_property
    def next_touchdown(self) -> np.ndarray:
        """(C, 2) int: for each frame and foot, the first frame >= it (unwrapped) where the foot touches down."""
        out = np.zeros((self.cycle, 2), dtype=int)
        for j in range(2):
            downs, _ = transitions(self.stance[:, j])
            if not downs:
                out[:, j] = -1
                continue
            d = np.array(downs)
            frames = np.arange(self.cycle)[:, None]
            ahead = (d[None, :] - frames) % self.cycle
            out[:, j] = np.arange(self.cycle) + ahead.min(axis=1)
        return out

    @functools.cached_property
    def swing_progress(self) -> np.ndarray:
        """(C, 2) fraction of the current swing elapsed at each frame (0 at lift-off, 1 at touch-down; 1 in stance)."""
        out = np.ones((self.cycle, 2))
        for j in range(2):
            downs, ups = transitions(self.stance[:, j])
            for up in ups:  # one swing per foot and cycle in a walk: a handful of iterations
                length = min((d - up) % self.cycle for d in downs)
                frames = (up + np.arange(length)) % self.cycle
                out[frames, j] = np.arange(length) / length
        return out

    # ---------------------------------------------------------------- lookups at unwrapped frames
    def split(self, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(cycle index k, frame in cycle i) of unwrapped frame numbers."""
        frames = np.asarray(frames, dtype=int)
        k = np.clip(frames // self.cycle, 0, MAX_CYCLES - 1)
        return k, frames % self.cycle

    def cycle_quat(self, k: np.ndarray) -> np.ndarray:
        return R.heading_quat(self.cycle_yaws[k])

    @functools.cached_property
    def table(self) -> dict[str, np.ndarray]:
        """World root state at every unwrapped frame 0 .. MAX_CYCLES * C - 1 (precomputed once)."""
        frames = np.arange(MAX_CYCLES * self.cycle)
        k, i = frames // self.cycle, frames % self.cycle
        qc = self.cycle_quat(k)
        return {
            "pos": R.rotate(qc, self.root_pos[i]) + self.cycle_shifts[k],
            "rot": R.multiply(qc, self.root_rot[i]),
            "vel": R.rotate(qc, self.lin_vel[i]),
            "ang_vel": R.rotate(qc, self.ang_vel[i]),
            "yaw": self.root_yaw[i] + self.cycle_yaws[k],
        }

    def state(self, frames: np.ndarray) -> dict[str, np.ndarray]:
        """World root position, rotation, linear and angular velocity and yaw at unwrapped frames (N,)."""
        f = np.clip(np.asarray(frames, dtype=int), 0, MAX_CYCLES * self.cycle - 1)
        return {key: value[f] for key, value in self.table.items()}

    def phase(self, frames: np.ndarray) -> np.ndarray:
        return (np.asarray(frames) % self.cycle) / self.cycle


def _cycle_transforms(yaw: float, shift_xz: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Yaw and translation of cycle k = 0..count-1 for the per-cycle transform (yaw, shift)."""
    yaws = yaw * np.arange(count)
    shifts = np.zeros((count, 3))
    for k in range(1, count):  # composition of rigid transforms: sequential by definition, once per reference
        shifts[k] = R.rotate(R.heading_quat(np.array(yaw)), shifts[k - 1]) + shift_xz
    return yaws, shifts


def build_reference(clip, contact_height: float = 0.03, contact_speed: float = 1.0, min_frames: int = 3) -> Reference:
    """The SRB reference of `clip` (a looping clip gives a cyclic, seamlessly repeated reference)."""
    if clip.num_frames < 4:
        raise CharctlError(f"clip {clip.name!r} is too short for the srb reference ({clip.num_frames} frames)")
    stance = derive_contact_schedule(clip, contact_height, contact_speed, min_frames)
    c = stance.shape[0]
    for j, foot in enumerate(("right", "left")):
        if stance[:, j].all() or not stance[:, j].any():
            raise CharctlError(
                f"clip {clip.name!r}: the {foot} foot never "
                f"{'lifts off' if stance[:, j].all() else 'touches down'}; srb needs a walking clip"
            )
    sole = sole_points_world(clip)
    if clip.loop:
        yaw0, yaw1 = R.yaw_about_y(clip.local_rot[[0, c], 0])
        dyaw = float(yaw1 - yaw0)
        turn = R.heading_quat(np.array(dyaw))
        p0 = clip.root_pos[0] * np.array([1.0, 0.0, 1.0])
        shift = clip.root_pos[c] * np.array([1.0, 0.0, 1.0]) - R.rotate(turn, p0)
    else:  # a non-looping clip: repeat it in place (decision; srb is meant for cyclic gaits)
        dyaw, shift = 0.0, np.zeros(3)
    yaws, shifts = _cycle_transforms(dyaw, shift, MAX_CYCLES)
    # Velocities by central differences over the previous / next cycle so the wrap is smooth.
    pos, rot = clip.root_pos[:c], R.normalize(clip.local_rot[:c, 0])
    qturn = R.heading_quat(np.array(dyaw))
    qback = R.conjugate(qturn)
    p_next = R.rotate(np.broadcast_to(qturn, (1, 4)), pos[:1])[0] + shift
    p_prev = R.rotate(np.broadcast_to(qback, (1, 4)), (pos[-1:] - shift))[0]
    ext_pos = np.concatenate([p_prev[None], pos, p_next[None]])
    r_next = R.multiply(qturn, rot[0])
    r_prev = R.multiply(qback, rot[-1])
    ext_rot = R.continuous_sign(np.concatenate([r_prev[None], rot, r_next[None]]))
    lin_vel = (ext_pos[2:] - ext_pos[:-2]) * clip.fps / 2.0
    dq = R.multiply(ext_rot[2:], R.conjugate(ext_rot[:-2]))
    ang_vel = R.log_map(dq) * clip.fps / 2.0
    downs = [f for j in range(2) for f in transitions(stance[:, j])[0]]
    td_height = float(clip.root_pos[downs, 1].min())
    return Reference(
        name=clip.name,
        fps=float(clip.fps),
        root_pos=pos.copy(),
        root_rot=rot,
        lin_vel=lin_vel,
        ang_vel=ang_vel,
        sole=sole[:c].copy(),
        stance=stance,
        cycle_yaws=yaws,
        cycle_shifts=shifts,
        touchdown_height=td_height,
    )
