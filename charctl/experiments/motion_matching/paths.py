"""Target paths on the ground (x, z in metres) and the path-following error.

A path is a polyline (closed for the built-in shapes; a CSV path is closed when its last
waypoint equals its first). The target point moves along it at `speed` m/s from the first
waypoint, so P(s) is the point at arc length s and the target at time t is P(speed * t).

Errors of a generated root ground path g(t), t = 0, dt, ..., (both reported as mean and std
over the frames):
  e_time  = |g(t) - P(speed * t)|   distance to where the target is at the same time (= the
            target point at the same scheduled arc length): rewards shape *and* keeping pace
  e_near  = min_s |g(t) - P(s)|     distance to the nearest point of the path: rewards shape
            only (a character that lags or cuts ahead along the path is not penalised)
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError

BUILTIN_PATHS = ("circle", "square", "star")


@dataclass
class TargetPath:
    name: str
    points: np.ndarray  # (K, 2) waypoints (x, z), metres; closed paths repeat the first at the end
    closed: bool

    def __post_init__(self) -> None:
        seg = np.diff(self.points, axis=0)
        self.seg_len = np.linalg.norm(seg, axis=1)
        self.cum = np.concatenate([[0.0], np.cumsum(self.seg_len)])
        self.dirs = seg / np.maximum(self.seg_len[:, None], 1e-12)

    @property
    def length(self) -> float:
        return float(self.cum[-1])

    def _segment(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = np.asarray(s, dtype=float)
        s = np.mod(s, self.length) if self.closed else np.clip(s, 0.0, self.length)
        i = np.clip(np.searchsorted(self.cum, s, side="right") - 1, 0, self.seg_len.size - 1)
        return i, s - self.cum[i]

    def point_at(self, s) -> np.ndarray:
        """(..., 2) point at arc length s (wraps on closed paths, clamps on open ones)."""
        i, u = self._segment(s)
        return self.points[i] + self.dirs[i] * u[..., None]

    def tangent_at(self, s) -> np.ndarray:
        """(..., 2) unit tangent at arc length s."""
        i, _ = self._segment(s)
        return self.dirs[i]

    def nearest_distance(self, p: np.ndarray, chunk: int = 2048) -> np.ndarray:
        """(N,) distance from points (N, 2) to the polyline."""
        a, d, L = self.points[:-1], self.dirs, self.seg_len
        out = np.empty(p.shape[0])
        for k in range(0, p.shape[0], chunk):  # chunks bound memory at N x K
            q = p[k : k + chunk, None, :] - a[None]
            u = np.clip(np.einsum("nki,ki->nk", q, d), 0.0, L)
            r = q - u[..., None] * d[None]
            out[k : k + chunk] = np.sqrt(np.einsum("nki,nki->nk", r, r).min(axis=1))
        return out


def make_path(spec: str, pcfg) -> TargetPath:
    """A built-in shape (circle | square | star) or a CSV file of x,z waypoints."""
    shapes = {"circle": _circle, "square": _square, "star": _star}
    if spec in shapes:
        return TargetPath(spec, shapes[spec](pcfg), closed=True)
    path = Path(spec)
    if path.suffix.lower() == ".csv" or path.exists():
        return read_path_csv(path)
    raise CharctlError(f"unknown path {spec!r}: use circle, square, star or a CSV file of x,z waypoints")


def _circle(p) -> np.ndarray:
    """Counter-clockwise (seen from above, +y) circle through the origin, starting along +x."""
    a = np.linspace(0.0, 2 * np.pi, 721)
    r = p.circle_radius
    return np.stack([r * np.sin(a), -r * (1 - np.cos(a))], axis=1)


def _square(p) -> np.ndarray:
    """Square starting at the middle of one side, heading +x."""
    h = 0.5 * p.square_side
    pts = [(0.0, 0.0), (h, 0.0), (h, -2 * h), (-h, -2 * h), (-h, 0.0), (0.0, 0.0)]
    return np.array(pts, dtype=float)


def _star(p) -> np.ndarray:
    """Star polygon: `star_points` tips at radius star_outer, inner corners at star_inner.

    It starts at the middle of an edge so that the first corner is not at the start.
    """
    n = p.star_points
    ang = np.pi / 2 + np.arange(2 * n) * np.pi / n
    rad = np.where(np.arange(2 * n) % 2 == 0, p.star_outer, p.star_inner)
    verts = np.stack([rad * np.cos(ang), -rad * np.sin(ang)], axis=1)
    mid = 0.5 * (verts[0] + verts[1])
    pts = np.concatenate([[mid], verts[1:], verts[:1], [mid]])
    return pts - mid


def read_path_csv(path: str | Path) -> TargetPath:
    """x,z waypoints (metres), one per line; an optional header line; '#' comments.

    Bad input is a one-line CharctlError naming the file and line.
    """
    path = Path(path)
    if not path.is_file():
        raise CharctlError(f"path file not found: {path}")
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise CharctlError(f"{path}: cannot read ({exc.__class__.__name__})") from None
    pts = []
    for no, line in enumerate(lines, 1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        cells = [c.strip() for c in text.replace(";", ",").split(",")]
        if not pts and no == _first_content_line(lines) and not _is_number(cells[0]):
            continue  # header
        if len(cells) != 2 or not all(_is_number(c) for c in cells):
            raise CharctlError(f"{path}:{no}: expected two numbers 'x,z', got {line.strip()[:60]!r}")
        x, z = float(cells[0]), float(cells[1])
        if not (np.isfinite(x) and np.isfinite(z)):
            raise CharctlError(f"{path}:{no}: non-finite waypoint {line.strip()[:60]!r}")
        pts.append((x, z))
    arr = np.array(pts, dtype=float).reshape(-1, 2)
    if arr.shape[0] >= 2:
        keep = np.concatenate([[True], np.linalg.norm(np.diff(arr, axis=0), axis=1) > 1e-9])
        arr = arr[keep]
    if arr.shape[0] < 2:
        raise CharctlError(f"{path}: a path needs at least two distinct x,z waypoints")
    closed = arr.shape[0] > 2 and np.linalg.norm(arr[0] - arr[-1]) < 1e-6
    return TargetPath(path.stem, arr, closed=closed)


def _first_content_line(lines: list[str]) -> int:
    for no, line in enumerate(lines, 1):
        if line.split("#", 1)[0].strip():
            return no
    return 0


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def path_duration(path: TargetPath, speed: float, laps: float) -> float:
    """Seconds the target needs: `laps` laps of a closed path, or to the end of an open one."""
    return path.length * (laps if path.closed else 1.0) / speed


def frame_errors(path: TargetPath, ground: np.ndarray, speed: float, dt: float) -> dict[str, np.ndarray]:
    """Per-frame e_time and e_near (metres) of a generated ground path (T, 2) sampled every dt."""
    s = speed * np.arange(ground.shape[0]) * dt
    if not path.closed:
        s = np.minimum(s, path.length)
    return {"e_time": np.linalg.norm(ground - path.point_at(s), axis=1), "e_near": path.nearest_distance(ground)}


def path_errors(path: TargetPath, ground: np.ndarray, speed: float, dt: float) -> dict[str, float]:
    """Mean/std of e_time and e_near (metres) of a generated ground path (T, 2) sampled every dt."""
    e = frame_errors(path, ground, speed, dt)
    e_time, e_near = e["e_time"], e["e_near"]
    return {
        "e_time_mean": float(e_time.mean()),
        "e_time_std": float(e_time.std()),
        "e_near_mean": float(e_near.mean()),
        "e_near_std": float(e_near.std()),
    }


def draw_paths(ax, path, ground: np.ndarray) -> None:
    """Target (dashed) and generated root path (solid) seen from above (x right, z down)."""
    ax.plot(path.points[:, 0], path.points[:, 1], "k--", lw=1.0, label="target")
    ax.plot(ground[:, 0], ground[:, 1], "-", color="tab:red", lw=1.2, label="generated")
    ax.plot(ground[:1, 0], ground[:1, 1], "o", color="tab:red", ms=4)
    ax.set_aspect("equal")
    ax.invert_yaxis()
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.legend(fontsize=7, loc="best")
