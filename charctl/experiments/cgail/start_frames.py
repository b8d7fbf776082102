"""Reference-state initialisation weighted towards the clip frames where episodes fail (env.start_failure_weight).

Uniform RSI (the paper, DeepMimic) starts an episode at any frame of its clip. A skill that always fails at one
place in its clip (the spindance's overhead arm sweep at frames 7-11, docs/cgail.md "Spindance") is then
practised from just before that place only by the few episodes that happen to start there. Here a share of the
starts is drawn in proportion to the recent failures in the `lead` reference frames from each start frame on,
so episodes begin shortly before where they tend to end. Written once against the array API (numpy for the CPU
env, torch for the device env); the failure counts are a (K, F) table, F the longest clip's frame count.
"""

from __future__ import annotations

import numpy as np

from charctl.motion.array_compat import Array, namespace


def lead_window_index(clip_frames: np.ndarray, loops: np.ndarray, lead: int) -> tuple[np.ndarray, np.ndarray]:
    """((K, F, lead + 1) flat indices into a (K, F) table, (K, F, lead + 1) bool valid): for skill k and start
    frame f, the reference frames f, f + 1, ..., f + lead of its clip. A looping clip wraps round its period
    (clip_frames - 1: its last frame is its first, as `rules.advance_reference`); a non-looping clip's window
    stops at its last frame. Entries past a clip's end are invalid (index 0)."""
    clip_frames = np.asarray(clip_frames, dtype=np.int64)
    K, F = len(clip_frames), int(clip_frames.max())
    f = np.arange(F)[None, :, None] + np.arange(lead + 1)[None, None, :]  # (1, F, L)
    period = np.maximum(clip_frames - 1, 1)[:, None, None]
    last = (clip_frames - 1)[:, None, None]
    looped = np.asarray(loops, dtype=bool)[:, None, None]
    frame = np.where(looped, f % period, f)
    valid = np.broadcast_to(np.arange(F)[None, :, None] < clip_frames[:, None, None], frame.shape) & (frame <= last)
    index = np.where(valid, np.arange(K)[:, None, None] * F + frame, 0)
    return index, valid


def update_frame_failures(counts: Array, skill: Array, frame: Array, failed: Array, halflife: float) -> Array:
    """(K, F) failure counts by skill and reference frame after one control step: `counts` decayed to half over
    `halflife` control steps, plus one for each env (N,) that `failed` this step, at its command `skill` and its
    reference `frame`."""
    xp = namespace(counts, skill)
    K, F = counts.shape
    added = xp.bincount(skill * F + frame, weights=xp.astype(failed, counts.dtype), minlength=K * F)
    return 0.5 ** (1.0 / halflife) * counts + xp.reshape(added, (K, F))


def draw_start_frames(
    counts: Array, lead: tuple[Array, Array], rsi_frames: Array, weight: float, skill: Array, u: Array
) -> Array:
    """(n,) start frames of envs commanded `skill` (n,), from uniforms `u` (n,): `start_frame_cdf` with the
    failure `counts` (K, F), the `lead` windows (`lead_window_index`) and `weight`, inverted by
    `sample_start_frames`."""
    return sample_start_frames(start_frame_cdf(counts, *lead, rsi_frames, weight), skill, u, rsi_frames)


def start_frame_cdf(counts: Array, index: Array, valid: Array, rsi_frames: Array, weight: float) -> Array:
    """(K, F) cumulative start-frame probabilities: (1 - `weight`) uniform over a clip's start frames
    [0, rsi_frames - 1) (as uniform RSI draws them) plus `weight` in proportion to the failures in each start
    frame's lead window (`lead_window_index`); uniform where a skill has no failures on record."""
    xp = namespace(counts, index)
    K, F = counts.shape
    ahead = xp.sum(
        xp.reshape(xp.take(xp.reshape(counts, (-1,)), xp.reshape(index, (-1,))), index.shape) * valid, axis=2
    )
    startable = xp.astype(xp.arange(F)[None, :] < (rsi_frames - 1)[:, None], counts.dtype)  # (K, F)
    uniform = startable / xp.sum(startable, axis=1, keepdims=True)
    ahead = ahead * startable
    total = xp.sum(ahead, axis=1, keepdims=True)
    by_failure = xp.where(total > 0, ahead / xp.where(total > 0, total, xp.ones_like(total)), uniform)
    return xp.cumulative_sum((1.0 - weight) * uniform + weight * by_failure, axis=1)


def sample_start_frames(cdf: Array, skill: Array, u: Array, rsi_frames: Array) -> Array:
    """(n,) start frames of envs commanded `skill` (n,) from uniforms `u` (n,) in [0, 1) by inverting their
    skill's row of `cdf` (`start_frame_cdf`), kept below rsi_frames - 1 (rounding at the top)."""
    xp = namespace(cdf, skill)
    rows = xp.take(cdf, skill, axis=0)  # (n, F)
    frame = xp.sum(xp.astype(rows <= u[:, None], skill.dtype), axis=1)
    return xp.minimum(frame, xp.take(rsi_frames, skill) - 2)
