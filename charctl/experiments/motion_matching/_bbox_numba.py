"""numba kernel of the bounding-box search (see search.py); imported only when runtime.index=bbox."""

from __future__ import annotations

import numpy as np
from numba import njit

from charctl.experiments.motion_matching.boxes import LARGE_BOX, SMALL_BOX  # compile-time constants

# reassociation/contraction let the compiler vectorise the sums; no 'nnan'/'ninf' (costs compare to BIG)
_FAST = {"nsz", "arcp", "contract", "afn", "reassoc"}
BIG = 1e300


@njit(cache=True, nogil=True, fastmath=_FAST)
def box_bound(q, lo, hi, b):
    """Squared distance from q to box b: a lower bound of the distance to any of its rows."""
    s = 0.0
    for d in range(lo.shape[1]):
        t = max(lo[b, d] - q[d], 0.0) + max(q[d] - hi[b, d], 0.0)
        s += t * t
    return s


@njit(cache=True, nogil=True, fastmath=_FAST)
def scan_large_box(F, q, slo, shi, lb, clip, phase, period, cur_clip, cur_phase, window, best_d, best_i):
    """Search the rows of large box lb (small boxes whose bound is below the best so far)."""
    n, D = F.shape
    per_large = LARGE_BOX // SMALL_BOX
    for sb in range(lb * per_large, min((lb + 1) * per_large, slo.shape[0])):
        if box_bound(q, slo, shi, sb) >= best_d:
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
            if c < best_d:
                best_d = c
                best_i = i
    return best_d, best_i


@njit(cache=True, nogil=True, fastmath=_FAST)
def bbox_search(F, q, slo, shi, llo, lhi, clip, phase, period, cur_clip, cur_phase, window):
    """(row, squared distance) of the nearest row of F outside the exclusion window; -1 if none.

    The large box with the lowest bound is searched first (a good first best), then every other
    large box whose bound is below the best so far, in storage order.
    """
    nl = llo.shape[0]
    bounds = np.empty(nl)
    for b in range(nl):
        bounds[b] = box_bound(q, llo, lhi, b)
    first = np.argmin(bounds)
    best_d, best_i = scan_large_box(F, q, slo, shi, first, clip, phase, period, cur_clip, cur_phase, window, BIG, -1)
    for lb in range(nl):
        if lb != first and bounds[lb] < best_d:
            best_d, best_i = scan_large_box(
                F, q, slo, shi, lb, clip, phase, period, cur_clip, cur_phase, window, best_d, best_i
            )
    return best_i, best_d
