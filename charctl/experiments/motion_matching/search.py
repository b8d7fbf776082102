"""Nearest-neighbour search over the database's searchable frames, skipping the exclusion window.

Every index returns the exact constrained nearest neighbour (squared L2 over the weighted,
normalised features) among the searchable rows that are not within the exclusion window of the
current frame (same clip, phase distance < k; circular for unrolled loops):

  brute   the reference: every distance, masked argmin (numpy)
  kdtree  scipy cKDTree; asks for the k nearest, takes the first one outside the window and
          asks for 4x more until one is found (exact: the k nearest overall contain it)
  bbox    Holden's bounding-box scheme compiled with numba: axis-aligned boxes over runs of 16
          and 64 consecutive rows (consecutive frames are close, so the boxes are tight); the
          large box with the lowest bound is searched first, then every box (large, then small)
          whose lower bound is below the best cost so far

An index answers (-1, inf) when the window holds every row; `search` makes that the one-line
exclusion.exclusion_error.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from charctl.experiments.motion_matching.boxes import LARGE_BOX, SMALL_BOX, box_bounds
from charctl.experiments.motion_matching.database import Database
from charctl.experiments.motion_matching.exclusion import exclusion_error, in_window


@dataclass
class RowInfo:
    """Per searchable row: clip id, phase (frames) and loop period (0 = not a loop); window k."""

    clip: np.ndarray
    phase: np.ndarray
    period: np.ndarray
    window: float

    def excluded(self, rows: np.ndarray, clip: int, phase: float) -> np.ndarray:
        """True for rows of clip `clip` whose (circular) phase distance to `phase` is < window (`in_window`)."""
        return in_window(self.clip[rows], self.phase[rows], self.period[rows], clip, phase, self.window)


def row_info(db: Database) -> RowInfo:
    rows = db.search_rows
    c = db.clip_id[rows]
    return RowInfo(c, db.phase[rows].astype(float), db.clip_period[c].astype(float), float(db.exclude_window))


class BruteIndex:
    """Exhaustive search (reference)."""

    def __init__(self, feats: np.ndarray, info: RowInfo):
        self.feats = np.ascontiguousarray(feats, dtype=float)
        self.sq = np.einsum("ij,ij->i", self.feats, self.feats)
        self.info = info
        self.rows = np.arange(feats.shape[0])

    def query(self, q: np.ndarray, clip: int = -1, phase: float = 0.0) -> tuple[int, float]:
        """(row, squared distance) of the nearest row outside the window of (clip, phase); clip -1: none.
        (-1, inf) when every row is inside it (as every index)."""
        d2 = self.sq - 2.0 * (self.feats @ q) + q @ q
        if clip >= 0:
            excluded = self.info.excluded(self.rows, clip, phase)
            if excluded.all():
                return -1, np.inf
            d2 = np.where(excluded, np.inf, d2)
        i = int(np.argmin(d2))
        return i, float(max(d2[i], 0.0))


class KDTreeIndex:
    """scipy cKDTree with an exact post-filter for the exclusion window."""

    def __init__(self, feats: np.ndarray, info: RowInfo, first_k: int = 8):
        from scipy.spatial import cKDTree

        self.n = feats.shape[0]
        self.tree = cKDTree(np.asarray(feats, dtype=float), leafsize=16, balanced_tree=False, compact_nodes=True)
        self.first_k = first_k
        self.info = info

    def query(self, q: np.ndarray, clip: int = -1, phase: float = 0.0) -> tuple[int, float]:
        k = min(1 if clip < 0 else self.first_k, self.n)
        while True:
            d, i = self.tree.query(q, k=k)
            d, i = np.atleast_1d(d), np.atleast_1d(i)
            ok = ~self.info.excluded(i, clip, phase) if clip >= 0 else np.ones(i.shape, bool)
            if ok.any():
                j = int(np.argmax(ok))
                return int(i[j]), float(d[j] ** 2)
            if k >= self.n:
                return -1, np.inf  # every row is inside the window
            k = min(4 * k, self.n)


class BBoxIndex:
    """Holden's two-level bounding boxes over consecutive rows (numba-compiled)."""

    def __init__(self, feats: np.ndarray, info: RowInfo):
        self.feats = np.ascontiguousarray(feats, dtype=float)
        self.info = info
        self.small_lo, self.small_hi = box_bounds(self.feats, SMALL_BOX)
        self.large_lo, self.large_hi = box_bounds(self.feats, LARGE_BOX)
        self.clip = np.ascontiguousarray(info.clip, dtype=np.int64)
        self.phase = np.ascontiguousarray(info.phase, dtype=float)
        self.period = np.ascontiguousarray(info.period, dtype=float)
        self.kernel = _bbox_kernel()

    def query(self, q: np.ndarray, clip: int = -1, phase: float = 0.0) -> tuple[int, float]:
        i, d = self.kernel(
            self.feats,
            np.ascontiguousarray(q, dtype=float),
            self.small_lo,
            self.small_hi,
            self.large_lo,
            self.large_hi,
            self.clip,
            self.phase,
            self.period,
            int(clip),
            float(phase),
            self.info.window,
        )
        if i < 0:
            return -1, np.inf  # every row is inside the window
        return int(i), float(d)


def _bbox_kernel():
    """The compiled bounding-box search (numba; compiled once and cached on disk)."""
    from charctl.experiments.motion_matching._bbox_numba import bbox_search

    return bbox_search


INDEXES: dict[str, Callable[[np.ndarray, RowInfo], object]] = {
    "brute": BruteIndex,
    "kdtree": KDTreeIndex,
    "bbox": BBoxIndex,
}


def make_index(kind: str, db_or_feats, info: RowInfo | None = None):
    """An index of `kind` over a database's searchable rows (or raw (M, D) rows plus their RowInfo)."""
    if isinstance(db_or_feats, Database):
        return INDEXES[kind](db_or_feats.search_features, row_info(db_or_feats))
    if info is None:
        n = db_or_feats.shape[0]
        info = RowInfo(np.zeros(n, dtype=np.int64), np.arange(n, dtype=float), np.zeros(n), 0.0)
    return INDEXES[kind](db_or_feats, info)


def search(db: Database, index, query: np.ndarray, cur: int | None) -> tuple[int, float]:
    """The database frame nearest to `query`, skipping the window around frame `cur`.

    Returns (frame index into the database, squared distance). A window that holds every searchable frame
    is exclusion.exclusion_error (eval and export refuse such a config before they start:
    prechecks.check_exclusion).
    """
    if cur is None or db.exclude_window <= 0:
        row, d2 = index.query(query)
    else:
        c = int(db.clip_id[cur])
        row, d2 = index.query(query, c, float(db.phase[cur]))
        if row < 0:
            raise exclusion_error(db.clip_names[c], int(cur - db.clip_start[c]), db.num_searchable, db.exclude_window)
    return int(db.search_rows[row]), d2
