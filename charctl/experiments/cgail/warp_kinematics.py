"""Kinematics of the on-device simulator (env.backend=warp) as torch tensors, for the shared features.

The policy state, discriminator observation, rewards and episode ends are `features.py` and
`rules.py`, written once for numpy and torch (`charctl.motion.array_compat`); this module only reads
a `WarpBatchedHumanoid` into their `Kinematics`, on its device, without a host round trip. The CPU
backend's twin is `features.sim_kinematics` (MuJoCo's C arrays); `tests/test_gpu_path.py` holds the
two equal on the same states.

Frames and units: world y-up, metres, m/s, rad/s; quaternions xyzw.
"""

from __future__ import annotations

import dataclasses
import functools

import torch

from charctl.experiments.cgail.features import Kinematics
from charctl.experiments.cgail.features import sim_kinematics as numpy_sim_kinematics
from charctl.motion import rotations_torch as RT
from charctl.motion.skeleton import load_skeleton
from charctl.sim.torch_view import TorchBatchedHumanoid


@functools.lru_cache(maxsize=8)
def _mass_tables(device: str, dtype: torch.dtype = torch.float64) -> tuple[torch.Tensor, torch.Tensor]:
    """(body masses (15,), local COM offsets (15, 3)) on `device`, in `dtype` (cast from float64)."""
    skel = load_skeleton()
    dev = torch.device(device)
    masses = torch.as_tensor(skel.masses, dtype=torch.float64, device=dev).to(dtype)
    return masses, torch.as_tensor(skel.com_local, dtype=torch.float64, device=dev).to(dtype)


def sim_kinematics(sim, rows: torch.Tensor | None = None) -> Kinematics:
    """Kinematics of a `WarpBatchedHumanoid` after a step (exact MuJoCo velocities), on its device: of every
    env, or of the envs `rows` ((n,) integer ids; the resets on the CPU, `env_arrays.TorchArrays.compact_rows`).

    Over C MuJoCo (`TorchBatchedHumanoid`, env.backend=torch) this is the numpy env's reader
    (`features.sim_kinematics`) on the wrapped `BatchedHumanoid`, its arrays wrapped without copies: the
    same numbers as the numpy env, and fewer, larger operations than torch's on the CPU.

    COM velocity = mass-weighted velocities of the body centres of mass (frame origin + rotated
    local COM offset), as in `features.sim_kinematics`.
    """
    if isinstance(sim, TorchBatchedHumanoid):  # C MuJoCo's numpy arrays underneath
        k = numpy_sim_kinematics(sim.base, slice(None) if rows is None else rows.numpy())
        return Kinematics(*(torch.from_numpy(getattr(k, f.name)) for f in dataclasses.fields(k)))
    lin, ang = sim.body_velocities()
    pos, rot, com = sim.body_pos, sim.body_quat_xyzw, sim.com()
    if rows is None:
        com = com.clone()  # a view of the simulator's live array
    else:
        lin, ang, pos, rot, com = lin[rows], ang[rows], pos[rows], rot[rows], com[rows]
    masses, com_local = _mass_tables(str(pos.device), pos.dtype)
    body_mat = RT.to_matrix(rot)  # kept for the heading frame (`features.heading_frame` reuses it)
    offset = (body_mat @ com_local[:, :, None])[..., 0]  # body COM - frame origin, world
    com_vel_bodies = lin + torch.cross(ang, offset, dim=-1)
    com_vel = torch.einsum("nbi,b->ni", com_vel_bodies, masses) / sim.total_mass
    return Kinematics(pos, rot, lin, ang, com, com_vel, body_mat)
