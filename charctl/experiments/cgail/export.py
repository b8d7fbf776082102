"""`charctl export RUN --onnx F | --torchscript F | --bvh F | --video F [--commands S] | --web DIR [--serve]`
and `charctl play`.

The exported policy takes the raw state (243) and, for cGAIL, the command blend c̄ (K) and
returns the mean action (28 PD-target offsets, radians); the observation normaliser is inside.
A command schedule "walk:0,run:3,right_kick:6" (skill:start second) drives a rollout that is
written as BVH (kinematic record of the simulated character) and/or mp4. `--web DIR` writes the
interactive web demo (`web_site.py`, docs/web.md), whose ONNX graph also computes the state from
MuJoCo's arrays (`web_graph.py`); `--serve` then serves it on a local port.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from torch import nn

from charctl.errors import CharctlError
from charctl.experiments.cgail.drive import policy_steps
from charctl.experiments.cgail.env import CgailEnv
from charctl.experiments.cgail.policy import TrainedRun, load_trained_run, resolve_run_dirs

WHAT_TO_EXPORT = "say what to export: --onnx FILE, --torchscript FILE, --bvh FILE, --video FILE or --web DIR"


class ExportedPolicy(nn.Module):
    """state (B, 243) [, command blend (B, K)] -> mean action (B, 28); normaliser built in."""

    def __init__(self, tr: TrainedRun):
        super().__init__()
        m = tr.agent.model
        self.norm_mean = nn.Parameter(m.obs_norm.mean.clone(), requires_grad=False)
        self.norm_std = nn.Parameter(torch.sqrt(m.obs_norm.var + m.obs_norm.eps).clone(), requires_grad=False)
        self.clip = float(m.obs_norm.clip)
        self.actor = m.actor
        self.conditional = tr.agent.conditional

    def forward(self, state: torch.Tensor, command: torch.Tensor) -> torch.Tensor:
        x = torch.clamp((state - self.norm_mean) / self.norm_std, -self.clip, self.clip)
        if self.conditional:
            x = torch.cat([x, command], dim=-1)
        return self.actor(x)


def _example_inputs(tr: TrainedRun, batch: int = 2) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    state = tr.agent.model.obs_norm.mean + torch.randn(batch, tr.agent.model.obs_dim, generator=g)
    cmd = torch.zeros(batch, len(tr.skill_names))
    cmd[:, 0] = 1.0
    return state, cmd


def export_onnx(tr: TrainedRun, path: Path) -> Path:
    model = ExportedPolicy(tr).eval()
    state, cmd = _example_inputs(tr)
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.onnx.export(
        model,
        (state, cmd),
        str(path),
        input_names=["state", "command"],
        output_names=["action"],
        dynamic_axes={"state": {0: "batch"}, "command": {0: "batch"}, "action": {0: "batch"}},
        dynamo=False,
    )
    return path


def export_torchscript(tr: TrainedRun, path: Path) -> Path:
    model = ExportedPolicy(tr).eval()
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.jit.script(model).save(str(path))
    return path


def parse_schedule(text: str, names: list[str]) -> list[tuple[float, int]]:
    """ "walk:0,run:3" -> [(0.0, k_walk), (3.0, k_run)], sorted by time; one-line errors."""
    out = []
    for item in text.split(","):
        if ":" not in item:
            raise CharctlError(f"bad --commands item {item!r}: use skill:seconds, e.g. walk:0,run:3")
        name, t = item.rsplit(":", 1)
        name = name.strip()
        if name not in names:
            raise CharctlError(f"--commands names unknown skill {name!r}; the run's skills are {', '.join(names)}")
        try:
            sec = float(t)
        except ValueError:
            raise CharctlError(f"bad time {t!r} in --commands item {item!r}") from None
        if not np.isfinite(sec) or sec < 0:
            raise CharctlError(f"bad time {t!r} in --commands item {item!r}: seconds must be finite and >= 0")
        out.append((sec, names.index(name)))
    return sorted(out)


@torch.no_grad()
def schedule_rollout(tr: TrainedRun, schedule: list[tuple[float, int]], seconds: float) -> tuple[np.ndarray, dict]:
    """One character following the command schedule; returns qpos (T, nq) and stats."""
    env = tr.held_env([schedule[0][1]], seconds + 10)
    hz = env.cfg.control_hz
    qpos = [env.sim.qpos[0].copy()]
    falls = 0
    for step in policy_steps(tr.agent, env, int(seconds * hz), before_step=_command_schedule(env, schedule[1:])):
        falls += int(step.result.terminated[0])
        qpos.append(env.sim.qpos[0].copy())
    return np.array(qpos), {"falls": falls, "fps": hz}


def _command_schedule(env: CgailEnv, pending: list[tuple[float, int]]) -> Callable[[int], None]:
    """`before_step` of a one-character env following `pending` (start second, skill), sorted by time: before
    control step t, each entry whose second is <= t / hz is commanded (ramped) in turn, then dropped."""
    pending = list(pending)
    hz = env.cfg.control_hz

    def before_step(t: int) -> None:
        while pending and t / hz >= pending[0][0]:
            _, k = pending.pop(0)
            env.set_command(np.array([0]), k, ramp=True)
            env.forced_command = np.array([k])

    return before_step


def export(target: str, options: dict, overrides: list[str]) -> None:
    """--onnx / --torchscript of the policy, --bvh / --video of a commanded rollout (--commands, --seconds),
    --web DIR: the interactive web demo (--serve: then serve it)."""
    (run_dir,) = resolve_run_dirs([target], overrides, "export")
    if options.get("serve") and not options.get("web"):
        raise CharctlError("--serve serves the site --web DIR writes: give --web DIR too")
    if not any(options.get(k) for k in ("onnx", "torchscript", "bvh", "video", "web")):
        raise CharctlError(WHAT_TO_EXPORT)
    if options.get("web"):
        from charctl.experiments.cgail.web_site import check_web_sources

        check_web_sources()  # before the run is loaded: the npm packages the site copies are installed
    tr = load_trained_run(run_dir, options.get("checkpoint"))
    # every argument is checked before anything is written (the schedule names the run's skills)
    names = tr.skill_names
    schedule = parse_schedule(options.get("commands") or f"{names[0]}:0", names)
    if not tr.agent.conditional and len({k for _, k in schedule}) > 1:
        raise CharctlError(
            f"{run_dir} is an AMP run (cgail.conditional=false): its policy has no command input, so a schedule "
            "that changes the skill changes nothing it sees; give one skill (--commands SKILL:0 starts in that "
            "skill's clip)"
        )
    if options.get("web") and tr.cfg.reward.kind == "tracking":
        raise CharctlError(
            f"{run_dir} is a tracking run: its policy needs the reference clip's phase, which the web demo "
            "does not play; export a cgail (adversarial) run"
        )
    if options.get("video"):
        from charctl.viz.video import check_can_render

        check_can_render()  # a machine that cannot render says so before the other files are written
    if options.get("onnx"):
        print(f"wrote {export_onnx(tr, Path(options['onnx']))}")
    if options.get("torchscript"):
        print(f"wrote {export_torchscript(tr, Path(options['torchscript']))}")
    if options.get("bvh") or options.get("video"):
        _write_rollout(tr, schedule, options)
    if options.get("web"):
        _write_web(tr, options)


def _write_rollout(tr, schedule: list[tuple[float, str]], options: dict) -> None:
    """--bvh / --video: one rollout of the command schedule (seconds, skill) for --seconds (default: the last
    switch + 3 s), written as a BVH clip at the control rate and/or an MP4."""
    seconds = float(options.get("seconds") or (schedule[-1][0] + 3.0))
    qpos, stats = schedule_rollout(tr, schedule, seconds)
    if options.get("bvh"):
        from charctl.motion.bvh import write_bvh
        from charctl.motion.clip import Clip
        from charctl.sim.humanoid import qpos_to_local_rot

        root, rot = qpos_to_local_rot(qpos, tr.cfg.env.shoulder_frame)
        clip = Clip(name="cgail_rollout", fps=stats["fps"], root_pos=root, local_rot=rot)
        print(f"wrote {write_bvh(clip, options['bvh'])} ({len(qpos)} frames, falls: {stats['falls']})")
    if options.get("video"):
        from charctl.sim.humanoid import load_model
        from charctl.viz.video import render_qpos

        info = render_qpos(
            load_model(tr.cfg.env.physics_hz, armature=tr.cfg.env.armature, shoulder_frame=tr.cfg.env.shoulder_frame),
            qpos,
            options["video"],
            stats["fps"],
        )
        print(f"wrote {options['video']} ({info['frames']} frames, falls: {stats['falls']})")


def _write_web(tr, options: dict) -> None:
    """--web DIR: the interactive web demo's site (--serve: then serve it)."""
    from charctl.experiments.cgail.web_site import serve, write_site

    out = Path(options["web"])
    info = write_site(tr, out, options.get("checkpoint"))
    how = (
        "" if options.get("serve") else f": serve it with any static file server, e.g. python3 -m http.server -d {out}"
    )
    print(f"wrote {out} ({info['files']} files, {info['bytes'] / 1e6:.1f} MB){how}")
    if options.get("serve"):
        serve(out)


def _display_problem() -> str | None:
    """Why no viewer window can open here (no DISPLAY, a display that does not answer, no GLFW), or None."""
    import os
    import warnings

    display = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    if not display:
        return "no display (DISPLAY is not set)"
    if os.environ.get("MUJOCO_GL", "glfw") != "glfw":
        return f"MUJOCO_GL={os.environ['MUJOCO_GL']} renders offscreen only"
    try:
        import glfw
    except Exception as exc:  # noqa: BLE001  the glfw package or its library is missing
        return f"GLFW is not available ({str(exc).splitlines()[0][:80] if str(exc) else type(exc).__name__})"
    old = getattr(glfw, "ERROR_REPORTING", None)
    try:
        glfw.ERROR_REPORTING = "ignore"  # no "GLFWError" warning on stderr: the one-line error says it
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ok = glfw.init()
            if ok:
                glfw.terminate()
    except Exception:  # noqa: BLE001
        ok = False
    finally:
        glfw.ERROR_REPORTING = old
    return None if ok else f"cannot open a window on display {display!r} (GLFW could not initialise)"


def _record_hint(run_dir) -> str:
    """`charctl export RUN --video out.mp4 --commands "walk:0,run:3"` with the run's own skills."""
    names: list[str] = []
    try:
        from charctl.runs import read_run_config

        cfg = read_run_config(run_dir)
        names = [str(n) for n in (cfg.get("use_skills") or [])] or [str(s.name) for s in cfg.get("skills") or []]
    except Exception:  # noqa: BLE001  the hint is best effort; the run is checked when it is loaded
        pass
    schedule = ",".join(f"{n}:{3 * i}" for i, n in enumerate(names[:3])) or "walk:0"
    return f'charctl export {run_dir} --video out.mp4 --commands "{schedule}"'


def play(run_dir) -> None:
    """Interactive viewer: keys 1..9 switch the command (needs a display)."""
    problem = _display_problem()
    if problem:
        raise CharctlError(f"{problem}; record a rollout instead: {_record_hint(run_dir)}")
    import time

    import mujoco.viewer

    tr = load_trained_run(run_dir)
    env = tr.make_env(1, seed=0, switch_prob=0.0, episode_seconds=1e6)
    env.forced_command = np.array([0])
    env.reset(np.array([0]))
    model = env.sim.model
    data = env.sim.batch.get_data(0)
    names = tr.skill_names
    print("keys: " + ", ".join(f"{i + 1}={n}" for i, n in enumerate(names[:9])))

    def on_key(key: int) -> None:
        k = key - ord("1")
        if 0 <= k < len(names):
            env.set_command(np.array([0]), k, ramp=True)
            env.forced_command = np.array([k])
            print(f"command: {names[k]}")

    steps = policy_steps(tr.agent, env)  # no end: one control step per frame while the viewer is open
    with mujoco.viewer.launch_passive(model, data, key_callback=on_key) as viewer:
        while viewer.is_running():
            t0 = time.perf_counter()
            next(steps)
            env.sim.batch.get_data(0, data)
            mujoco.mj_forward(model, data)
            viewer.sync()
            time.sleep(max(0.0, 1.0 / env.cfg.control_hz - (time.perf_counter() - t0)))
