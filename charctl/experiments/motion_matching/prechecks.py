"""Checks of a motion-matching config made before anything is written, without computing any feature: the
number of searchable frames (`check_searchable`) and frames a search would find nothing from (`check_exclusion`,
`blocked_frames`)."""

from __future__ import annotations

import numpy as np

from charctl.experiments.motion_matching.database import (
    exclude_window_frames,
    feature_offsets,
    full_horizon,
    require_searchable,
    searchable_and_phase,
)
from charctl.experiments.motion_matching.exclusion import blocked_from_phases, exclusion_error
from charctl.experiments.motion_matching.sources import SourceMotion


def check_searchable(cfg, sources: list[SourceMotion]) -> int:
    """The number of searchable frames build_database(cfg, sources) would have, counted without computing
    any feature (so a sweep can check every case before it writes); fewer than 2 is build_database's
    one-line error."""
    count = sum(int(np.count_nonzero(rows)) for rows, _ in search_frames(cfg, sources))
    require_searchable(count)
    return count


def check_exclusion(cfg, sources: list[SourceMotion]) -> None:
    """A one-line error (the one `search` gives when it finds nothing) if `runtime.exclude_window` can
    exclude every searchable frame of build_database(cfg, sources) from a search, found without computing
    any feature (so eval and export check it before they write); see `blocked_frames`."""
    per_clip = search_frames(cfg, sources)
    count = sum(int(np.count_nonzero(rows)) for rows, _ in per_clip)
    for s, frames in zip(
        sources, blocked_from_phases(per_clip, [s.period for s in sources], exclude_window_frames(cfg))
    ):
        if frames.size:
            raise exclusion_error(s.name, int(frames[0]), count, exclude_window_frames(cfg))


def blocked_frames(cfg, sources: list[SourceMotion]) -> list[np.ndarray]:
    """Per source, the frames (indices into the clip) a search can be made from with every searchable frame
    of build_database(cfg, sources) inside their exclusion window (`in_window`): a search from one of them
    finds nothing.

    Conservative where only the rollout knows: which frames are current when a search is made depends on
    the search results (the start frame is the best match to the path, playback runs on from each jump for
    runtime.search_interval frames or, with runtime.continue_if_best, further), so every frame that can be
    current is counted: from the clip's first searchable frame (a start or jump target) to its last.
    Exact otherwise: another clip's frames are never excluded, so only a database whose searchable frames
    all lie in one clip can have blocked frames; from a current phase p the searchable frame farthest away
    decides (it is inside the window only if all are): the first or last searchable phase of a clip that is
    not a loop, a neighbour of the antipode p + period/2 of a loop."""
    return blocked_from_phases(search_frames(cfg, sources), [s.period for s in sources], exclude_window_frames(cfg))


def search_frames(cfg, sources: list[SourceMotion]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per source, which of its frames build_database(cfg, sources) makes searchable (T,) and their phases
    (T,), without computing any feature."""
    fut, past = feature_offsets(cfg)
    out = []
    for s in sources:
        t = np.arange(s.root_pos.shape[0])
        searchable, phase = searchable_and_phase(s, cfg, t)
        out.append((searchable & full_horizon(t, fut, past), phase))
    return out
