"""The ``score`` stage: every sample's per-frame scores over the labels plus null, from the labeler
(one hand's points on their own for each of two hands, then joined)."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from ..hands import Hands, replace_valid
from ..labelers import FrameBatch, Labeler, assign, pack_frames
from ..labelers.assign import row_log_probabilities
from ..labeling import EMPTY, NULL, Constraint
from ..layout import Layout
from ..take import Take
from ..temporal.stride import stride_for, strided_scores
from ..temporal.voting import LOG_FLOOR, Samples, Segments, split_segments
from ..tracklets import find_crossings, find_tracklets
from .hands import hands_near
from .run import LabelRun

#: Observations scored per frame at most: beyond this, the points nearest the frame's median
#: (the hand) are kept, so a take with thousands of ghosts per frame costs bounded time.
MAX_POINTS_PER_LABEL = 3
#: Log-score of a label of the other hand (below the vote's floor: never chosen per frame).
OTHER_HAND = -30.0
#: Hands whose centres are nearer than this (metres) are scored on every frame, whatever the
#: stride: where they touch, which points a hand holds changes from frame to frame.
NEAR_HANDS = 0.15
#: Bytes of a take's per-hand scores kept at most (a long take's are scored afresh rather than held).
HAND_SCORES_BYTES = 256 * 2 ** 20


def points_cap(layout: Layout) -> int:
    """Observations a frame is packed to at most for one hand of ``layout``."""
    return max(MAX_POINTS_PER_LABEL * len(layout), len(layout) + 24)


def pack_take(take: Take, cap: int, chunk: int = 4096) -> FrameBatch:
    """All frames packed to at most ``cap`` observations, in chunks (bounded memory for huge takes)."""
    parts = [pack_frames(take.positions[s:s + chunk], cap) for s in range(0, take.n_frames, chunk)]
    k = max(b.points.shape[1] for b in parts)

    def widen(arrays: list[np.ndarray], fill) -> np.ndarray:
        out = np.full((take.n_frames, k) + arrays[0].shape[2:], fill, dtype=arrays[0].dtype)
        row = 0
        for a in arrays:
            out[row:row + len(a), :a.shape[1]] = a
            row += len(a)
        return out

    return FrameBatch(widen([b.points for b in parts], 0.0), widen([b.mask for b in parts], False),
                      widen([b.slots for b in parts], -1))


def apply_constraints(scores: np.ndarray, slots: np.ndarray, mask: np.ndarray,
                      constraints: Sequence[Constraint]) -> np.ndarray:
    """Scores with every constraint made certain: the locked sample gets its label, and no other
    observation of those frames can take that label."""
    if not constraints:
        return scores
    scores = scores.copy()
    m = scores.shape[2] - 1
    for c in constraints:
        frames = slice(c.start, c.stop)
        col = m if c.label == NULL else c.label
        hit = (slots[frames] == c.slot) & mask[frames]
        block = scores[frames]
        if c.label != NULL:
            block[~hit, col] = LOG_FLOOR * 10  # the label is taken in these frames
        rows = block[hit]
        rows[:] = LOG_FLOOR * 10
        rows[:, col] = 0.0
        block[hit] = rows
    return scores


def score_samples(scores: np.ndarray, batch: FrameBatch, rows: np.ndarray | None = None,
                  previous: Samples | None = None) -> Samples:
    """The scored samples of a take, in the order of ``np.nonzero(batch.mask)``: floored
    log-probabilities and the per-frame assignment. With ``rows`` (frame indices) and the
    ``previous`` samples of the same batch, only the samples of those frames are computed again."""
    mask, slots = batch.mask, batch.slots
    if rows is not None and previous is not None:
        rows = np.asarray(rows, dtype=np.int64)
        sub = score_samples(scores[rows], FrameBatch(batch.points[rows], mask[rows], slots[rows]))
        again = np.zeros(mask.shape[0], dtype=bool)
        again[rows] = True
        at = again[previous.frame]  # samples are in frame order, as are the rows' own
        out = replace(previous, logp=previous.logp.copy(), label=previous.label.copy(),
                      confidence=previous.confidence.copy())
        out.logp[at], out.label[at], out.confidence[at] = sub.logp, sub.label, sub.confidence
        return out
    f_idx, k_idx = np.nonzero(mask)
    logp = row_log_probabilities(scores[f_idx, k_idx])  # == scores[mask], in its order
    frame_labels, frame_conf = assign(scores, mask, logp)
    np.maximum(logp, np.float32(LOG_FLOOR), out=logp)
    return Samples(frame=f_idx.astype(np.int64), slot=slots[f_idx, k_idx].astype(np.int64), logp=logp,
                   label=frame_labels[f_idx, k_idx].astype(np.int64), confidence=frame_conf[f_idx, k_idx])


def hand_scores(take: Take, layout: Layout, members: np.ndarray, batch: FrameBatch, labeler: Labeler,
                rows: np.ndarray, segments: Segments, stride: int, every: np.ndarray) -> np.ndarray:
    """One hand's scores ``(R, K, M + 1)`` of the ``rows`` (frame indices) of the joint ``batch``, in
    its columns: the points ``members`` (bool ``(F, P)``) offers to the hand, scored by ``labeler``
    on their own (every ``stride``-th frame of each of the ``segments``, and every frame where
    ``every`` (bool ``(F,)``): :func:`..temporal.stride.strided_scores`); NaN where the hand was not
    offered the point."""
    m = len(layout)
    mask, slots = batch.mask[rows], batch.slots[rows]
    frames, k = mask.shape
    out = np.full((frames, k, m + 1), np.nan, dtype=np.float32)
    column = np.full((frames, take.n_points), -1, dtype=np.int64)  # joint column of each (frame, slot)
    f_idx, k_idx = np.nonzero(mask)
    column[f_idx, slots[f_idx, k_idx]] = k_idx
    positions = np.where(members[rows][..., None], take.positions[rows], np.nan).astype(np.float32)
    part = pack_take(replace(take, positions=positions, residuals=None, filled=None), points_cap(layout))
    scores = strided_scores(labeler.scores, part, segments, stride, frames=rows, every=every[rows])
    pf, pk = np.nonzero(part.mask)
    jk = column[pf, part.slots[pf, pk]]
    ok = jk >= 0
    out[pf[ok], jk[ok]] = scores[pf[ok], pk[ok]]
    return out


def all_hand_scores(run: LabelRun, members: np.ndarray,
                    known: Sequence[tuple[np.ndarray, np.ndarray]] = ()) -> np.ndarray:
    """:func:`hand_scores` of every frame, re-using ``known`` ``(members, scores)`` of this take
    and those the run's cache kept of the last take labeled, where a hand was offered the same
    points (the frames where it was not are scored again). ``known`` scores not kept are the
    caller's to give up: one is changed in place (a long take's are hundreds of megabytes)."""
    take, layout, batch, labeler = run.take_in, run.layout, run.batch, run.labeler
    segments, stride, every = run.segments, run.stride, run.near
    key = (run.cache.take_key(take), getattr(labeler, "path", id(labeler)), batch.mask.shape, tuple(layout.names),
           stride)
    kept_scores = run.cache.entries("hand_scores")
    kept = kept_scores.get(key, [])
    best, changed = None, None
    for old_members, old_scores in [*known, *kept]:
        rows = np.flatnonzero((old_members != members).any(axis=1))
        if changed is None or len(rows) < len(changed):
            best, changed = old_scores, rows
    if best is None or len(changed) > 0.5 * len(members):
        scores = hand_scores(take, layout, members, batch, labeler, np.arange(take.n_frames), segments, stride, every)
    else:
        scores = best.copy() if any(best is s for _, s in kept) else best
        if len(changed):
            scores[changed] = hand_scores(take, layout, members, batch, labeler, changed, segments, stride, every)
    if scores.nbytes * 4 <= HAND_SCORES_BYTES:  # both hands, before and after a second look
        if key not in kept_scores:
            kept_scores.clear()
            kept_scores[key] = []
        entries = kept_scores[key]
        entries.append((members.copy(), scores))
        del entries[:-4]
    return scores


def joint_scores(per_hand: Sequence[np.ndarray], found: Hands, batch: FrameBatch, rows: np.ndarray) -> np.ndarray:
    """Joint per-frame scores ``(R, K, 2M + 1)`` of the ``rows`` of a two-hand take from each hand's
    scores (:func:`hand_scores`, all frames): a sample offered to both hands gets both, each at
    half the weight; a sample of no hand is null."""
    m = per_hand[0].shape[2] - 1
    slots = batch.slots[rows]
    frames, k = slots.shape
    both = found.both[rows][np.arange(frames)[:, None], np.maximum(slots, 0)] & (slots >= 0)
    weight = np.where(both, np.log(0.5), 0.0).astype(np.float32)
    joint = np.full((frames, k, 2 * m + 1), OTHER_HAND, dtype=np.float32)
    null = np.full((frames, k), -np.inf)
    for h, scores in enumerate(per_hand):
        scores = scores[rows]
        seen = ~np.isnan(scores[..., m])
        joint[seen, h * m:(h + 1) * m] = scores[seen, :m] + weight[seen, None]
        null[seen] = np.logaddexp(null[seen], scores[seen, m] + weight[seen])
    joint[..., 2 * m] = np.where(np.isfinite(null), null, 0.0)
    return joint


def offered_to(run: LabelRun) -> np.ndarray | None:
    """bool ``(n, hands)``: the hands each scored sample is offered to (None: one hand)."""
    if run.found.count == 1:
        return None
    mask, slots = run.batch.mask, run.batch.slots
    f_idx, k_idx = np.nonzero(mask)
    return np.stack([run.found.members(h)[f_idx, slots[f_idx, k_idx]] for h in range(2)], axis=1)


def _segments(run: LabelRun):
    """The take's trajectories cut at the corrections, a reviewer's splits and the hands' cuts."""
    cuts: dict[int, list[int]] = {}
    for c in run.constraints:
        cuts.setdefault(c.slot, []).extend([c.start, c.stop])
    for slot, frame in list(run.corrections.splits) + run.found.cuts:
        cuts.setdefault(int(slot), []).append(int(frame))
    return split_segments(Segments(run.tracklets.slot.astype(np.int64), run.tracklets.start, run.tracklets.stop),
                          cuts)


def score_stage(run: LabelRun) -> None:
    """Pack the frames, cut the trajectories and score every sample (``run.scores``, ``run.samples``)."""
    settings, take, layout, found = run.settings, run.take, run.layout, run.found
    t = time.perf_counter()
    run.say("packing frames")
    ignore = run.ignore
    if ignore is not None and ignore.any():
        run.take_in = replace_valid(take, take.valid & ~(ignore if ignore.ndim == 2 else ignore[None, :]))
    else:
        run.take_in = take
    run.batch = batch = pack_take(run.take_in, points_cap(layout) * found.count)
    run.tracklets = find_tracklets(take)
    run.segments = _segments(run)
    if run.mode.decides_per_frame:
        run.stride = 1
    elif settings.stride is None:
        # Ours; the published labelers score every frame, as their papers do.
        run.stride = stride_for(take.rate) if run.method.strided else 1
    else:
        run.stride = settings.stride
    run.timed("pack", t)

    t = time.perf_counter()
    run.say(f"scoring {take.n_frames} frames with {settings.method}", 0.02)
    if found.count == 2:
        run.labeler = run.labeler or run.method.make(layout, settings.model, cache=run.cache)
        run.scored_members = [found.members(h) for h in range(2)]
        run.near = hands_near(found, NEAR_HANDS)
        run.hand_scores = [all_hand_scores(run, run.scored_members[h]) for h in range(2)]
        scores = joint_scores(run.hand_scores, found, batch, np.arange(take.n_frames))
    else:
        run.labeler = run.labeler or run.method.build(layout, batch, model=settings.model, fit=run.fit,
                                                      start=run.start, cache=run.cache)
        labeler = run.labeler
        hooked = hasattr(labeler, "on_batch")
        if hooked:  # ONNX labelers report each batch of frames
            message = f"scoring {take.n_frames} frames with {settings.method}"
            labeler.on_batch = lambda part: run.say(message, 0.02 + (run.scored_share - 0.02) * part)
        try:
            scores = strided_scores(labeler.scores, batch, run.segments, run.stride)
        finally:
            if hooked:
                labeler.on_batch = None
    run.joint = scores
    run.say(f"scored {take.n_frames} frames", run.scored_share)
    run.scores = apply_constraints(scores, batch.slots, batch.mask, run.constraints)
    run.timed("scores", t)
    run.crossings = find_remembered_crossings(run) if settings.split_swaps and run.mode.splits_swaps else {}
    valid = take.valid
    run.locked_at = np.full(valid.shape, EMPTY, dtype=np.int16)  # the locked label of each sample
    for c in run.constraints:
        run.locked_at[c.start:c.stop, c.slot] = np.where(valid[c.start:c.stop, c.slot], c.label, EMPTY)
    run.member = offered_to(run)


def find_remembered_crossings(run: LabelRun) -> dict[int, list[int]]:
    """:func:`..tracklets.find_crossings` of the take, kept in the run's cache (a tenth of a second
    on a 10,000-frame take; a re-solve asks again)."""
    found = run.cache.remember("crossings", run.cache.take_key(run.take), lambda: find_crossings(run.take))
    return {slot: list(frames) for slot, frames in found.items()}  # callers may extend theirs
