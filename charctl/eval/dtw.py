"""Dynamic time warping on a precomputed cost matrix (dtw-python), plus a brute-force reference."""

from __future__ import annotations

import numpy as np


def dtw_align(cost: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Optimal monotone alignment of two sequences given their (n, m) frame-to-frame cost matrix.

    Steps are (1,0), (0,1), (1,1) with unit weights (dtw-python's `symmetric1`), both ends
    anchored. Returns the aligned index pairs (i, j) and the summed cost along the path.
    """
    import dtw as dtw_python

    cost = np.asarray(cost, dtype=float)
    if cost.ndim != 2 or min(cost.shape) == 0:
        raise ValueError(f"cost matrix must be 2-D and non-empty, got shape {cost.shape}")
    res = dtw_python.dtw(cost, step_pattern=dtw_python.symmetric1, keep_internals=False, distance_only=False)
    return np.asarray(res.index1), np.asarray(res.index2), float(res.distance)


def dtw_bruteforce(cost: np.ndarray) -> float:
    """Reference DP: D[i,j] = c[i,j] + min(D[i-1,j], D[i,j-1], D[i-1,j-1]); returns D[n-1, m-1]."""
    n, m = cost.shape
    D = np.full((n + 1, m + 1), np.inf)
    D[0, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            D[i, j] = cost[i - 1, j - 1] + min(D[i - 1, j], D[i, j - 1], D[i - 1, j - 1])
    return float(D[n, m])


def mean_aligned_cost(cost: np.ndarray) -> float:
    """Mean per-frame cost along the optimal path, averaged over the frames of the first sequence."""
    i, j, _ = dtw_align(cost)
    per_frame = np.zeros(cost.shape[0])
    counts = np.zeros(cost.shape[0])
    np.add.at(per_frame, i, cost[i, j])
    np.add.at(counts, i, 1)
    return float(np.mean(per_frame / np.maximum(counts, 1)))
