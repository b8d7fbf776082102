"""The COM path a user gives `charctl export RUN --com-path` (com-cnn, paper §5: "the user drags the COM"): a CSV
file or a procedural circle/line, placed in the seed's frame (y up, metres; generate.py's module docstring), and the
paper's safety clamp of each input COM to at most generate.max_com_step metres from the previous one."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.experiments.com_cnn.sequences import XZ


# ---------------------------------------------------------------------------- the safety clamp
def clamp_com_path(path: np.ndarray, start: np.ndarray, max_step: float) -> np.ndarray:
    """(H, 3) path whose every point is at most `max_step` m from the previous (clamped) one, same direction.

    c'_k = c'_{k-1} + d * min(1, max_step / |d|), d = c_k - c'_{k-1}, c'_{-1} = start (paper §5).
    Sequential by nature: each point depends on the clamped one before it.
    """
    out = np.empty_like(path, dtype=float)
    prev = np.asarray(start, dtype=float)
    for k in range(path.shape[0]):
        d = path[k] - prev
        n = float(np.linalg.norm(d))
        prev = prev + (d * (max_step / n) if n > max_step else d)
        out[k] = prev
    return out


def largest_step(path: np.ndarray, start: np.ndarray) -> tuple[float, int]:
    steps = np.linalg.norm(np.diff(np.concatenate([start[None], path]), axis=0), axis=1)
    k = int(np.argmax(steps))
    return float(steps[k]), k


# ---------------------------------------------------------------------------- COM paths
def read_com_csv(path: str | Path, fps: float) -> np.ndarray:
    """(H, 3) COM path from a CSV with a header `x,y,z` (one row per frame) or `t,x,y,z` (seconds, resampled)."""
    p = Path(path)
    if not p.is_file():
        raise CharctlError(f"com path: {p} is not a file (give FILE.csv or e.g. circle:r=2,speed=1.2)")
    try:
        rows = [r for r in csv.reader(p.read_text().splitlines()) if any(c.strip() for c in r)]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise CharctlError(f"com path {p}: cannot read ({exc})") from None
    if not rows:
        raise CharctlError(f"com path {p}: empty file")
    header = [c.strip().lower() for c in rows[0]]
    if header not in (["x", "y", "z"], ["t", "x", "y", "z"]):
        raise CharctlError(
            f"com path {p}: expected the header 'x,y,z' or 't,x,y,z' "
            f"(metres, y up; t in seconds), got '{','.join(rows[0])}'"
        )
    values = np.empty((len(rows) - 1, len(header)))
    for n, row in enumerate(rows[1:]):
        if len(row) != len(header):
            raise CharctlError(f"com path {p}: line {n + 2} has {len(row)} values, the header names {len(header)}")
        try:
            values[n] = [float(c) for c in row]
        except ValueError:
            raise CharctlError(
                f"com path {p}: line {n + 2} holds a value that is not a number: {','.join(row)}"
            ) from None
        if not np.all(np.isfinite(values[n])):
            raise CharctlError(f"com path {p}: line {n + 2} holds a NaN or infinite value")
    if values.shape[0] < 2:
        raise CharctlError(f"com path {p}: needs at least 2 rows")
    if header[0] != "t":
        return values
    t = values[:, 0]
    if np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0))
        raise CharctlError(f"com path {p}: times must increase (line {k + 3}: t={t[k + 1]} after t={t[k]})")
    grid = np.arange(t[0], t[-1] + 1e-9, 1.0 / fps)
    return np.stack([np.interp(grid, t, values[:, a]) for a in (1, 2, 3)], axis=1)


def circle_path(
    start: np.ndarray, frames: int, fps: float, r: float = 2.0, speed: float = 1.2, dir: str = "left"
) -> np.ndarray:
    """A circle of radius r (m) walked at `speed` (m/s) from `start`, initially heading +z, turning left/right."""
    if r <= 0:
        raise CharctlError("circle: r must be positive")
    phi = speed * np.arange(1, frames + 1) / fps / r
    side = {"left": 1.0, "right": -1.0}.get(dir)
    if side is None:
        raise CharctlError(f"circle: dir must be left or right, got {dir!r}")
    x = start[0] + side * r * (1.0 - np.cos(phi))  # facing +z the character's left is +x
    return np.stack([x, np.full(frames, start[1]), start[2] + r * np.sin(phi)], axis=1)


def line_path(start: np.ndarray, frames: int, fps: float, speed: float = 1.2) -> np.ndarray:
    """Straight ahead (+z) at `speed` m/s (speed=0: stand still)."""
    z = start[2] + speed * np.arange(1, frames + 1) / fps
    return np.stack([np.full(frames, start[0]), np.full(frames, start[1]), z], axis=1)


PATHS = {"circle": circle_path, "line": line_path}


def procedural_path(spec: str, start: np.ndarray, frames: int, fps: float) -> np.ndarray:
    """`name:key=value,...` from PATHS, e.g. circle:r=2,speed=1.2,dir=right or line:speed=1.0."""
    name, _, args = spec.partition(":")
    kwargs: dict = {}
    for item in filter(None, (a.strip() for a in args.split(","))):
        key, eq, value = item.partition("=")
        if not eq:
            raise CharctlError(f"com path {spec!r}: '{item}' is not key=value")
        try:
            kwargs[key.strip()] = float(value) if key.strip() != "dir" else value.strip()
        except ValueError:
            raise CharctlError(f"com path {spec!r}: {key}={value} is not a number") from None
    fn = PATHS[name]
    try:
        return fn(start, frames, fps, **kwargs)
    except TypeError:
        import inspect

        names = [p for p in inspect.signature(fn).parameters if p not in ("start", "frames", "fps")]
        raise CharctlError(f"com path {spec!r}: {name} takes {', '.join(names)}") from None


def make_com_path(
    spec: str, start: np.ndarray, seconds: float, fps: float, crouch_at: float | None, gen_cfg
) -> np.ndarray:
    """The input COM path (H, 3) of a --com-path spec, translated to `start`, with the crouch and the clamp."""
    name = spec.partition(":")[0]
    if name in PATHS:
        path = procedural_path(spec, start, max(1, int(round(seconds * fps))), fps)
    elif spec.lower().endswith(".csv") or Path(spec).is_file():
        path = read_com_csv(spec, fps)
        path = path + (start - path[0]) * XZ  # first point onto the seed's last COM (horizontally)
    else:
        raise CharctlError(
            f"com path {spec!r}: give a .csv file or one of "
            f"{', '.join(f'{k}:...' for k in PATHS)} (e.g. circle:r=2,speed=1.2)"
        )
    if crouch_at is not None:
        t = np.arange(1, path.shape[0] + 1) / fps
        ramp = np.clip((t - crouch_at) / max(float(gen_cfg.crouch_ramp_s), 1e-9), 0.0, 1.0)
        path = path - np.outer(ramp, [0.0, float(gen_cfg.crouch_drop), 0.0])
    step, k = largest_step(path, start)
    limit = float(gen_cfg.max_com_step)
    if step > limit + 1e-9:
        where = "from the seed's COM to the first point" if k == 0 else f"between frames {k - 1} and {k}"
        msg = f"com path {spec}: jump of {step:.2f} m {where} ({step * fps:.1f} m/s; limit {limit} m/frame)"
        if not gen_cfg.com_clamp:
            raise CharctlError(msg + "; fix the path or set generate.com_clamp=true")
        print(f"note: {msg}; clamped (generate.com_clamp)")
    return clamp_com_path(path, start, limit) if gen_cfg.com_clamp else path
