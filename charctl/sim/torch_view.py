"""C MuJoCo's batched humanoid (`BatchedHumanoid`) seen as torch tensors on the CPU (env.backend=torch).

`TorchBatchedHumanoid` wraps a `charctl.sim.batch.BatchedHumanoid` and exposes the interface of
`charctl.sim.warp_batch.WarpBatchedHumanoid` that the torch form of the env (`env.CgailEnv` on
`env_arrays.TorchArrays`), its kinematics reader (`warp_kinematics.sim_kinematics`) and the device rollout
use, so the torch env runs over C MuJoCo on the CPU as it runs over MuJoCo Warp on a GPU.

What is a view and what is a copy:

* the raw state arrays (`qpos`, `qvel`, `ctrl`, `xfrc_applied`, `xpos`, `xquat`, `cvel`,
  `subtree_com`, `geom_xpos`, `geom_xmat`) are `torch.from_numpy` views of MuJoCo's own arrays: no
  copy, writes go straight into MuJoCo's data (the read-only ones must not be written);
* the derived quantities (`body_pos`, `body_quat_xyzw`, `body_velocities`,
  `non_foot_ground_contact`) are computed by `BatchedHumanoid`'s numpy code, exactly as the numpy
  env (`CgailEnv`) gets them: one gather into charctl body order each, as there, and the resulting
  numpy array is wrapped without a further copy; `com()` is a view;
* inputs: PD targets and pushes are written into MuJoCo's `ctrl` / `xfrc_applied` (one write, as in
  the numpy env); `set_state` writes only the rows of the envs it resets.

Dtype: float64, MuJoCo's own (a float32 view cannot exist; a conversion would be a copy of every
array on every step). The env computes its features in float64, the numbers of `CgailEnv`, and casts
only the policy state and discriminator observation to float32 for the networks (`dtype` tells it so).

Frames and units as `BatchedHumanoid`: world frame, y-up, metres, m/s, rad/s, quaternions xyzw in
`body_quat_xyzw` (MuJoCo's wxyz in `xquat`), charctl body order in the derived quantities, MuJoCo body
ids in the raw arrays. Env ids may be an (N,) bool mask or integer indices, as for the Warp twin.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np
import torch

from charctl.sim.batch import BatchedHumanoid, SimSettings


def as_tensor_view(a: np.ndarray) -> torch.Tensor:
    """`torch.from_numpy(a)`: shares memory with `a` (no copy), also for MuJoCo's read-only arrays."""
    with warnings.catch_warnings():  # torch warns that a read-only array is wrapped as a writable tensor
        warnings.simplefilter("ignore", UserWarning)
        return torch.from_numpy(a)


def _numpy(x) -> np.ndarray:
    """A CPU tensor or array as a float64 numpy array (a view when it is float64 already)."""
    if isinstance(x, torch.Tensor):
        x = x.detach()
        return (x if x.dtype == torch.float64 else x.double()).numpy()
    return np.asarray(x, dtype=np.float64)


class TorchBatchedHumanoid:
    """`num_envs` humanoids on C MuJoCo (`BatchedHumanoid`) with `WarpBatchedHumanoid`'s torch interface."""

    dtype = torch.float64

    def __init__(
        self,
        num_envs: int,
        settings: SimSettings | None = None,
        reset_fn: Callable[[torch.Tensor], None] | None = None,
        base: BatchedHumanoid | None = None,
    ):
        """`base`: an existing `BatchedHumanoid` to wrap (else one is built from `settings`). `reset_fn(mask)`
        is called with the (N,) bool mask of the envs reset after a blow-up, as for the Warp backend."""
        self.base = base or BatchedHumanoid(num_envs, settings)
        if reset_fn is not None:
            self.base.reset_fn = lambda ids: reset_fn(self.as_mask(torch.from_numpy(np.asarray(ids))))
        b = self.base
        self.device = torch.device("cpu")
        self.num_envs, self.settings, self.substeps = b.num_envs, b.settings, b.substeps
        self.model, self.layout = b.model, b.layout
        self.body_ids_np = b.body_ids
        self.body_ids = torch.as_tensor(b.body_ids)
        self.total_mass = float(b.model.body_subtreemass[1])  # kg
        self.qpos0 = torch.as_tensor(b.model.qpos0)
        for name in ("qpos", "qvel", "ctrl", "xfrc_applied", "xpos", "xquat", "cvel", "subtree_com"):
            setattr(self, name, as_tensor_view(getattr(b, name)))
        self.geom_xpos = as_tensor_view(b.geom_xpos)  # (N, ngeom, 3)
        self.geom_xmat = as_tensor_view(b.geom_xmat).view(b.num_envs, -1, 3, 3)  # (N, ngeom, 3, 3), a view

    # ------------------------------------------------------------------ env ids
    def as_mask(self, ids) -> torch.Tensor:
        """(N,) bool mask from a mask or from integer env ids."""
        ids = torch.as_tensor(ids)
        if ids.dtype == torch.bool:
            return ids
        mask = torch.zeros(self.num_envs, dtype=torch.bool)
        mask[ids.long()] = True
        return mask

    # ------------------------------------------------------------------ state
    def set_state(self, ids, qpos, qvel) -> None:
        """Write full states and recompute kinematics (MuJoCo mjSTAGE_VEL). `ids`: (N,) bool mask with
        `qpos` (N, nq) and `qvel` (N, nv) (only the masked rows are read), or integer ids with
        (len(ids), nq) / (len(ids), nv). PD targets of those envs become their pose, as in `BatchedHumanoid`."""
        ids_t = torch.as_tensor(ids)
        qpos, qvel = _numpy(qpos), _numpy(qvel)
        if ids_t.dtype == torch.bool:
            rows = np.flatnonzero(ids_t.numpy())
            if rows.size == 0:
                return
            qpos, qvel = qpos[rows], qvel[rows]
        else:
            rows = ids_t.long().numpy()
        self.base.set_state(rows, qpos, qvel)

    # ------------------------------------------------------------------ stepping
    def step(self, targets, force=None, force_substeps: int = 0) -> torch.Tensor:
        """Hold PD `targets` (N, nu) radians for one control step; returns the (N,) bool tensor of envs
        that blew up and were reset (model defaults, then `reset_fn`). `force` (N, nbody, 6) world-frame
        [force, torque] (MuJoCo body ids) acts during the first `force_substeps` physics substeps."""
        f = None if force is None else _numpy(force)
        return torch.from_numpy(self.base.step(_numpy(targets), force=f, force_substeps=force_substeps))

    def recover(self, mask, count: bool = True) -> None:
        """Reset the envs in `mask` to the model's defaults (rest pose) and call `reset_fn`; `count` them as
        blow-ups unless told not to."""
        rows = np.flatnonzero(self.as_mask(mask).numpy())
        if rows.size == 0:
            return
        before = self.base.unstable_count
        self.base.recover(rows)
        if not count:
            self.base.unstable_count = before

    @property
    def unstable_count(self) -> int:
        """Envs reset after a blow-up so far."""
        return self.base.unstable_count

    # ------------------------------------------------------------------ derived quantities
    @property
    def body_pos(self) -> torch.Tensor:
        """(N, 15, 3) world positions (m) of the body frames, charctl body order."""
        return torch.from_numpy(self.base.body_pos)

    @property
    def body_quat_xyzw(self) -> torch.Tensor:
        """(N, 15, 4) world orientations of the bodies, xyzw, charctl body order."""
        return torch.from_numpy(self.base.body_quat_xyzw)

    def body_velocities(self) -> tuple[torch.Tensor, torch.Tensor]:
        """World linear velocity (m/s) of each body frame origin and world angular velocity (rad/s), (N, 15, 3) each."""
        lin, ang = self.base.body_velocities()
        return torch.from_numpy(lin), as_tensor_view(ang)

    def com(self) -> torch.Tensor:
        """(N, 3) whole-body centre of mass (m), world frame; a view of MuJoCo's subtree_com."""
        return self.subtree_com[:, 1]

    def lowest_point_heights(self) -> torch.Tensor:
        """(N, ngeom_char) lowest world y (m) of every character geom."""
        return torch.from_numpy(self.base.lowest_point_heights())

    def non_foot_ground_contact(self, tol: float = 0.005) -> torch.Tensor:
        """(N,) True where a body other than the feet is within `tol` metres of the ground (a fall)."""
        return torch.from_numpy(self.base.non_foot_ground_contact(tol))
