"""Scoring a trajectory on some of its frames: the per-frame labeler's work cut by the stride.

At 100-120 Hz a marker moves a few millimetres from one frame to the next, so the frames of one
trajectory score alike, and the vote sums a trajectory's scores over its samples. Every
``stride``-th frame is scored (and any frame holding a trajectory piece that has none of those);
every other sample takes the scores of the nearest scored sample of its own segment (the
trajectory between cuts), so the vote still sees one score per sample. The labeler's time, most
of a take's, falls by about the stride.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..labelers.base import FrameBatch
from .voting import Segments

#: Seconds between the scored frames of a trajectory: every 4th frame at 120 Hz, every 3rd at
#: 100 Hz, every other at 60 Hz. The temporal benchmark's labels (han2018 at 120 Hz, the glove at
#: 100 Hz) are right as often as with every frame scored (``benchmarks/reports/temporal.md``).
STRIDE_S = 1 / 30


def stride_for(rate: float) -> int:
    """Frames between scored ones at ``rate`` frames per second (at least 1)."""
    return max(1, int(round(rate * STRIDE_S))) if np.isfinite(rate) and rate > 0 else 1


def strided_scores(score: Callable[[np.ndarray, np.ndarray], np.ndarray], batch: FrameBatch,
                   segments: Segments, stride: int, frames: np.ndarray | None = None,
                   every: np.ndarray | None = None) -> np.ndarray:
    """Per-frame scores ``(R, K, C)`` of ``batch`` (``R`` rows, ``K`` columns), with ``score`` called
    on only the rows it needs.

    Args:
        score: a labeler's ``scores(points, mask)``: ``(r, K, 3)`` float32 and bool ``(r, K)`` to
            ``(r, K, C)`` scores.
        batch: the packed frames; ``batch.slots`` names each observation's take slot.
        segments: the take's segments (trajectories, cut where the vote decides pieces apart): a
            sample only ever takes the scores of its own segment.
        stride: score every ``stride``-th frame of the take (1: every frame).
        frames: int ``(R,)``, the take frame of each row (default: row ``r`` is frame ``r``).
        every: bool ``(R,)``: rows scored whatever the stride (where the scene changes faster than
            a trajectory: two hands that touch).
    """
    mask = np.asarray(batch.mask, dtype=bool)
    rows_n = mask.shape[0]
    frame = np.arange(rows_n, dtype=np.int64) if frames is None else np.asarray(frames, dtype=np.int64)
    if stride <= 1 or rows_n == 0:
        return score(batch.points, batch.mask)
    f_idx, k_idx = np.nonzero(mask)
    span = int(frame.max()) + 2
    key = batch.slots[f_idx, k_idx].astype(np.int64) * span + frame[f_idx]
    starts = np.isin(key, segments.slot.astype(np.int64) * span + segments.start.astype(np.int64))
    order = np.argsort(key, kind="stable")
    ordered = key[order]
    # Sorted by (slot, frame), a sample continues its predecessor's segment where it is the next
    # frame of the same slot and no segment starts at it.
    same = np.zeros(len(order), dtype=bool)
    same[1:] = (np.diff(ordered) == 1) & ~starts[order[1:]]
    first = np.flatnonzero(~same)  # sorted position where each piece begins
    run = np.cumsum(~same) - 1  # the piece of each sorted sample
    needed = frame % stride == 0
    if every is not None:
        needed |= every
    # A piece with no sample on a base frame gets its first frame scored.
    pieces_with = np.zeros(len(first), dtype=bool)
    pieces_with[run[needed[f_idx[order]]]] = True
    needed[f_idx[order[first[~pieces_with]]]] = True
    rows = np.flatnonzero(needed)
    part = score(batch.points[rows], batch.mask[rows])
    out = np.zeros((rows_n,) + part.shape[1:], dtype=part.dtype)
    out[rows] = part
    scored = needed[f_idx[order]]
    if scored.all():
        return out
    # The nearest scored sample of the same piece, before and after each sample (sorted positions).
    position = np.arange(len(order))
    before = np.maximum.accumulate(np.where(scored, position, -1))
    after = np.minimum.accumulate(np.where(scored, position, len(order))[::-1])[::-1]
    piece_start = first[run]
    piece_stop = np.append(first[1:], len(order))[run]
    before = np.where(before >= piece_start, before, -1)
    after = np.where(after < piece_stop, after, -1)
    use_after = (before < 0) | ((after >= 0) & (after - position < position - before))
    donor = np.where(use_after, after, before)
    fill = ~scored
    to, src = order[fill], order[donor[fill]]
    out[f_idx[to], k_idx[to]] = out[f_idx[src], k_idx[src]]
    return out
