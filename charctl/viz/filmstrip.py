"""Filmstrips: rows of offscreen MuJoCo renders (kinematic poses) in one PNG.

Rendering goes through `charctl.viz.video.make_renderer` (OSMesa on a headless machine,
`MUJOCO_GL=osmesa`; a machine that cannot render gets its one-line error).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def render_poses(model, qpos: np.ndarray, width: int = 240, height: int = 240, camera: str | int | None = "side"):
    """(T, H, W, 3) uint8 images of the (T, nq) poses `qpos` of `model` (mj_forward per pose, no physics);
    `camera` names a camera of the model (the humanoid's "side" / "front" follow its centre of mass)."""
    import mujoco

    from charctl.viz.video import camera_id, make_renderer

    renderer = make_renderer(model, width, height)
    data = mujoco.MjData(model)
    cam = camera_id(model, camera)
    frames = []
    try:
        for q in np.atleast_2d(qpos):
            data.qpos[:] = q
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, camera=cam)
            frames.append(renderer.render().copy())
    finally:
        renderer.close()
    return np.stack(frames)


def write_filmstrip(
    model,
    rows: list[np.ndarray],
    path: str | Path,
    row_labels: list[str],
    tile_titles: list[list[str]] | None = None,
    title: str | None = None,
    width: int = 240,
    height: int = 240,
    camera: str | int | None = "side",
) -> Path:
    """One PNG: row r shows the poses `rows[r]` ((n, nq), the same n in every row) left to right,
    labelled `row_labels[r]`, each tile titled `tile_titles[r][c]` when given."""
    from charctl.viz.plots import new_figure, save_figure

    flat = render_poses(model, np.concatenate([np.atleast_2d(q) for q in rows]), width, height, camera)  # one renderer
    images = np.split(flat, np.cumsum([len(np.atleast_2d(q)) for q in rows])[:-1])
    n_rows, n_cols = len(images), max(len(im) for im in images)
    fig, axes = new_figure(n_rows, n_cols, figsize=(1.6 * n_cols, 1.75 * n_rows + (0.3 if title else 0)), squeeze=False)
    for r, ims in enumerate(images):
        for c in range(n_cols):
            ax = axes[r, c]
            ax.set_xticks([])
            ax.set_yticks([])
            for side in ax.spines.values():
                side.set_visible(False)
            if c < len(ims):
                ax.imshow(ims[c])
                if tile_titles is not None:
                    ax.set_title(tile_titles[r][c], fontsize=7)
        axes[r, 0].set_ylabel(row_labels[r], fontsize=8)
    if title:
        fig.suptitle(title, fontsize=9)
    return save_figure(fig, path, dpi=110)
