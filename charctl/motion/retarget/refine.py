"""Retargeting step 5 (docs/motion_import.md): mink refinement of frames whose end effectors are off their
targets or whose bodies are under the ground, plus the residual measures the quality report uses."""

from __future__ import annotations

import numpy as np

from charctl.motion import rotations as R
from charctl.motion.clip import Clip
from charctl.motion.retarget.common import _Y, GROUND_TOL, REFINE_TOL
from charctl.motion.skeleton import END_EFFECTORS


# ---------------------------------------------------------------------------- mink refinement
def lowest_points(clip_or_fk, skel=None) -> np.ndarray:
    """(T, B) lowest world height of each body's collision shape."""
    if isinstance(clip_or_fk, Clip):
        pos, rot = clip_or_fk.fk
        skel = clip_or_fk.skeleton
    else:
        pos, rot = clip_or_fk
    T = pos.shape[0]
    out = np.empty((T, skel.num_bodies))
    for b, g in enumerate(skel.geoms):
        c = np.array(g.pos)
        if g.kind == "sphere":
            pts = c[None]
            r = g.size[0]
        elif g.kind == "capsule":
            r, half = g.size
            pts = np.stack([c + [0, half, 0], c - [0, half, 0]])
        else:
            half = np.array(g.size)
            pts = c + half * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
            r = 0.0
        world = pos[:, b, None, :] + R.rotate(rot[:, b, None, :], np.broadcast_to(pts, (T,) + pts.shape))
        out[:, b] = world[..., 1].min(axis=1) - r
    return out


def _lowest_geom(model, data) -> float:
    """Lowest point (m) of the humanoid's collision geoms in a MuJoCo state (signed distance to the floor)."""
    import mujoco

    floor = model.geom("floor").id
    fromto = np.zeros(6)
    return min(mujoco.mj_geomDistance(model, data, g, floor, 0.5, fromto) for g in range(model.ngeom) if g != floor)


def ee_errors(clip: Clip, targets: dict[str, np.ndarray]) -> np.ndarray:
    """(T, 4) distance (m) of each end effector (END_EFFECTORS order) from its target."""
    pos = clip.body_pos
    sk = clip.skeleton
    return np.stack([np.linalg.norm(pos[:, sk.index(e)] - targets[e], axis=-1) for e in END_EFFECTORS], axis=1)


def refine_clip(clip: Clip, targets: dict[str, np.ndarray], ground: bool = True, max_iters: int = 30):
    """mink IK on the frames whose end effectors miss their targets or (`ground`) that go under the ground."""
    err = ee_errors(clip, targets).max(axis=1)
    low = lowest_points(clip).min(axis=1)
    frames = np.flatnonzero((err > REFINE_TOL) | (ground & (low < -GROUND_TOL)))
    if frames.size == 0:
        return clip, 0, 0
    import mink

    from charctl.sim.humanoid import layout, load_model, local_rot_to_qpos, qpos_to_local_rot

    model = load_model()
    qpos = local_rot_to_qpos(clip.root_pos, clip.local_rot)
    body_pos, body_rot = clip.fk
    cfg = mink.Configuration(model)
    ee_tasks = {
        e: mink.FrameTask(e, "body", position_cost=1.0, orientation_cost=0.3 if "ankle" in e else 0.0, lm_damping=1e-2)
        for e in END_EFFECTORS
    }
    root_task = mink.FrameTask("root", "body", position_cost=0.1, orientation_cost=0.5, lm_damping=1e-2)
    chest_task = mink.FrameTask("chest", "body", position_cost=0.0, orientation_cost=0.5, lm_damping=1e-2)
    posture = mink.PostureTask(model, cost=1e-2)
    tasks = [*ee_tasks.values(), root_task, chest_task, posture]
    limits = [mink.ConfigurationLimit(model)]
    sk = clip.skeleton
    # a body under the ground gets a position task one depth higher (the feet and hands keep theirs)
    lift_tasks = [mink.FrameTask(b, "body", position_cost=2.0, orientation_cost=0.0, lm_damping=1e-2) for b in sk.names]
    depth = np.maximum(-lowest_points(clip), 0.0) if ground else np.zeros((clip.num_frames, sk.num_bodies))
    iters = 0
    lay = layout()
    out = qpos.copy()
    for t in frames:
        cfg.update(qpos[t])
        for e, task in ee_tasks.items():
            b = sk.index(e)
            rot = R.xyzw_to_wxyz(body_rot[t, b])
            task.set_target(mink.SE3.from_rotation_and_translation(mink.SO3(rot), targets[e][t]))
        for task, b in ((root_task, 0), (chest_task, sk.index("chest"))):
            rot = R.xyzw_to_wxyz(body_rot[t, b])
            task.set_target(mink.SE3.from_rotation_and_translation(mink.SO3(rot), body_pos[t, b]))
        posture.set_target(qpos[t])
        lifts = []
        for b in np.flatnonzero(depth[t] > GROUND_TOL):
            lift = body_pos[t, b] + (depth[t, b] + 0.002) * _Y
            lift_tasks[b].set_target(mink.SE3.from_rotation_and_translation(mink.SO3.identity(), lift))
            lifts.append(lift_tasks[b])
        for _ in range(max_iters):
            v = mink.solve_ik(cfg, tasks + lifts, 1.0, "daqp", damping=1e-4, limits=limits)
            cfg.integrate_inplace(v, 1.0)
            iters += 1
            worst = max(np.linalg.norm(cfg.data.xpos[model.body(e).id] - targets[e][t]) for e in END_EFFECTORS)
            if worst < 0.5 * REFINE_TOL and (not ground or _lowest_geom(model, cfg.data) > -0.5 * GROUND_TOL):
                break
        out[t] = cfg.q
    assert out.shape[1] == lay.nq
    root_pos, local = qpos_to_local_rot(out)
    return clip.replace(root_pos=root_pos, local_rot=R.continuous_sign(local)), int(frames.size), iters
