"""`charctl train motion-matching`: no learning; builds the feature database and stores it in the run."""

from __future__ import annotations

import time

import numpy as np

from charctl.experiments.motion_matching.cases import resolve_case


def preflight(cfg) -> None:
    """`charctl train`'s check before the run directory is made: `train`'s one-line errors about the case, the
    clips and a database with too few searchable frames (prechecks.check_searchable, no feature computed).
    Training never searches, so runtime.exclude_window is not checked here (eval and export check it)."""
    from charctl.experiments.motion_matching.prechecks import check_searchable
    from charctl.experiments.motion_matching.sources import load_sources

    cfg, _ = resolve_case(cfg)
    sources, _ = load_sources(cfg)
    check_searchable(cfg, sources)


def train(cfg, run) -> dict:
    """No learning: build the database, report its size and save it (database.npz) in the run."""
    from charctl.experiments.motion_matching.database import build_database

    cfg, case = resolve_case(cfg)
    tic = time.perf_counter()
    db = build_database(cfg)
    seconds = time.perf_counter() - tic
    np.savez_compressed(
        run.path("database.npz"),
        features=db.features[db.search_rows],
        frames=db.search_rows,
        clip_id=db.clip_id[db.search_rows],
        mean=db.layout.mean,
        scale=db.layout.scale,
        sqrt_w=db.layout.sqrt_w,
    )
    metrics = {
        "searchable_frames": int(db.num_searchable),
        "playback_frames": int(db.num_frames),
        "feature_dims": int(db.layout.dims),
        "fps": float(db.fps),
        "wall_s": seconds,
        "blocks": {k: [v.start, v.stop] for k, v in db.layout.blocks.items()},
        "clips": db.clip_names,
        "case": case,
    }
    run.write_metrics(metrics)
    print(
        f"database: {db.num_searchable} searchable frames ({db.num_frames} with the unrolled loops), "
        f"{db.layout.dims} features, {db.fps:.0f} Hz, built in {seconds:.2f} s -> {run.dir / 'database.npz'}"
    )
    return {k: v for k, v in metrics.items() if not isinstance(v, (dict, list))}
