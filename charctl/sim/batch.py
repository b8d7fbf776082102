"""N humanoids stepped together on MuJoCo's multi-threaded `mujoco.batch.Batch`.

Control runs at `control_hz`; PD targets (actuator ctrl, radians) are held over
`physics_hz / control_hz` physics substeps, all inside C. After each control step the
position/velocity-dependent fields are current (stage mjSTAGE_VEL), so observations are read
from live numpy views without any per-env Python work.

Faults never crash the batch: a simulation whose state turns non-finite, whose joint speeds
exceed `max_speed`, or that MuJoCo itself reports as diverged is reset (by the caller's reset
function, default: the model's rest pose) and counted in `unstable_count`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from charctl.motion.rotations import cross
from charctl.motion.skeleton import FEET, load_skeleton
from charctl.sim import CONTROL_HZ, JOINT_ARMATURE, PHYSICS_HZ
from charctl.sim.humanoid import layout, load_model


@dataclass
class SimSettings:
    """Rates and safety limits of the batched simulator."""

    physics_hz: float = PHYSICS_HZ  # MuJoCo step rate (charctl.sim.PHYSICS_HZ)
    control_hz: float = CONTROL_HZ  # policy rate; PD targets held for physics_hz/control_hz substeps
    nthread: int = 0  # worker threads (0 = all CPUs)
    max_speed: float = 200.0  # |qvel| above this (m/s, rad/s) counts as a blow-up
    friction: float = 1.0
    armature: float = JOINT_ARMATURE  # kg m^2 per hinge (charctl.sim.JOINT_ARMATURE)
    shoulder_frame: str = "parent"  # the shoulders' hinge-chain frames (charctl.sim.humanoid.SHOULDER_FRAMES)

    @classmethod
    def of(cls, cfg) -> SimSettings:
        """The settings an experiment's config section states (physics_hz, control_hz, armature, shoulder_frame;
        cgail's `env`); the rest at their defaults."""
        return cls(
            physics_hz=cfg.physics_hz,
            control_hz=cfg.control_hz,
            armature=cfg.armature,
            shoulder_frame=cfg.shoulder_frame,
        )


class BatchedHumanoid:
    """`num_envs` humanoids; arrays are (num_envs, ...) live views (world frame, y-up)."""

    def __init__(
        self, num_envs: int, settings: SimSettings | None = None, reset_fn: Callable[[np.ndarray], None] | None = None
    ):
        import mujoco
        import mujoco.batch

        self.settings = s = settings or SimSettings()
        ratio = s.physics_hz / s.control_hz
        if abs(ratio - round(ratio)) > 1e-6 or ratio < 1:
            raise ValueError(f"physics_hz ({s.physics_hz}) must be a whole multiple of control_hz ({s.control_hz})")
        self.substeps = int(round(ratio))
        self.model = load_model(s.physics_hz, s.friction, s.armature, s.shoulder_frame)
        self.num_envs = num_envs
        self.batch = mujoco.batch.Batch(self.model, nsim=num_envs, nthread=s.nthread)
        self._stage_vel = int(mujoco.mjtStage.mjSTAGE_VEL)
        self._simulation_error = mujoco.batch.SimulationError
        self.qpos = self.batch.bind("qpos")
        self.qvel = self.batch.bind("qvel")
        self.ctrl = self.batch.bind("ctrl")
        self.xfrc_applied = self.batch.bind("xfrc_applied")  # (N, nbody, 6) external force/torque, world frame
        self.xpos = self.batch.bind("xpos")  # (N, nbody, 3) body frame origins; body 0 = world
        self.xquat = self.batch.bind("xquat")  # (N, nbody, 4) wxyz
        self.cvel = self.batch.bind("cvel")  # (N, nbody, 6) [angular, linear] at the subtree COM
        self.subtree_com = self.batch.bind("subtree_com")
        self.geom_xpos = self.batch.bind("geom_xpos")
        self.geom_xmat = self.batch.bind("geom_xmat")
        self.reset_fn = reset_fn
        self.unstable_count = 0
        self.layout = layout()
        skel = load_skeleton()
        self.body_ids = np.array([self.model.body(n).id for n in skel.names])  # charctl order -> MuJoCo ids
        self._ground_geoms, self._foot_geoms = self._contact_geoms(skel)
        self.batch.reset()

    # ------------------------------------------------------------------ state
    def set_state(self, ids: np.ndarray, qpos: np.ndarray, qvel: np.ndarray) -> None:
        """Write full states of envs `ids` and recompute their kinematics."""
        ids = np.asarray(ids, dtype=np.int64)
        if ids.size == 0:
            return
        self.qpos[ids] = qpos
        self.qvel[ids] = qvel
        self.ctrl[ids] = qpos[:, 7:]
        self.batch.forward(ids, stage=self._stage_vel)

    # ------------------------------------------------------------------ stepping
    def step(self, targets: np.ndarray, force: np.ndarray | None = None, force_substeps: int = 0) -> np.ndarray:
        """Hold PD `targets` (N, nu) radians for one control step; returns the mask of envs that
        blew up and were reset.

        `force` (N, nbody, 6) world-frame force/torque (xfrc_applied, MuJoCo body ids) acts during
        the first `force_substeps` physics substeps of this control step (pushes shorter than a
        control step), then is cleared.
        """
        self.ctrl[:] = targets
        bad = np.zeros(self.num_envs, dtype=bool)
        chunks = [(self.substeps, None)]
        if force is not None and force_substeps > 0:
            k = min(int(force_substeps), self.substeps)
            chunks = [(k, force), (self.substeps - k, None)]
        for nstep, f in chunks:
            if nstep <= 0:
                continue
            self.xfrc_applied[:] = 0.0 if f is None else f
            try:
                self.batch.step(nstep=nstep, stage=self._stage_vel)
            except self._simulation_error as exc:
                bad[exc.ids] = True
        bad |= ~np.isfinite(self.qpos).all(axis=1) | ~np.isfinite(self.qvel).all(axis=1)
        bad |= np.abs(self.qvel).max(axis=1) > self.settings.max_speed
        bad |= self._diverged_by_warnings()
        if bad.any():
            self.recover(np.flatnonzero(bad))
        return bad

    def recover(self, ids: np.ndarray) -> None:
        """Reset blown-up envs (caller's reset function, else rest pose) and count them."""
        self.unstable_count += len(ids)
        self.batch.reset(ids)
        if self.reset_fn is not None:
            self.reset_fn(ids)

    def _diverged_by_warnings(self) -> np.ndarray:
        """MuJoCo's own bad-qacc/qpos/qvel resets show up as rising warning counters."""
        w = np.asarray(self.batch.warning)  # (N, mjNWARNING, 2)
        import mujoco

        cols = [
            int(mujoco.mjtWarning.mjWARN_BADQACC),
            int(mujoco.mjtWarning.mjWARN_BADQPOS),
            int(mujoco.mjtWarning.mjWARN_BADQVEL),
        ]
        counts = w[:, cols, 1].sum(axis=1)  # mjWarningStat = (lastinfo, number)
        prev = getattr(self, "_warn_prev", None)
        self._warn_prev = counts.copy()
        return np.zeros(self.num_envs, dtype=bool) if prev is None else counts > prev

    # ------------------------------------------------------------------ derived quantities
    # `rows` selects envs: all of them (the default, a view) or an index array (resets touch a few).
    def body_pos_rows(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(n, 15, 3) world positions of the body frames of envs `rows`, charctl body order."""
        return self.xpos[rows][:, self.body_ids]

    def body_quat_rows(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(n, 15, 4) world orientations (xyzw) of the bodies of envs `rows`, charctl body order."""
        q = self.xquat[rows][:, self.body_ids]
        return np.concatenate([q[..., 1:4], q[..., :1]], axis=-1)

    def body_velocities_rows(
        self, rows: np.ndarray | slice = slice(None), body_pos: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """World linear velocity of each body frame origin and world angular velocity, (n, 15, 3) each."""
        cv = self.cvel[rows][:, self.body_ids]
        ang, lin_c = cv[..., :3], cv[..., 3:]
        pos = self.body_pos_rows(rows) if body_pos is None else body_pos
        r = pos - self.subtree_com[rows][:, 1:2]
        return lin_c + cross(ang, r), ang

    @property
    def body_pos(self) -> np.ndarray:
        """(N, 15, 3) world positions of the body frames, charctl body order."""
        return self.body_pos_rows()

    @property
    def body_quat_xyzw(self) -> np.ndarray:
        return self.body_quat_rows()

    def body_velocities(self) -> tuple[np.ndarray, np.ndarray]:
        """World linear velocity of each body frame origin and world angular velocity, (N, 15, 3) each."""
        return self.body_velocities_rows()

    def com(self) -> np.ndarray:
        """(N, 3) whole-body centre of mass."""
        return self.subtree_com[:, 1]

    def lowest_point_heights(self) -> np.ndarray:
        """(N, ngeom_char) lowest y of every character geom (exact for spheres/capsules, boxes via corners)."""
        return _lowest_y(self.model, self.geom_xpos, self.geom_xmat, self._ground_geoms)

    def non_foot_ground_contact(self, tol: float = 0.005) -> np.ndarray:
        """(N,) True where a body other than the feet is within `tol` metres of the ground (a fall)."""
        low = self.lowest_point_heights()
        return (low[:, ~self._foot_geoms] < tol).any(axis=1)

    def _contact_geoms(self, skel) -> tuple[np.ndarray, np.ndarray]:
        m = self.model
        ids = np.array([g for g in range(m.ngeom) if m.geom_bodyid[g] != 0])
        feet = {m.body(n).id for n in FEET}
        is_foot = np.array([m.geom_bodyid[g] in feet for g in ids])
        return ids, is_foot


def _lowest_y(model, geom_xpos: np.ndarray, geom_xmat: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """Lowest world-y point of each geom in `ids` across the batch, vectorised."""
    import mujoco

    pos = geom_xpos[:, ids]  # (N, G, 3)
    mat = geom_xmat[:, ids].reshape(pos.shape[0], len(ids), 3, 3)
    size = model.geom_size[ids]
    gtype = model.geom_type[ids]
    # y-extent of each shape along world y: sphere r; capsule r + half * |axis_y|; box sum |R_y,k| h_k
    ext = np.zeros(pos.shape[:2])
    sph = gtype == mujoco.mjtGeom.mjGEOM_SPHERE
    cap = gtype == mujoco.mjtGeom.mjGEOM_CAPSULE
    box = gtype == mujoco.mjtGeom.mjGEOM_BOX
    ext[:, sph] = size[sph, 0]
    ext[:, cap] = size[cap, 0] + size[cap, 1] * np.abs(mat[:, cap, 1, 2])
    ext[:, box] = np.einsum("ngk,gk->ng", np.abs(mat[:, box, 1, :]), size[box])
    return pos[..., 1] - ext
