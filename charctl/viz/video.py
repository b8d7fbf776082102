"""Offscreen MuJoCo rendering to mp4 (imageio-ffmpeg's bundled ffmpeg).

Headless machines render through OSMesa (`MUJOCO_GL=osmesa`, Debian package libosmesa6,
installed by `make install`) or EGL (`MUJOCO_GL=egl` on a GPU box). A machine that cannot
render gets a one-line `CharctlError` saying what to install, never a traceback.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError


def _ensure_gl_backend() -> None:
    if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
        os.environ["MUJOCO_GL"] = "osmesa"
    if os.environ.get("MUJOCO_GL") == "osmesa":
        os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")


def camera_id(model, camera: str | int | None) -> int:
    """MuJoCo camera id of `camera`: a camera name of the model (-1, the free camera, when it has none of
    that name), an id as given, or -1 for None."""
    if camera is None:
        return -1
    if isinstance(camera, str):
        try:
            return model.camera(camera).id
        except KeyError:
            return -1
    return camera


def make_renderer(model, width: int = 640, height: int = 360):
    """A mujoco.Renderer, or a one-line CharctlError explaining how to enable rendering."""
    _ensure_gl_backend()
    try:
        import mujoco

        return mujoco.Renderer(model, height=height, width=width)
    except Exception as exc:  # missing libOSMesa / EGL, no display ...
        backend = os.environ.get("MUJOCO_GL", "default")
        raise CharctlError(
            f"cannot render with MUJOCO_GL={backend} ({str(exc).splitlines()[0][:100]}); "
            "install Debian's libosmesa6 (`make render-deps`) or set MUJOCO_GL=egl on a GPU machine"
        ) from None


def check_can_render() -> None:
    """A one-line CharctlError now if this machine cannot render (so a command that writes a video checks
    this before any of its other files is written)."""
    from charctl.sim.humanoid import load_model

    make_renderer(load_model(), 32, 32).close()


def write_video(frames: list[np.ndarray], path: str | Path, fps: float) -> Path:
    """Write HxWx3 uint8 frames as an H.264 mp4 (atomic: temp file then rename)."""
    import imageio.v2 as imageio

    path = Path(path)
    if not frames:
        raise CharctlError("no frames to write")
    tmp = path.with_name(path.stem + ".tmp" + path.suffix)
    from charctl.paths import check_output_file

    check_output_file(path, "video")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with imageio.get_writer(
            tmp, fps=float(fps), codec="libx264", quality=7, macro_block_size=8, ffmpeg_log_level="quiet"
        ) as w:
            for f in frames:
                w.append_data(np.asarray(f, dtype=np.uint8))
        if not tmp.is_file() or tmp.stat().st_size == 0:  # ffmpeg died without an error imageio noticed
            raise RuntimeError(f"{_ffmpeg_exe()} wrote no video")
        os.replace(tmp, path)
    except Exception as exc:  # ffmpeg missing or failing, a read-only folder, a full disk ...
        if tmp.exists():
            tmp.unlink()
        if isinstance(exc, OSError) and exc.strerror:
            cause = exc.strerror
        else:
            lines = [ln.strip() for ln in str(exc).strip().splitlines() if ln.strip()]
            cause = f"ffmpeg failed: {(lines[0] if lines else type(exc).__name__)[:160]}"
        raise CharctlError(f"cannot write video {path}: {cause}") from None
    return path


def _ffmpeg_exe() -> str:
    try:
        import imageio_ffmpeg

        return imageio_ffmpeg.get_ffmpeg_exe()
    except Exception:  # noqa: BLE001
        return "ffmpeg"


def render_qpos(
    model,
    qpos: np.ndarray,
    path: str | Path,
    fps: float,
    width: int = 640,
    height: int = 360,
    camera: str | int | None = "side",
    annotate: Callable[[object, int], None] | None = None,
) -> dict:
    """Render a (T, nq) qpos sequence of `model` (kinematic playback) to an mp4.

    `camera` names a camera of the model (the humanoid has tracking cameras "side" and
    "front"); None uses MuJoCo's default free camera. `annotate(scene, t)` may add geoms (e.g.
    force arrows) to the scene before each frame is drawn. Returns frame count and render fps.
    """
    import mujoco

    renderer = make_renderer(model, width, height)
    data = mujoco.MjData(model)
    cam = camera_id(model, camera)
    frames = []
    t0 = time.perf_counter()
    try:
        for t in range(qpos.shape[0]):
            data.qpos[:] = qpos[t]
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, camera=cam if cam is not None else -1)
            if annotate is not None:
                annotate(renderer.scene, t)
            frames.append(renderer.render().copy())
    finally:
        renderer.close()
    render_fps = len(frames) / max(time.perf_counter() - t0, 1e-9)
    write_video(frames, path, fps)
    return {"frames": len(frames), "render_fps": render_fps, "path": str(path)}


def render_clip(clip, path: str | Path, fps: float | None = None, width: int = 640, height: int = 360) -> dict:
    """Kinematic playback of a humanoid clip (resampled to `fps` if given) as an mp4."""
    from charctl.sim.humanoid import load_model, local_rot_to_qpos

    if fps is not None:
        if fps <= 0:
            raise CharctlError(f"--fps must be positive, got {fps}")
        clip = clip.resample(fps)
    qpos = local_rot_to_qpos(clip.root_pos, clip.local_rot)
    return render_qpos(load_model(), qpos, path, clip.fps, width, height)
