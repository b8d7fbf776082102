"""numba kernel of the bounding-box search (see search.py); imported only when runtime.index=bbox."""

from __future__ import annotations

import numpy as np
from numba import njit

from charctl.experiments.motion_matching.search import LARGE_BOX, SMALL_BOX  # compile-time constants


@njit(cache=True, nogil=True)
def box_bound(q, lo, hi, b, limit):
    """Squared distance from q to box b (stops early once it reaches `limit`)."""
    s = 0.0
    for d in range(q.shape[0]):
        v = q[d]
        if v < lo[b, d]:
            t = lo[b, d] - v
            s += t * t
        elif v > hi[b, d]:
            t = v - hi[b, d]
            s += t * t
        if s >= limit:
            break
    return s


@njit(cache=True, nogil=True)
def bbox_search(F, q, slo, shi, llo, lhi, clip, phase, period, cur_clip, cur_phase, window):
    """(row, squared distance) of the nearest row of F outside the exclusion window; -1 if none."""
    n, D = F.shape
    nl = llo.shape[0]
    bounds = np.empty(nl)
    for b in range(nl):
        bounds[b] = box_bound(q, llo, lhi, b, np.inf)
    order = np.argsort(bounds)
    best_i, best_d = -1, np.inf
    per_large = LARGE_BOX // SMALL_BOX
    for ob in range(nl):
        lb = order[ob]
        if bounds[lb] >= best_d:
            break  # visited in order of the bound: every later box is at least as far
        for sb in range(lb * per_large, min((lb + 1) * per_large, slo.shape[0])):
            if box_bound(q, slo, shi, sb, best_d) >= best_d:
                continue
            for i in range(sb * SMALL_BOX, min((sb + 1) * SMALL_BOX, n)):
                if clip[i] == cur_clip:
                    dp = abs(phase[i] - cur_phase)
                    if period[i] > 0:
                        dp = min(dp, period[i] - dp)
                    if dp < window:
                        continue
                c = 0.0
                for d in range(D):
                    t = q[d] - F[i, d]
                    c += t * t
                    if c >= best_d:
                        break
                if c < best_d:
                    best_d = c
                    best_i = i
    return best_i, best_d
