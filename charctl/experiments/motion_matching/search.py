"""Nearest-neighbour search over the database's searchable frames, skipping the exclusion window.

All indices return the exact constrained nearest neighbour (squared L2 over the weighted,
normalised features) among the searchable frames that are not within the exclusion window of
the current frame:

  brute   the reference: every distance, masked argmin (numpy)
  kdtree  scipy cKDTree; asks for the k nearest, takes the first one outside the window and
          doubles k until one is found (exact: the k nearest overall contain the constrained one)
  bbox    Holden-style bounding boxes: per block of consecutive frames an axis-aligned box; the
          blocks are visited in order of their lower-bound distance until it exceeds the best
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from charctl.experiments.motion_matching.database import Database

ExcludeFn = Callable[[np.ndarray], np.ndarray]  # search rows -> bool mask (True = skip)


class BruteIndex:
    """Exhaustive search (reference)."""

    def __init__(self, feats: np.ndarray):
        self.feats = np.ascontiguousarray(feats)
        self.sq = np.einsum("ij,ij->i", self.feats, self.feats)

    def query(self, q: np.ndarray, exclude: ExcludeFn | None = None) -> tuple[int, float]:
        """(row, squared distance) of the nearest row not excluded."""
        d2 = self.sq - 2.0 * (self.feats @ q) + q @ q
        if exclude is not None:
            d2 = np.where(exclude(np.arange(d2.shape[0])), np.inf, d2)
        i = int(np.argmin(d2))
        return i, float(max(d2[i], 0.0))


class KDTreeIndex:
    """scipy cKDTree with an exact post-filter for the exclusion window."""

    def __init__(self, feats: np.ndarray, first_k: int = 8):
        from scipy.spatial import cKDTree

        self.n = feats.shape[0]
        self.tree = cKDTree(feats, leafsize=16, balanced_tree=False, compact_nodes=True)
        self.first_k = first_k

    def query(self, q: np.ndarray, exclude: ExcludeFn | None = None) -> tuple[int, float]:
        k = min(1 if exclude is None else self.first_k, self.n)
        while True:
            d, i = self.tree.query(q, k=k)
            d, i = np.atleast_1d(d), np.atleast_1d(i)
            ok = ~exclude(i) if exclude is not None else np.ones(i.shape, bool)
            if ok.any():
                j = int(np.argmax(ok))
                return int(i[j]), float(d[j] ** 2)
            if k >= self.n:
                raise RuntimeError("every searchable frame is excluded")
            k = min(4 * k, self.n)


class BBoxIndex:
    """Axis-aligned boxes over blocks of `block` consecutive rows, visited best-bound first."""

    def __init__(self, feats: np.ndarray, block: int = 32, visit: int = 4):
        self.feats = np.ascontiguousarray(feats)
        n, d = feats.shape
        self.block = block
        nb = -(-n // block)
        pad = nb * block - n
        padded = np.concatenate([feats, np.repeat(feats[-1:], pad, axis=0)]) if pad else feats
        grouped = padded.reshape(nb, block, d)
        self.lo = grouped.min(axis=1)
        self.hi = grouped.max(axis=1)
        self.n = n
        self.visit = visit

    def query(self, q: np.ndarray, exclude: ExcludeFn | None = None) -> tuple[int, float]:
        gap = np.maximum(self.lo - q, 0.0) + np.maximum(q - self.hi, 0.0)
        bound = np.einsum("ij,ij->i", gap, gap)
        order = np.argsort(bound)
        best, best_d = -1, np.inf
        for start in range(0, order.size, self.visit):
            boxes = order[start:start + self.visit]
            if bound[boxes[0]] >= best_d:
                break
            rows = (boxes[:, None] * self.block + np.arange(self.block)).ravel()
            rows = rows[rows < self.n]
            diff = self.feats[rows] - q
            d2 = np.einsum("ij,ij->i", diff, diff)
            if exclude is not None:
                d2 = np.where(exclude(rows), np.inf, d2)
            j = int(np.argmin(d2))
            if d2[j] < best_d:
                best, best_d = int(rows[j]), float(d2[j])
        if best < 0:
            raise RuntimeError("every searchable frame is excluded")
        return best, best_d


INDEXES: dict[str, Callable[[np.ndarray], object]] = {
    "brute": BruteIndex,
    "kdtree": KDTreeIndex,
    "bbox": BBoxIndex,
}


def make_index(kind: str, feats: np.ndarray):
    """An index of `kind` over the (M, D) searchable feature rows."""
    return INDEXES[kind](feats)


def search(db: Database, index, query: np.ndarray, cur: int | None) -> tuple[int, float]:
    """The database frame nearest to `query`, skipping the window around frame `cur`.

    Returns (frame index into the database, squared distance).
    """
    rows = db.search_rows
    exclude = None if cur is None or db.exclude_window <= 0 else (lambda r: db.excluded(rows[r], cur))
    row, d2 = index.query(query, exclude)
    return int(rows[row]), d2
