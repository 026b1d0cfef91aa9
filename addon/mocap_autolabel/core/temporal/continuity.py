"""Evidence from continuity: a trajectory that begins must continue a marker that was just seen.

A marker hidden for a moment comes back as a new trajectory near where it was, moved as the
markers around it moved; a ghost that flickers up while that marker is hidden is wherever the
cameras' reflections put it. Per-frame labelers see one frame and cannot tell the two apart: the
free label goes to whichever point looks most like it (on han2018, 155 ghost trajectories took
the label of a hidden marker, a median 28 mm from its true spot). Once the vote has labeled the
take, every trajectory's first and last frames are compared with each label's last sample
before it and first sample after it: the label's position there, carried by the mean motion of
its nearest labeled neighbours over the frames between, must land within a tolerance that grows
with those frames. The samples within ``window`` frames of that end earn ``inside`` nats for the
label where it lands, ``-outside`` where it does not; labels not seen near enough earn nothing.
"""

from __future__ import annotations

import numpy as np

from .voting import Segments, segment_of

#: Metres: the tolerance across a gap of one frame (a hidden marker's own noise and skin slip) ...
TOLERANCE = 0.005
#: ... plus this many metres per second of gap (a finger moves against its neighbours). Both
#: chosen on synthetic validation takes; with the true labels on 40 of them, 5 mm + 0.1 m/s let
#: 660 true trajectory starts in and 42 out, and 86 ghost-label pairs in of 125,000 (10 mm +
#: 0.25 m/s: 849 ghost pairs in).
SPEED = 0.1
#: Gaps longer than this (seconds) give no evidence: the prediction has drifted too far.
MAX_GAP_S = 0.5
#: Neighbours whose motion carries a label across the gap.
NEIGHBOURS = 3
#: An anchor must hold its label for this many frames: a ghost labeled for a frame or two by the
#: first vote must not veto the real marker that comes back after it.
MIN_ANCHOR = 10
#: Frames at each end of a trajectory that earn the evidence.
WINDOW = 12


def continuity_logp(positions: np.ndarray, frame: np.ndarray, slot: np.ndarray, label: np.ndarray,
                    held_for: np.ndarray, tracklets: Segments, n_labels: int, rate: float,
                    inside: float, outside: float, window: int | None = None,
                    rows: np.ndarray | None = None) -> np.ndarray:
    """Evidence ``(n, M + 1)`` nats of each sample for each label from continuity at the ends of
    its trajectory (the null column is 0).

    Args:
        positions: ``(n, 3)`` metres, the samples' positions.
        frame, slot: int ``(n,)``.
        label: int ``(n,)`` their labels so far (negative: null).
        held_for: int ``(n,)`` frames of the segment that gave each sample its label.
        tracklets: the trajectories whose ends are checked (ordered by slot, start).
        n_labels: ``M``.
        rate: frames per second.
        inside, outside: nats per sample for (against) a label at (not at) its predicted spot.
        window: frames at each end that earn the evidence (default :data:`WINDOW`).
        rows: the samples to weigh (indices; default all): only their trajectories' ends are
            checked, and the other samples get 0. Anchors are read off all samples.
    """
    n = len(frame)
    window = WINDOW if window is None else window
    out = np.zeros((n, n_labels + 1), dtype=np.float32)
    if not n or not len(tracklets) or (inside == 0 and outside == 0):
        return out
    frames = int(frame.max()) + 1
    anchor = (label >= 0) & (held_for >= MIN_ANCHOR)
    # float32: millimetre tolerances, and half the memory traffic of the (P, M, 3) gathers below.
    x = np.full((frames, n_labels, 3), np.nan, dtype=np.float32)
    x[frame[anchor], label[anchor]] = positions[anchor]
    held = ~np.isnan(x[..., 0])
    index = np.arange(frames)[:, None]
    last = np.maximum.accumulate(np.where(held, index, -1), axis=0)  # (F, M): last frame <= f held
    first = np.minimum.accumulate(np.where(held, index, frames)[::-1], axis=0)[::-1]
    # Tracklets cover every slot of the take, samples only the points that were scored (a frame
    # crowded past the labeler's cap keeps the points nearest the hand): size by both.
    n_slots = int(max(slot.max(), tracklets.slot.max())) + 1
    own = np.full((frames, n_slots, 3), np.nan)
    own[frame, slot] = positions
    anchored = np.full((frames, n_slots), -1, dtype=np.int64)  # the label a sample anchors, if any
    anchored[frame[anchor], slot[anchor]] = label[anchor]
    seg = segment_of(tracklets, frame, slot)
    s = np.flatnonzero(seg >= 0) if rows is None else np.asarray(rows)[seg[rows] >= 0]  # on a checked trajectory
    checked = np.zeros(len(tracklets), dtype=bool)
    checked[seg[s]] = True
    max_gap = MAX_GAP_S * rate
    before = np.where((tracklets.start > 0)[:, None], last[np.maximum(tracklets.start - 1, 0)], -1)
    after = np.where((tracklets.stop < frames)[:, None], first[np.minimum(tracklets.stop, frames - 1)], frames)
    for end, at, t0 in (("start", tracklets.start, before), ("stop", tracklets.stop - 1, after)):
        gap = np.abs(at[:, None] - t0)
        ok = (t0 >= 0) & (t0 < frames) & (gap <= max_gap) & checked[:, None]
        evidence = np.zeros((len(tracklets), n_labels), dtype=np.float32)
        ti, li = np.nonzero(ok)
        if len(ti):
            a0, a1 = t0[ti, li], at[ti]
            here = own[a1, tracklets.slot[ti]]  # (P, 3) the trajectory's end point
            was = x[a0, li]  # (P, 3) the label's anchor
            # The label's neighbours at the anchor (squared distances: only their order counts),
            # and how they moved from there to the end frame. Markers on the trajectory itself
            # cannot vouch for it: leave out the label it holds at that end.
            d = x[a0] - was[:, None]  # (P, M, 3)
            near = np.einsum("pmi,pmi->pm", d, d)
            near[~(held[a0] & held[a1]) | (np.arange(n_labels)[None] == li[:, None])] = np.inf
            mine = anchored[a1, tracklets.slot[ti]]
            near[np.flatnonzero(mine >= 0), mine[mine >= 0]] = np.inf
            k = min(NEIGHBOURS, n_labels)
            pick = np.argpartition(near, k - 1, axis=1)[:, :k] if k < n_labels else np.argsort(near, axis=1)
            use = np.isfinite(np.take_along_axis(near, pick, axis=1))
            shift = x[a1[:, None], pick] - x[a0[:, None], pick]  # (P, k, 3) the neighbours' motion
            count = use.sum(axis=1)
            shift = np.where(use[..., None], shift, 0.0).sum(axis=1) / np.maximum(count, 1)[:, None]
            r = np.linalg.norm(here - (was + shift), axis=1)
            tol = TOLERANCE + SPEED * gap[ti, li] / rate
            fine = (count > 0) | (gap[ti, li] <= 2)  # no neighbours: only a short gap is judged
            fine &= np.isfinite(here[:, 0])  # an end that was not scored is not judged
            evidence[ti[fine], li[fine]] = np.where(r[fine] <= tol[fine], inside, -outside)
        edge = tracklets.start[seg[s]] if end == "start" else tracklets.stop[seg[s]] - 1
        near_end = np.abs(frame[s] - edge) < window
        rows = s[near_end]
        out[rows, :n_labels] += evidence[seg[rows]]
    return out
