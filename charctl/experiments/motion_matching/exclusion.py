"""The motion-matching exclusion rule (paper §3): a search made from the current frame skips the frames of the
same clip closer in phase than `runtime.exclude_window`. One rule, used by Database.excluded, search.RowInfo and the
pre-checks (`prechecks.py`); the bbox kernel (`_bbox_numba.py`) holds a compiled copy of `in_window` for speed: a
numba version of this very function (np.where on arrays) was measured 39x slower (943 vs 24 ms per 2e6 rows), so the
kernel keeps its scalar loop; the search tests run every index kind (brute, kdtree, bbox) on the same cases
(tests/test_motion_matching.py), which pins the copy to this rule."""

from __future__ import annotations

import numpy as np

from charctl.errors import CharctlError


def in_window(clip, phase, period, cur_clip, cur_phase, window) -> np.ndarray:
    """The exclusion rule (paper §3): True for the frames of clip `clip` at `phase` (frames; circular within
    `period` for an unrolled loop, 0 = not a loop) that a search made from the current frame (`cur_clip`,
    `cur_phase`) skips: same clip and phase distance < `window` (database frames; 0 skips nothing). Arguments
    broadcast. Database.excluded, search.RowInfo.excluded and the pre-checks use it; the bbox kernel
    (_bbox_numba.py) is its compiled copy."""
    d = np.abs(np.asarray(phase, dtype=float) - cur_phase)
    d = np.where(np.asarray(period) > 0, np.minimum(d, period - d), d)
    return (np.asarray(clip) == cur_clip) & (d < window)


def blocked_from_phases(
    per_clip: list[tuple[np.ndarray, np.ndarray]], periods: list[float], window: int
) -> list[np.ndarray]:
    """`prechecks.blocked_frames` from `prechecks.search_frames`' masks and phases, the clips' periods and the
    window."""
    out = [np.zeros(0, dtype=int) for _ in per_clip]
    holding = [i for i, (rows, _) in enumerate(per_clip) if rows.any()]
    if window <= 0 or len(holding) != 1:
        return out
    i = holding[0]
    rows, phase = per_clip[i]
    period = float(periods[i])
    x = np.sort(phase[rows])
    cur = np.arange(int(np.argmax(rows)), rows.size)
    p = phase[cur]
    if period > 0:
        j = np.searchsorted(x, np.mod(p + period / 2, period))
        far = np.stack([x[j % x.size], x[(j - 1) % x.size]])
    else:
        far = np.stack([np.full(p.shape, x[0]), np.full(p.shape, x[-1])])
    out[i] = cur[in_window(0, far, period, 0, p, window).all(axis=0)]
    return out


def exclusion_error(clip: str, frame: int, searchable: int, window: int) -> CharctlError:
    """The one-line error of a search (from frame `frame` of clip `clip`) that finds every one of the
    database's `searchable` frames inside its exclusion window of `window` database frames."""
    return CharctlError(
        f"runtime.exclude_window excludes every searchable frame from a search at frame {frame} of clip "
        f"{clip!r}: all {searchable} are in that clip, closer than {window} frames (at data.fps) in phase; "
        "lower runtime.exclude_window or add clips"
    )
