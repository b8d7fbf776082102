"""N humanoids stepped together on MuJoCo Warp (`mujoco_warp`), the GPU twin of `BatchedHumanoid`.

Same MJCF (`charctl.sim.humanoid.load_model`), same interface, but every array is a torch tensor
on the simulation device that *shares memory* with MuJoCo Warp's arrays (`wp.to_torch`, no copy),
so a control step never goes through the host: PD targets are written into `ctrl`, the
`physics_hz / control_hz` substeps run as Warp kernels (one CUDA graph per substep count on a GPU),
blown-up worlds are found and reset with masked tensor ops, and the kinematics read by the
observations (body poses, COM-based velocities, geom frames) are recomputed on the device.

Frames and units are those of the C backend: world frame, y-up, metres, m/s, rad/s; MuJoCo body
ids inside the raw arrays, charctl body order (skeleton order) in `body_pos` and friends. MuJoCo
Warp computes in float32 (the C backend in float64): `tests/test_gpu_path.py` states the
parity tolerance after 1, 10 and 30 control steps.

`env ids` may be given as a boolean mask (N,) (the sync-free form every device-side caller uses)
or as integer indices. Warp on its CPU device runs the same code on the host (slowly, after a
one-time kernel compilation of about a minute that is cached under Warp's kernel cache,
`~/.cache/warp/<version>` unless WARP_CACHE_PATH says otherwise): that is what the parity tests
use on machines without a GPU.
"""

from __future__ import annotations

import gc
import importlib.util
from collections.abc import Callable
from contextlib import contextmanager

import numpy as np
import torch

from charctl.motion import rotations_torch as RT
from charctl.motion.skeleton import FEET, load_skeleton
from charctl.sim.batch import SimSettings
from charctl.sim.humanoid import layout, load_model

BACKENDS = ("cpu", "warp", "torch", "auto")
WARP_INSTALL_HINT = "install MuJoCo Warp with `pip install -e '.[gpu]'` (README, section GPU)"
# Contacts allocated per world: the character has 5 spheres (1 contact each with the ground), 8
# capsules (<= 2) and 2 boxes (<= 4): <= 29 at once. 48 leaves room; pyramidal cones with condim 3
# give 4 constraint rows per contact, plus the 4 limited hinges.
NCONMAX_PER_WORLD = 48
NJMAX_PER_WORLD = 4 * NCONMAX_PER_WORLD + 8


def warp_available() -> bool:
    """True when `mujoco_warp` (and with it `warp`) can be imported."""
    return importlib.util.find_spec("mujoco_warp") is not None and importlib.util.find_spec("warp") is not None


def resolve_backend(backend: str, device: str) -> str:
    """`env.backend` -> "cpu" (C MuJoCo, numpy env), "warp" (MuJoCo Warp on `device`) or "torch" (C MuJoCo
    with the torch env on the CPU, `charctl.sim.torch_view`).

    auto = warp when `device` is a CUDA device and MuJoCo Warp is installed, else cpu. An explicit
    warp without MuJoCo Warp installed, or torch with a device other than the CPU, is a one-line
    CharctlError.
    """
    from charctl.errors import CharctlError

    if backend not in BACKENDS:
        raise CharctlError(f"env.backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend == "auto":
        return "warp" if str(device).startswith("cuda") and warp_available() else "cpu"
    if backend == "warp" and not warp_available():
        raise CharctlError(f"env.backend=warp needs MuJoCo Warp, which is not installed: {WARP_INSTALL_HINT}")
    if backend == "torch" and torch.device(device).type != "cpu":
        raise CharctlError(f"env.backend=torch runs on the CPU (device=cpu), got device={device}; use env.backend=warp")
    return backend


def warp_device_name(device: str | torch.device) -> str:
    """Warp's name for a torch device: "cpu" or "cuda:N"."""
    dev = torch.device(device)
    if dev.type == "cpu":
        return "cpu"
    return f"cuda:{dev.index if dev.index is not None else torch.cuda.current_device()}"


@contextmanager
def _gc_paused():
    """No garbage collection while a CUDA graph is captured (a finalised Warp object would be recorded)."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def _init_warp(wp, quiet: bool) -> None:
    """`wp.init()`; with `quiet`, no greeting and no per-module "compiled/loaded" lines (warnings still print)."""
    if quiet:
        wp.config.quiet = True
        if hasattr(wp, "LOG_WARNING"):
            wp.config.log_level = max(int(getattr(wp.config, "log_level", 0)), int(wp.LOG_WARNING))
    wp.init()


def _substeps(s: SimSettings) -> int:
    """Physics steps per control step; physics_hz must be a whole multiple of control_hz."""
    ratio = s.physics_hz / s.control_hz
    if abs(ratio - round(ratio)) > 1e-6 or ratio < 1:
        raise ValueError(f"physics_hz ({s.physics_hz}) must be a whole multiple of control_hz ({s.control_hz})")
    return int(round(ratio))


class WarpBatchedHumanoid:
    """`num_envs` humanoids on MuJoCo Warp; tensors are (num_envs, ...) live views on `device`."""

    dtype = torch.float32  # MuJoCo Warp computes in float32

    def __init__(
        self,
        num_envs: int,
        settings: SimSettings | None = None,
        device: str | torch.device = "cpu",
        reset_fn: Callable[[torch.Tensor], None] | None = None,
        quiet: bool = True,
    ):
        import mujoco
        import mujoco_warp as mjw
        import warp as wp

        _init_warp(wp, quiet)
        self.settings = s = settings or SimSettings()
        self.substeps = _substeps(s)
        self.device = torch.device(device)
        self.wp_device = wp.get_device(warp_device_name(self.device))
        if self.device.type == "cuda" and self.device.index is None:
            self.device = torch.device(f"cuda:{self.wp_device.ordinal}")
        self.num_envs = num_envs
        # host MjModel (constants, geometry)
        self.model = load_model(s.physics_hz, s.friction, s.armature, s.shoulder_frame)
        mjd = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, mjd)
        self._mjw, self._wp = mjw, wp
        self._put_on_device(mjd)
        self._bind_state_views()
        self.reset_fn = reset_fn
        self._unstable = torch.zeros((), dtype=torch.long, device=self.device)
        self.layout = layout()
        skel = load_skeleton()
        self.body_ids_np = np.array([self.model.body(n).id for n in skel.names])  # charctl order -> MuJoCo ids
        self.body_ids = torch.as_tensor(self.body_ids_np, device=self.device)
        self.total_mass = float(self.model.body_subtreemass[1])
        f32 = dict(dtype=torch.float32, device=self.device)
        self.qpos0 = torch.as_tensor(self.model.qpos0, **f32)
        self._setup_contact_geoms(skel)
        self._graphs: dict[str, object] = {}
        self._warm: set[str] = set()
        self._use_graphs = bool(self.wp_device.is_cuda and wp.is_mempool_enabled(self.wp_device))
        self.recover(torch.ones(num_envs, dtype=torch.bool, device=self.device), count=False)

    def _put_on_device(self, mjd) -> None:
        """The MuJoCo Warp model and `num_envs` copies of the host state `mjd` on the Warp device
        (conditional CUDA graphs where the driver supports them)."""
        mjw, wp = self._mjw, self._wp
        with wp.ScopedDevice(self.wp_device):
            self.wp_model = mjw.put_model(self.model)
            if self.wp_device.is_cuda:
                self.wp_model.opt.graph_conditional = bool(wp.is_conditional_graph_supported())
            self.wp_data = mjw.put_data(
                self.model, mjd, nworld=self.num_envs, nconmax=NCONMAX_PER_WORLD, njmax=NJMAX_PER_WORLD
            )

    def _bind_state_views(self) -> None:
        """Torch views of the Warp state arrays (zero-copy, (num_envs, ...), float32, world frame)."""
        d = self.wp_data
        view = self._wp.to_torch  # zero-copy: these tensors ARE MuJoCo Warp's state
        self.qpos = view(d.qpos)  # (N, nq) float32
        self.qvel = view(d.qvel)  # (N, nv)
        self.ctrl = view(d.ctrl)  # (N, nu) PD targets, radians
        self.qacc_warmstart = view(d.qacc_warmstart)
        self.xfrc_applied = view(d.xfrc_applied)  # (N, nbody, 6) external [force, torque], world frame
        self.xpos = view(d.xpos)  # (N, nbody, 3) body frame origins; body 0 = world
        self.xquat = view(d.xquat)  # (N, nbody, 4) wxyz
        self.cvel = view(d.cvel)  # (N, nbody, 6) [angular, linear] at the subtree COM
        self.subtree_com = view(d.subtree_com)
        self.geom_xpos = view(d.geom_xpos)  # (N, ngeom, 3)
        self.geom_xmat = view(d.geom_xmat)  # (N, ngeom, 3, 3)

    # ------------------------------------------------------------------ warp launches
    def _run(self, key: str, fn: Callable[[], None]) -> None:
        """Launch `fn`'s Warp kernels on the simulation device; on a GPU capture them once as a CUDA
        graph named `key` and replay it (one launch instead of hundreds). Falls back to plain launches
        when capture is not possible (old driver, no memory pool)."""
        wp = self._wp
        with wp.ScopedDevice(self.wp_device):
            if not self._use_graphs:
                fn()
                return
            graph = self._graphs.get(key)
            if graph is None:
                if key not in self._warm:  # first call: run eagerly (compiles and loads every module)
                    self._warm.add(key)
                    fn()
                    return
                try:  # second call: capture (records, does not run), then replay below
                    with _gc_paused(), wp.ScopedCapture() as cap:
                        fn()
                    self._graphs[key] = graph = cap.graph
                except Exception:  # pragma: no cover - depends on the CUDA driver
                    self._use_graphs = False
                    fn()
                    return
            wp.capture_launch(graph)

    def _physics(self, nstep: int) -> None:
        mjw, m, d = self._mjw, self.wp_model, self.wp_data
        self._run(f"step{nstep}", lambda: [mjw.step(m, d) for _ in range(nstep)])

    def _kinematics(self) -> None:
        """Position/velocity-dependent fields (xpos, xquat, geom frames, subtree COM, cvel) of the
        current qpos/qvel: what C MuJoCo's mjSTAGE_VEL leaves current after a step."""
        mjw, m, d = self._mjw, self.wp_model, self.wp_data

        def kin() -> None:
            mjw.kinematics(m, d)
            mjw.com_pos(m, d)
            mjw.com_vel(m, d)

        self._run("kinematics", kin)

    # ------------------------------------------------------------------ state
    def as_mask(self, ids) -> torch.Tensor:
        """(N,) bool mask on the device from a mask or from integer env ids."""
        ids = torch.as_tensor(ids, device=self.device)
        if ids.dtype == torch.bool:
            return ids
        mask = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        mask[ids.long()] = True
        return mask

    def _write_rows(self, mask: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor, ctrl: torch.Tensor) -> None:
        """Masked overwrite of the state of the worlds in `mask` (rows outside keep their values)."""
        m = mask[:, None]
        self.qpos.copy_(torch.where(m, qpos, self.qpos))
        self.qvel.copy_(torch.where(m, qvel, self.qvel))
        self.ctrl.copy_(torch.where(m, ctrl, self.ctrl))
        self.qacc_warmstart.masked_fill_(m, 0.0)
        self.xfrc_applied.masked_fill_(mask[:, None, None], 0.0)

    def set_state(self, ids, qpos, qvel) -> None:
        """Write full states and recompute kinematics. `ids`: (N,) bool mask with `qpos` (N, nq) and
        `qvel` (N, nv) (only masked rows are used), or integer ids with (len(ids), nq) / (len(ids), nv).
        PD targets of those envs become their pose (ctrl = qpos[:, 7:]), as in the C backend."""
        f32 = dict(dtype=torch.float32, device=self.device)
        qpos, qvel = torch.as_tensor(qpos, **f32), torch.as_tensor(qvel, **f32)
        ids_t = torch.as_tensor(ids, device=self.device)
        if ids_t.dtype != torch.bool:
            ids_t = ids_t.long()
            full_q, full_v = self.qpos.clone(), self.qvel.clone()
            full_q[ids_t], full_v[ids_t] = qpos, qvel
            qpos, qvel = full_q, full_v
        mask = self.as_mask(ids_t)
        self._write_rows(mask, qpos, qvel, qpos[:, 7:])
        self._kinematics()

    # ------------------------------------------------------------------ stepping
    def step(self, targets, force=None, force_substeps: int = 0) -> torch.Tensor:
        """Hold PD `targets` (N, nu) radians for one control step; returns the (N,) bool mask of
        envs that blew up and were reset (rest pose, then the caller's `reset_fn(mask)`).

        `force` (N, nbody, 6) world-frame [force, torque] (xfrc_applied, MuJoCo body ids) acts during
        the first `force_substeps` physics substeps of this control step, then is cleared.
        """
        self.ctrl.copy_(torch.as_tensor(targets, dtype=torch.float32, device=self.device))
        chunks: list[tuple[int, object]] = [(self.substeps, None)]
        if force is not None and force_substeps > 0:
            k = min(int(force_substeps), self.substeps)
            chunks = [(k, force), (self.substeps - k, None)]
        for nstep, f in chunks:
            if nstep <= 0:
                continue
            if f is None:
                self.xfrc_applied.zero_()
            else:
                self.xfrc_applied.copy_(torch.as_tensor(f, dtype=torch.float32, device=self.device))
            self._physics(nstep)
        self.xfrc_applied.zero_()
        bad = self.blown_up()
        self.recover(bad)
        return bad

    def blown_up(self) -> torch.Tensor:
        """(N,) bool: state not finite or a joint speed above `max_speed` (m/s, rad/s)."""
        finite = torch.isfinite(self.qpos).all(dim=1) & torch.isfinite(self.qvel).all(dim=1)
        return ~finite | (self.qvel.abs().amax(dim=1) > self.settings.max_speed)

    def recover(self, mask, count: bool = True) -> None:
        """Reset the worlds in `mask` to the model's rest pose (zero velocity, zero ctrl, cleared solver
        warm start and pushes), count them, call `reset_fn(mask)` and recompute kinematics. Sync-free:
        runs for every mask, also an all-false one."""
        mask = self.as_mask(mask)
        n = self.num_envs
        rest_q = self.qpos0.expand(n, -1)
        self._write_rows(mask, rest_q, torch.zeros_like(self.qvel), torch.zeros_like(self.ctrl))
        if count:
            self._unstable += mask.sum()
        if self.reset_fn is not None:
            self.reset_fn(mask)
        self._kinematics()

    @property
    def unstable_count(self) -> int:
        """Worlds reset after a blow-up so far (reading it synchronises with the device)."""
        return int(self._unstable)

    # ------------------------------------------------------------------ derived quantities
    @property
    def body_pos(self) -> torch.Tensor:
        """(N, 15, 3) world positions of the body frames, charctl body order."""
        return self.xpos[:, self.body_ids]

    @property
    def body_quat_xyzw(self) -> torch.Tensor:
        """(N, 15, 4) world orientations of the bodies, xyzw, charctl body order."""
        return RT.wxyz_to_xyzw(self.xquat[:, self.body_ids])

    def body_velocities(self) -> tuple[torch.Tensor, torch.Tensor]:
        """World linear velocity of each body frame origin and world angular velocity, (N, 15, 3) each."""
        cv = self.cvel[:, self.body_ids]
        ang, lin_c = cv[..., :3], cv[..., 3:]
        r = self.body_pos - self.subtree_com[:, 1:2]
        return lin_c + torch.cross(ang, r, dim=-1), ang

    def com(self) -> torch.Tensor:
        """(N, 3) whole-body centre of mass, world frame."""
        return self.subtree_com[:, 1]

    def lowest_point_heights(self) -> torch.Tensor:
        """(N, ngeom_char) lowest world y (m) of every character geom (exact for spheres, capsules and boxes)."""
        return lowest_y(
            self.geom_xpos[:, self._geom_ids], self.geom_xmat[:, self._geom_ids], self._geom_type_code, self._geom_size
        )

    def non_foot_ground_contact(self, tol: float = 0.005) -> torch.Tensor:
        """(N,) True where a body other than the feet is within `tol` metres of the ground (a fall)."""
        low = self.lowest_point_heights()
        return (low[:, ~self._is_foot] < tol).any(dim=1)

    def _setup_contact_geoms(self, skel) -> None:
        import mujoco

        m = self.model
        ids = np.array([g for g in range(m.ngeom) if m.geom_bodyid[g] != 0])
        feet = {m.body(n).id for n in FEET}
        code = np.zeros(len(ids), dtype=np.int64)  # 0 sphere, 1 capsule, 2 box
        code[m.geom_type[ids] == mujoco.mjtGeom.mjGEOM_CAPSULE] = 1
        code[m.geom_type[ids] == mujoco.mjtGeom.mjGEOM_BOX] = 2
        dev = self.device
        self._geom_ids = torch.as_tensor(ids, device=dev)
        self._is_foot = torch.as_tensor(np.array([m.geom_bodyid[g] in feet for g in ids]), device=dev)
        self._geom_type_code = torch.as_tensor(code, device=dev)
        self._geom_size = torch.as_tensor(m.geom_size[ids], dtype=torch.float32, device=dev)


def lowest_y(pos: torch.Tensor, mat: torch.Tensor, type_code: torch.Tensor, size: torch.Tensor) -> torch.Tensor:
    """Lowest world-y point (m) of geoms: pos (N, G, 3), mat (N, G, 3, 3), type_code (G,) 0 sphere /
    1 capsule / 2 box, size (G, 3) MuJoCo geom sizes. Torch twin of `charctl.sim.batch._lowest_y`.

    y-extent along world y: sphere r; capsule r + half-length * |R_y,z|; box sum_k |R_y,k| h_k.
    """
    row_y = mat[..., 1, :]  # (N, G, 3) world-y row of each geom frame
    sphere = size[:, 0].expand(pos.shape[:2])
    capsule = size[:, 0] + size[:, 1] * row_y[..., 2].abs()
    box = (row_y.abs() * size).sum(dim=-1)
    ext = torch.where(type_code == 0, sphere, torch.where(type_code == 1, capsule, box))
    return pos[..., 1] - ext
