"""`charctl export SRB_RUN --video FILE`: video of the trained SRB, the box, its feet (contact
points) and the contact forces as arrows, walking and being pushed (the push drawn as a red arrow
at the COM).

MuJoCo is used only to draw: a model with three free bodies (box, right foot, left foot) is posed
kinematically from the recorded trajectory (no MuJoCo dynamics) and rendered with
charctl.viz.video.render_qpos.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.experiments import latest_run_dir
from charctl.experiments.srb.push import PushCase
from charctl.experiments.srb.rollout import simulate_chunk
from charctl.sim.scene import scene_assets, scene_ground

FORCE_SCALE = 1.0 / 500.0  # m of arrow per newton (a 60 kg body's weight ~ 1.2 m)


def srb_mjcf(half_extents: np.ndarray, foot_half_length: float) -> str:
    hx, hy, hz = half_extents
    fl = foot_half_length
    feet = "".join(
        f'<body name="{name}" pos="0 0 0"><freejoint/>'
        f'<geom type="box" size="{fl:.4f} 0.02 0.045" rgba="{rgba}" contype="0" conaffinity="0"/></body>'
        for name, rgba in (("right_foot", "0.85 0.45 0.35 1"), ("left_foot", "0.35 0.55 0.85 1"))
    )
    return f"""<mujoco model="srb">
  <visual><global offwidth="1280" offheight="720"/><quality shadowsize="2048"/></visual>
  <asset>
{scene_assets(40)}
  </asset>
  <worldbody>
{scene_ground(40, collides=False)}
    <body name="box" pos="0 1 0"><freejoint/>
      <geom type="box" size="{hx:.4f} {hy:.4f} {hz:.4f}" rgba="0.8 0.8 0.78 0.85" contype="0" conaffinity="0"/>
      <camera name="side" mode="trackcom" pos="-2.4 1.0 2.8" xyaxes="0.759 0 0.651 0.164 0.968 -0.191"/>
    </body>
    {feet}
  </worldbody>
</mujoco>"""


def trace_to_qpos(trace: dict, env_index: int = 0) -> np.ndarray:
    """(T, 21) qpos: box (pos, quat wxyz), right and left foot bodies at their contact midpoints."""
    pos, rot, feet = trace["pos"][:, env_index], trace["rot"][:, env_index], trace["feet"][:, env_index]
    t = pos.shape[0]
    q = np.zeros((t, 21))
    q[:, :3] = pos
    q[:, 3:7] = np.concatenate([rot[:, 3:4], rot[:, :3]], axis=1)
    for j in range(2):
        heel, toe = feet[:, 2 * j], feet[:, 2 * j + 1]
        mid = 0.5 * (heel + toe) + np.array([0.0, 0.02, 0.0])
        d = toe - heel
        yaw = np.arctan2(-d[:, 2], d[:, 0])
        s = 7 + 7 * j
        q[:, s : s + 3] = mid
        q[:, s + 3 : s + 7] = np.stack([np.cos(yaw / 2), np.zeros(t), np.sin(yaw / 2), np.zeros(t)], axis=1)
    return q


def _arrow(scene, start: np.ndarray, end: np.ndarray, rgba, width: float = 0.025) -> None:
    import mujoco

    if scene.ngeom >= scene.maxgeom or np.linalg.norm(end - start) < 1e-4:
        return
    g = scene.geoms[scene.ngeom]
    mujoco.mjv_initGeom(
        g, mujoco.mjtGeom.mjGEOM_ARROW, np.zeros(3), np.zeros(3), np.eye(3).ravel(), np.asarray(rgba, dtype=np.float32)
    )
    mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_ARROW, width, start.astype(float), end.astype(float))
    scene.ngeom += 1


def render_push_video(run, path: str | Path, seconds: float = 6.0) -> dict:
    """Roll out the trained policy (deterministic) for about `seconds` with one push (400 N to the
    left for 0.2 s after 1.5 s, at gait phase 0.25) and render it with the contact forces as green
    arrows at the contact points and the push as a red arrow into the COM."""
    import mujoco

    from charctl.experiments.srb.env import SRBEnv
    from charctl.experiments.srb.train import load_policy, policy_actions
    from charctl.viz.video import render_qpos

    agent, _ = load_policy(run)
    env = SRBEnv(run.cfg, 1, seed=0, auto_reset=False, max_steps=10**9)
    first = PushCase(
        "impulse", 400.0, 0.2, 90.0, 0.25, settle_s=1.5, observe_s=max(seconds - 1.5 - 0.2 - env.ref.cycle_seconds, 0.5)
    )
    _, trace = simulate_chunk(env, agent.model, [(first, 0)], 0.0, policy_actions, record=True, seconds=seconds)
    model = mujoco.MjModel.from_xml_string(srb_mjcf(env.body.half_extents, env.body.foot_half_length))
    qpos = trace_to_qpos(trace)

    def annotate(scene, t: int) -> None:
        feet, forces = trace["feet"][t, 0], trace["forces"][t, 0]
        for c in range(4):
            _arrow(scene, feet[c], feet[c] + forces[c] * FORCE_SCALE, (0.1, 0.75, 0.2, 1.0))
        push = trace["push"][t, 0]
        if np.linalg.norm(push) > 0:
            com = trace["pos"][t, 0]
            _arrow(scene, com - push * FORCE_SCALE, com, (0.9, 0.1, 0.1, 1.0), width=0.04)

    info = render_qpos(model, qpos, path, fps=1.0 / float(trace["dt"]), camera="side", annotate=annotate)
    start = float(trace["start"][0])
    info["pushes"] = (
        f"{first.force_n:.0f} N to the left for {first.duration_s:g} s at t = {start:.2f} s"
        if np.isfinite(start)
        else "none (video shorter than the push onset)"
    )
    return info


def export(target: str, options: dict, overrides: list[str]) -> None:
    """`--video FILE [--seconds S]`: the trained SRB walking and being pushed."""
    if not options.get("video"):
        raise CharctlError("srb exports --video (the box, its feet and contact forces walking and being pushed)")
    from charctl.experiments.srb.config import Config
    from charctl.runs import open_run

    run_dir = latest_run_dir("srb", overrides) if target == "srb" else Path(target)
    run = open_run(run_dir, Config, overrides)
    seconds = float(options.get("seconds") or 6.0)
    if seconds <= 0:
        raise CharctlError("--seconds must be positive")
    info = render_push_video(run, options["video"], seconds)
    print(f"wrote {options['video']} ({info['frames']} frames, pushes: {info['pushes']})")
