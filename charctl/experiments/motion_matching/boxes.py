"""The bounding-box layout shared by the index (search.py) and its numba kernel (_bbox_numba.py).

Rows are grouped into small boxes of SMALL_BOX consecutive rows and large boxes of LARGE_BOX rows; each
box stores the per-column minimum and maximum of its rows (a lower bound of the distance to any of them).
"""

from __future__ import annotations

import numpy as np

SMALL_BOX = 16  # rows per small box
LARGE_BOX = 64  # rows per large box (a multiple of SMALL_BOX)


def box_bounds(feats: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-column min/max over runs of `size` consecutive rows."""
    n, d = feats.shape
    nb = -(-n // size)
    pad = nb * size - n
    padded = np.concatenate([feats, np.repeat(feats[-1:], pad, axis=0)]) if pad else feats
    grouped = padded.reshape(nb, size, d)
    return np.ascontiguousarray(grouped.min(axis=1)), np.ascontiguousarray(grouped.max(axis=1))
