"""`charctl export RUN --com-path FILE.csv|circle:r=2,speed=1.2 [--crouch-at T] --bvh OUT.bvh --video OUT.mp4`:
full-body motion from a seed history and a user's COM path (paper §5: "the user drags the COM").

Frames: the seed clip (generate.seed_clip, its first `history` frames) is placed so that its last
frame stands at the origin facing +z; the COM path is world coordinates in that frame (y up,
metres), translated horizontally so that its first point is the seed's last COM. Procedural paths
start there heading +z. The paper's safety (§5) clamps each input COM to at most
generate.max_com_step metres from the previous input, keeping the direction.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.experiments.com_cnn.body import BodyModel
from charctl.experiments.com_cnn.com_path import make_com_path
from charctl.experiments.com_cnn.data import heading_frame
from charctl.experiments.com_cnn.rollout import Buffer, ReferenceFn, previous_root_reference, rollout
from charctl.experiments.com_cnn.sequences import XZ, Sequence, canonical_start, heading_yaw, make_sequence
from charctl.motion import rotations as R


# ---------------------------------------------------------------------------- seed and references
def seed_sequence(run) -> Sequence:
    """The seed clip through the dataset pipeline (30 fps, tiled if looping), placed so its frame
    `history - 1` stands at the origin facing +z."""
    name = str(run.cfg.generate.seed_clip)
    seq = next((s for s in run.seqs if s.name == name), None)
    if seq is None:
        if run.body.kind != "humanoid":
            raise CharctlError(
                f"generate.seed_clip={name!r} is not among the clips of "
                f"data.bvh_dir ({', '.join(s.name for s in run.seqs[:6])}, ...)"
            )
        from charctl.motion.library import load_clip

        clip = load_clip(name).resample(run.cfg.data.fps)
        seq = make_sequence(
            clip.name,
            name,
            clip.label,
            clip.fps,
            clip.root_pos,
            clip.local_rot[:, 0],
            clip.local_rot[:, 1:],
            clip.loop,
            run.cfg.data,
            run.body,
        )
    L = min(int(run.cfg.data.history), seq.num_frames)
    pos, rot = canonical_start(
        seq.root_pos[:L][::-1], seq.root_rot[:L][::-1], run.body.forward
    )  # last frame -> origin, +z
    pos, rot, joints = pos[::-1].copy(), rot[::-1].copy(), seq.joint_rot[:L]
    out = Sequence(seq.name, seq.base, seq.label, seq.fps, pos, rot, joints)
    out.com = run.body.com(pos, rot, joints)
    return out


def estimated_root_reference(
    body: BodyModel, com_all: np.ndarray, first: int, window: int, min_speed: float, fps: float
) -> ReferenceFn:
    """data.frame=root_t without ground truth: estimate the root's heading frame at t from the COM path.

    Heading: the previous root heading turned by as much as the COM's direction of travel turned
    over `window` frames (held when the COM moves slower than `min_speed`), so walking sideways or
    backwards keeps its offset. Position: C_t minus the previous frame's horizontal COM-to-root
    offset (in its heading frame), rotated by the new heading. com_all (B, L, 3) holds the seed's
    COM followed by the path; `first` is the buffer index of the first generated frame.
    """
    step_min = min_speed * window / fps

    def direction(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.arctan2(a[..., 0], a[..., 2]), np.linalg.norm(a[..., [0, 2]], axis=-1)

    def ref(k: int, s: int, buf: Buffer, com_t: np.ndarray):
        pos, rot = buf.root_pos[:, s - 1], buf.root_rot[:, s - 1]
        joints = R.exp_map(buf.joint_exp[:, s - 1].reshape(pos.shape[0], -1, 3))
        _, q_prev = heading_frame(pos, rot, body.forward)
        yaw_prev = heading_yaw(rot, body.forward)
        offset = R.rotate(R.conjugate(q_prev), (body.com(pos, rot, joints) - pos) * XZ)
        c = first + k  # index of C_t in com_all
        a_now, n_now = direction(com_all[:, c] - com_all[:, max(c - window, 0)])
        a_prev, n_prev = direction(com_all[:, c - 1] - com_all[:, max(c - 1 - window, 0)])
        turn = np.where((n_now > step_min) & (n_prev > step_min), np.angle(np.exp(1j * (a_now - a_prev))), 0.0)
        q = R.heading_quat(yaw_prev + turn)
        return (com_t - R.rotate(q, offset)) * XZ, q

    return ref


def reference_for_generation(run, com_all: np.ndarray, first: int) -> ReferenceFn:
    if run.cfg.data.frame == "root_prev":
        return previous_root_reference(run.body)
    g = run.cfg.generate
    return estimated_root_reference(
        run.body, com_all, first, int(g.heading_window), float(g.min_com_speed), float(run.cfg.data.fps)
    )


def generate(run, com_path: np.ndarray, seed: Sequence) -> tuple[Buffer, float]:
    """Generated frames (batch 1) for a COM path (H, 3) after `seed`, and the wall time in seconds."""
    pred = run.predictor()
    i = pred.history
    seed_buf = Buffer(
        seed.root_pos[None], seed.root_rot[None], R.log_map(seed.joint_rot).reshape(1, seed.num_frames, -1)
    )
    pad = max(i - seed.num_frames, 0)
    com_all = np.concatenate([np.repeat(seed.com[:1], pad, 0), seed.com, com_path])[None]
    t0 = time.perf_counter()
    gen = rollout(
        pred, run.body, seed_buf, com_path[None], reference_for_generation(run, com_all, pad + seed.num_frames)
    )
    return gen, time.perf_counter() - t0


def generate_motion(run, spec: str, seconds: float, crouch_at: float | None) -> dict:
    """Seed + COM path -> the whole motion (seed frames first) and its numbers (speed, COM tracking)."""
    fps = float(run.cfg.data.fps)
    seed = seed_sequence(run)
    com_path = make_com_path(spec, seed.com[-1], seconds, fps, crouch_at, run.cfg.generate)
    generate(run, com_path[:3], seed)  # warm-up (first-call allocations)
    gen, wall = generate(run, com_path, seed)
    n = gen.joint_exp.shape[1]
    root_pos = np.concatenate([seed.root_pos, gen.root_pos[0]])
    root_rot = np.concatenate([seed.root_rot, gen.root_rot[0]])
    joint_rot = np.concatenate([seed.joint_rot, R.exp_map(gen.joint_exp[0].reshape(n, -1, 3))])
    com_out = run.body.com(root_pos, root_rot, joint_rot)
    L, H = seed.num_frames, com_path.shape[0]
    err = np.linalg.norm(com_out[L:] - com_path, axis=1)
    return {
        "seed": seed,
        "com_path": com_path,
        "root_pos": root_pos,
        "root_rot": root_rot,
        "joint_rot": joint_rot,
        "com_out": com_out,
        "stats": {
            "path": spec,
            "crouch_at_s": crouch_at,
            "seed_clip": seed.name,
            "seed_frames": L,
            "frames": H,
            "wall_s": wall,
            "frames_per_s": H / wall,
            "real_time_factor": H / wall / fps,
            "com_tracking_error_m": float(err.mean()),
            "com_tracking_error_max_m": float(err.max()),
            "input_com_height_m": [float(com_path[:, 1].min()), float(com_path[:, 1].max())],
            "root_height_m": [float(root_pos[L:, 1].min()), float(root_pos[L:, 1].max())],
        },
    }


def generation_demo(run, figure: Path | None = None) -> dict:
    """eval: a circle (r 2 m, 1.2 m/s) with a crouch at 60 % of eval.speed_frames frames, batch 1, CPU."""
    fps = float(run.cfg.data.fps)
    seconds = int(run.cfg.eval.speed_frames) / fps
    out = generate_motion(run, "circle:r=2,speed=1.2", seconds, round(0.6 * seconds, 2))
    if figure is not None:
        plot_generation(out, fps, figure)
    return out["stats"]


# ---------------------------------------------------------------------------- outputs
def frames_to_clip(run, name: str, root_pos, root_rot, joint_rot):
    """A charctl Clip of the humanoid (for write_bvh / render_clip)."""
    from charctl.motion.clip import Clip

    local = np.concatenate([root_rot[:, None], joint_rot], axis=1)
    return Clip(
        name=name,
        fps=float(run.cfg.data.fps),
        root_pos=root_pos,
        local_rot=local,
        label="generated",
        skeleton=run.body.skeleton,
    )


def write_generic_bvh(body: BodyModel, root_pos, root_rot, joint_rot, fps: float, path: Path) -> Path:
    """BVH in the source skeleton's hierarchy and channel order (data.bvh_dir runs)."""
    from scipy.spatial.transform import Rotation

    local = np.concatenate([root_rot[:, None], joint_rot], axis=1)
    T = local.shape[0]
    offsets = body.skeleton.offsets / body.bvh_scale
    cols = []
    for j, chans in enumerate(body.bvh_channels):  # write time, not a hot path
        rot_ch = [c for c in chans if c.lower().endswith("rotation")]
        eul = (
            Rotation.from_quat(local[:, j]).as_euler("".join(c[0].upper() for c in rot_ch), degrees=True)
            if rot_ch
            else None
        )
        for c in chans:
            axis = "XYZ".index(c[0].upper())
            if c.lower().endswith("position"):
                cols.append(root_pos[:, axis] / body.bvh_scale if j == 0 else np.full(T, offsets[j, axis]))
            else:
                cols.append(eul[:, rot_ch.index(c)])
    data = np.stack(cols, axis=1)
    text = (
        body.bvh_header
        + f"MOTION\nFrames: {T}\nFrame Time: {1.0 / fps:.8f}\n"
        + "\n".join(" ".join(f"{v:.6f}" for v in row) for row in data)
        + "\n"
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def render_with_com(clip, com: np.ndarray, path: Path) -> dict:
    """Kinematic playback of the humanoid with the input COM drawn as a purple ball (paper Fig. 1)."""
    import mujoco

    from charctl.sim.humanoid import load_model, local_rot_to_qpos
    from charctl.viz.video import render_qpos

    purple = np.array([0.6, 0.2, 0.8, 0.9], dtype=np.float32)
    z_up_to_y_up = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]).ravel()  # cylinder axis along world +y

    def annotate(scene, t: int) -> None:
        ball = (mujoco.mjtGeom.mjGEOM_SPHERE, np.array([0.06, 0.0, 0.0]), com[t], np.eye(3).ravel())
        shadow = (
            mujoco.mjtGeom.mjGEOM_CYLINDER,
            np.array([0.07, 0.003, 0.0]),
            com[t] * [1.0, 0.0, 1.0] + [0, 0.004, 0],
            z_up_to_y_up,
        )
        for kind, size, pos, mat in (ball, shadow):
            if scene.ngeom < scene.maxgeom:
                mujoco.mjv_initGeom(scene.geoms[scene.ngeom], kind, size, pos, mat, purple)
                scene.ngeom += 1

    qpos = local_rot_to_qpos(clip.root_pos, clip.local_rot)
    return render_qpos(load_model(), qpos, path, clip.fps, annotate=annotate)


def plot_generation(out: dict, fps: float, path: Path) -> None:
    """Top view of the input COM, the body's COM and the root; and heights against time."""
    from charctl.viz.plots import new_figure, save_figure

    com_in, com_out, root, L = out["com_path"], out["com_out"], out["root_pos"], out["seed"].num_frames
    fig, (ax, bx) = new_figure(1, 2, figsize=(10, 4.5))
    ax.plot(com_out[:L, 0], com_out[:L, 2], color="gray", label="seed (data)")
    ax.plot(com_in[:, 0], com_in[:, 2], "k--", lw=1, label="input COM (clamped)")
    ax.plot(com_out[L:, 0], com_out[L:, 2], label="generated body COM")
    ax.plot(root[L:, 0], root[L:, 2], lw=0.8, label="generated root")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=7)
    ax.set_title("top view")
    t = (np.arange(com_out.shape[0]) - L + 1) / fps
    bx.plot(t[L:], com_in[:, 1], "k--", lw=1, label="input COM height")
    bx.plot(t, com_out[:, 1], label="body COM height")
    bx.plot(t, root[:, 1], lw=0.8, label="root height")
    bx.axvline(0.0, color="gray", lw=0.5)
    bx.set_xlabel("time since the seed ended (s)")
    bx.set_ylabel("height (m)")
    bx.legend(fontsize=7)
    bx.set_title("heights")
    save_figure(fig, path)
