"""Trajectory voting: one label per tracklet segment from per-frame scores, exclusive in time.

Per-frame scores of any labeler are pooled over the samples of each segment, then one
assignment over all segments decides: two segments that overlap in time never take the same
label. That assignment is a small integer programme (HiGHS through ``scipy.optimize.milp``):
for every label, the segments that could take it and are alive at one instant form a clique,
and each clique holds the label at most once (the maximal cliques of intervals are found at
their start frames).

Two scores are available:
- ``"likelihood"`` (ours): the sum over the segment's frames of log p(label | frame),
  the maximum-likelihood segment label if frames are independent;
- ``"power"`` (Ghorbani 2019): S = |T|^q (sum over frames given that label of c^p)^(1/p), the
  published trajectory vote, weighted by |T| so that segments of different length compare.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import Bounds, LinearConstraint, milp
from scipy.sparse import csr_matrix

from ..labeling import NULL, Constraint

#: log-probabilities below this are treated as this (one wrong frame must not veto a segment).
LOG_FLOOR = -12.0


@dataclass
class Samples:
    """Every scored sample of a take, flattened: the unit of the temporal step.

    Attributes:
        frame, slot: int64 ``(n,)``.
        logp: float32 ``(n, M + 1)``: per-frame log-probabilities over the labels and null
            (row-normalised), floored at :data:`LOG_FLOOR`.
        label, confidence: the per-frame decision (shared assignment step) and its confidence.
    """

    frame: np.ndarray
    slot: np.ndarray
    logp: np.ndarray
    label: np.ndarray
    confidence: np.ndarray


@dataclass
class Segments:
    """Segments (tracklets or pieces of them), ordered by (slot, start); ``[start, stop)`` frames."""

    slot: np.ndarray
    start: np.ndarray
    stop: np.ndarray

    def __len__(self) -> int:
        return int(self.slot.shape[0])


def split_segments(segments: Segments, cuts: dict[int, list[int]]) -> Segments:
    """Split segments at frames: ``cuts`` maps a slot to frames where a new segment must begin."""
    if not cuts:
        return segments
    cut_slot = np.concatenate([np.full(len(v), k, dtype=np.int64) for k, v in cuts.items()])
    cut_frame = np.concatenate([np.asarray(v, dtype=np.int64) for v in cuts.values()])
    # The segment each cut falls strictly inside (cuts on an edge or outside every segment do nothing).
    inside = segment_of(segments, cut_frame, cut_slot)
    keep = inside >= 0
    keep[keep] = cut_frame[keep] > segments.start[inside[keep]]
    if not keep.any():
        return segments
    # Every segment's start, plus each cut as a new start; sorted, each runs to the next start of
    # its slot or to its segment's end.
    key = np.unique(np.concatenate([segments.slot * (1 << 32) + segments.start,
                                    cut_slot[keep] * (1 << 32) + cut_frame[keep]]))
    slot, start = key >> 32, key & ((1 << 32) - 1)
    owner = segment_of(segments, start, slot)
    stop = segments.stop[owner].copy()
    nxt = np.flatnonzero(owner[1:] == owner[:-1])
    stop[nxt] = start[nxt + 1]
    return Segments(slot.astype(np.int64), start.astype(np.int64), stop.astype(np.int64))


def segment_of(segments: Segments, frame: np.ndarray, slot: np.ndarray) -> np.ndarray:
    """The segment of each sample ``(frame, slot)``, -1 if it lies in none."""
    key_start = segments.slot * (1 << 32) + segments.start
    key = slot.astype(np.int64) * (1 << 32) + frame
    i = np.searchsorted(key_start, key, side="right") - 1
    ok = (i >= 0)
    i = np.maximum(i, 0)
    ok &= (segments.slot[i] == slot) & (frame < segments.stop[i])
    return np.where(ok, i, -1)


def find_swaps(samples: Samples, seg: np.ndarray, segments: Segments, min_run: int = 6,
               penalty: float = 25.0, edge_penalty: float = 10.0) -> dict[int, list[int]]:
    """Frames where a segment's evidence flips from one label to another for good (a swap by the
    capture system without a gap). Binary segmentation: the best single change point of the
    summed log-probabilities, kept if it gains more than ``penalty`` nats, then each side again.
    A swap in a segment's first or last frames leaves too few frames for that: a run of fewer
    than ``min_run`` frames at either end that all prefer one other label is cut off if it gains
    more than ``edge_penalty`` nats (a frame's log-probabilities are floored at -12, so one
    frame that is sure of another label suffices).

    Returns ``{slot: [frames where a new segment begins]}``.
    """
    cuts: dict[int, list[int]] = {}
    order = np.lexsort((samples.frame, seg))
    seg_sorted = seg[order]
    bounds = np.searchsorted(seg_sorted, np.arange(len(segments) + 1))
    best = np.argmax(samples.logp, axis=1)
    # A segment whose frames all prefer one label has nothing to cut: that label is also the best
    # of its sum (each frame's log-probability of it is its highest), so neither test below fires.
    best_sorted = best[order]
    flips = np.flatnonzero((best_sorted[1:] != best_sorted[:-1]) & (seg_sorted[1:] == seg_sorted[:-1]))
    for s in np.unique(seg_sorted[flips + 1]):
        if s < 0:
            continue
        lo, hi = bounds[s], bounds[s + 1]
        if hi - lo > min_run:
            for frame in _edge_swaps(samples.logp[order[lo:hi]], best[order[lo:hi]],
                                     samples.frame[order[lo:hi]], min_run, edge_penalty):
                cuts.setdefault(int(segments.slot[s]), []).append(frame)
        if hi - lo < 2 * min_run:
            continue
        rows = order[lo:hi]
        votes = np.bincount(best[rows], minlength=samples.logp.shape[1])
        if (votes >= min_run).sum() < 2:  # no second label with a sustained run: nothing to split
            continue
        for frame in _change_points(samples.logp[rows], samples.frame[rows], min_run, penalty):
            cuts.setdefault(int(segments.slot[s]), []).append(int(frame))
    return cuts


def _edge_swaps(logp: np.ndarray, best: np.ndarray, frames: np.ndarray, min_run: int, penalty: float) -> list[int]:
    """Cut frames for short runs at either end of one segment (rows in frame order) that prefer
    another label than the segment's as a whole."""
    main = int(np.argmax(logp.sum(axis=0)))
    cuts = []
    for rows, cut_at in ((np.arange(len(best)), lambda n: int(frames[n])),
                         (np.arange(len(best))[::-1], lambda n: int(frames[len(best) - n]))):
        other = best[rows[0]]
        if other == main:
            continue
        n = int(np.argmax(best[rows] != other)) if (best[rows] != other).any() else len(rows)
        if n >= min_run or len(rows) - n < min_run:
            continue
        run = rows[:n]
        if (logp[run, other] - logp[run, main]).sum() > penalty:
            cuts.append(cut_at(n))
    return cuts


def _change_points(logp: np.ndarray, frames: np.ndarray, min_run: int, penalty: float) -> list[int]:
    n = len(logp)
    if n < 2 * min_run:
        return []
    csum = np.concatenate([np.zeros((1, logp.shape[1])), np.cumsum(logp, axis=0)])
    whole = csum[-1].max()
    cut = np.arange(min_run, n - min_run + 1)
    before = csum[cut]  # (C, L)
    after = csum[-1][None] - before
    # Best pair of different labels on the two sides: top two of each side suffice.
    b2, a2 = _top_two(before), _top_two(after)
    rows = np.arange(len(cut))
    gain = np.full(len(cut), -np.inf)
    for i in range(2):
        for j in range(2):
            bi, aj = b2[:, i], a2[:, j]
            g = before[rows, bi] + after[rows, aj] - whole
            gain = np.where(bi != aj, np.maximum(gain, g), gain)
    c = int(np.argmax(gain))
    if gain[c] <= penalty:
        return []
    at = cut[c]
    return (_change_points(logp[:at], frames[:at], min_run, penalty) + [int(frames[at])]
            + _change_points(logp[at:], frames[at:], min_run, penalty))


def _top_two(x: np.ndarray) -> np.ndarray:
    """``(C, 2)``: the columns of each row's second-largest and largest value (a full sort of every
    row costs several times more)."""
    first = np.argmax(x, axis=1)
    rest = x.copy()
    rest[np.arange(len(x)), first] = -np.inf
    return np.stack([np.argmax(rest, axis=1), first], axis=1)


def segment_weights(samples: Samples, seg: np.ndarray, n_segments: int, score: str = "likelihood",
                    p: float = 2.0, q: float = -0.5) -> tuple[np.ndarray, np.ndarray]:
    """Weights ``(S, M + 1)`` of each segment for each label (null last), higher is better, and
    each segment's number of scored samples ``(S,)``."""
    ok = seg >= 0
    seg, m1 = seg[ok], samples.logp.shape[1]
    count = np.bincount(seg, minlength=n_segments).astype(np.float64)
    if score == "likelihood":
        # Sums per segment as a sparse product: many times faster than np.add.at.
        member = csr_matrix((np.ones(len(seg)), (seg, np.arange(len(seg)))), shape=(n_segments, len(seg)))
        logp = samples.logp if ok.all() else samples.logp[ok]
        return np.asarray(member @ logp.astype(np.float64, copy=False)), count
    if score == "power":
        col = np.where(samples.label[ok] >= 0, samples.label[ok], m1 - 1).astype(np.int64)
        acc = np.bincount(seg * m1 + col, weights=samples.confidence[ok].astype(np.float64) ** p,
                          minlength=n_segments * m1).reshape(n_segments, m1)
        s = np.maximum(count, 1.0)[:, None] ** q * acc ** (1.0 / p)
        return s * count[:, None], count
    raise ValueError(f"unknown voting score {score!r}: 'likelihood' or 'power'")


#: Branch-and-bound nodes the integer programme may explore per solve: a bound on its work, never
#: on its time, so that the same take gives the same labels on any machine under any load. Hand
#: takes need one node (the root relaxation is integral on the han2018 raw takes, the glove and
#: the two-hand benchmark's); a body take labeled as a hand can need far more. Where the bound
#: stops the solver, the better of its best labeling so far and the greedy one is used, and the
#: vote refines no further.
MILP_NODES = 1000
#: Candidate (segment, label) pairs up to which a first look (a vote whose labels are evidence for
#: the vote that decides) solves its integer programme exactly; larger ones take its rounded
#: relaxation. Where two hands are mixed up, the exact programme's root alone can take minutes on a
#: few thousand frames; hands apart stay well under this.
FIRST_LOOK_PAIRS = 4000
#: The node bound does not bound the root: HiGHS's cutting planes and heuristics there are
#: unbounded, and a programme whose linear relaxation leaves many pairs undecided can spend many minutes
#: in them (a sparse take read with the dense han19 layout). Where the relaxation leaves more
#: candidate pairs fractional than this, it is rounded (as a first look's) and the solve counts as
#: work-limited. Hand takes leave none or a few hundred at most (two hands interlaced); a body take
#: read as a hand, up to about 300.
FRACTIONAL_PAIRS = 400


def exclusive_assignment(weights: np.ndarray, segments: Segments, locked: dict[int, int] | None = None,
                         candidates: int | None = None, node_limit: int = MILP_NODES,
                         switch: np.ndarray | None = None, facts: dict | None = None,
                         exact_pairs: int | None = None) -> np.ndarray:
    """The best label per segment (:data:`NULL` allowed) such that no two segments that overlap
    in time share a label. ``locked`` fixes some segments' labels.

    Args:
        weights: ``(S, M + 1)`` (see :func:`segment_weights`), null in the last column.
        segments: their frame ranges.
        locked: ``{segment: label or NULL}``.
        candidates: labels considered per segment (its best by weight; None: all); null is always
            one. Only labels that outweigh null are ever considered, so all of them stay few: a
            segment whose top labels are all taken by overlapping segments can still take its
            fifth (a thumb tip inside a fist that reads as the fingers it touches).
        switch: float ``(S,)``: nats that segment ``s`` pays for a label other than segment
            ``s - 1``'s, where the two are pieces of one trajectory (see :func:`switch_costs`); 0
            where they are not. A piece may then take any label that some piece of its trajectory
            finds useful.
        node_limit: branch-and-bound nodes a solve may explore (:data:`MILP_NODES`).
        facts: if given, ``facts["work_limited"]`` counts the solves stopped by ``node_limit``.
        exact_pairs: None: the integer programme decides. Otherwise, where the groups that clash hold
            more candidate pairs than this, its linear relaxation does, rounded greedily in the
            order of its values (no branch and bound, no cutting planes): for a first look, whose
            labels are only evidence for the vote that decides.

    Returns:
        int64 ``(S,)`` labels.
    """
    n, m1 = weights.shape
    m = m1 - 1
    locked = locked or {}
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    switch = np.zeros(n) if switch is None else np.array(switch, dtype=np.float64)
    switch[0] = 0.0  # the first segment follows none
    chain = np.cumsum(switch <= 0) - 1  # pieces of one trajectory joined by a paid switch
    top = np.argsort(-weights[:, :m], axis=1)[:, :min(candidates or m, m)]
    # A label weighing no more than null is never worth taking: null scores higher and frees the
    # label for others. Leaving such candidates out is exact and keeps the groups small. A piece
    # of a trajectory may also need a label that only its other pieces find useful.
    useful = np.zeros((n, m), dtype=bool)
    np.put_along_axis(useful, top, np.take_along_axis(weights, top, axis=1) > weights[:, m:m1], axis=1)
    useful = np.logical_or.reduceat(useful, np.flatnonzero(np.diff(chain, prepend=-1)), axis=0)[chain]
    allowed = np.concatenate([useful, np.ones((n, 1), dtype=bool)], axis=1)
    for s, label in locked.items():
        allowed[s] = False
        allowed[s, m if label == NULL else label] = True
    var_seg, var_lab = np.nonzero(allowed)
    # Shortcut: if every trajectory's best labels are already exclusive, that is optimal.
    best = _best_chains(np.where(allowed, weights, -np.inf), switch)
    if not label_conflicts(best, segments, m):
        return np.where(best == m, NULL, best)
    # Segments interact only through a shared candidate label over overlapping frames, or as
    # pieces of one trajectory: solve just the groups of interacting segments that hold a clash;
    # every other segment keeps its best.
    group = _interacting_groups(var_seg, var_lab, segments, m, n, chain)
    clashing = np.unique(group[_clashing(best, segments, m)])
    inside = np.isin(group, clashing)
    out = best.copy()
    keep_var = inside[var_seg]
    sub = np.flatnonzero(inside)
    index = np.full(n, -1, dtype=np.int64)
    index[sub] = np.arange(len(sub))
    sub_locked = {int(index[s]): lab for s, lab in locked.items() if inside[s]}
    sub_segments = Segments(segments.slot[sub], segments.start[sub], segments.stop[sub])
    sub_var = index[var_seg[keep_var]]
    out[sub], stopped = _milp_assignment(weights[sub], sub_segments, sub_var, var_lab[keep_var],
                                         sub_locked, node_limit, switch[sub],
                                         relaxed=exact_pairs is not None and len(sub_var) > exact_pairs)
    if facts is not None:
        facts["work_limited"] = facts.get("work_limited", 0) + int(stopped)
    return np.where(out == m, NULL, out)


def _best_chains(weights: np.ndarray, switch: np.ndarray) -> np.ndarray:
    """The best labels ``(S,)`` (null as ``M``) without exclusivity: each trajectory's pieces by
    dynamic programming over its chain (keep the label, or pay ``switch`` to change it)."""
    n = len(weights)
    linked = switch > 0
    # Position of each segment within its chain; the chains are processed level by level.
    start = np.flatnonzero(~linked)
    pos = np.arange(n) - np.repeat(start, np.diff(np.append(start, n)))
    score = weights.copy()
    for level in range(1, int(pos.max(initial=0)) + 1):
        s = np.flatnonzero(pos == level)
        prev = score[s - 1]
        score[s] += np.maximum(prev, prev.max(axis=1, keepdims=True) - switch[s, None])
    label = np.argmax(score, axis=1)  # final for the last piece of each chain
    for level in range(int(pos.max(initial=0)), 0, -1):
        s = np.flatnonzero(pos == level)
        prev = score[s - 1]
        keep = prev[np.arange(len(s)), label[s]] >= prev.max(axis=1) - switch[s]
        label[s - 1] = np.where(keep, label[s], np.argmax(prev, axis=1))
    return label


def _milp_assignment(weights: np.ndarray, segments: Segments, var_seg: np.ndarray, var_lab: np.ndarray,
                     locked: dict[int, int], node_limit: int, switch: np.ndarray,
                     relaxed: bool = False) -> tuple[np.ndarray, bool]:
    """The exclusive assignment as an integer programme over the candidate (segment, label) pairs
    (and one switch variable per paid link between pieces of a trajectory); returns labels with
    null as ``M``, and whether the work bound stopped the solver (then the better of its labeling
    and :func:`_greedy_assignment`'s; or its rounded relaxation, where that leaves more than
    :data:`FRACTIONAL_PAIRS` pairs fractional). ``relaxed``: the linear relaxation instead, its pairs
    taken greedily in the order of their values."""
    n, m1 = weights.shape
    m = m1 - 1
    n_pairs = len(var_seg)
    links = np.flatnonzero(switch > 0)  # segment s is linked to s - 1
    n_vars = n_pairs + len(links)
    rows, cols, vals = [var_seg], [np.arange(n_pairs)], [np.ones(n_pairs)]
    # Each segment takes exactly one label (null included).
    n_rows = n
    # A switch variable is at least z(s - 1, l) - z(s, l) for every label l of s - 1: it is 1
    # wherever the two pieces differ.
    # var_seg is sorted (labels sorted within a segment): segment s's variables are
    # seg_vars[s]:seg_vars[s + 1], and (segment, label) keys are sorted too.
    seg_vars = np.searchsorted(var_seg, np.arange(n + 1))
    key = var_seg * m1 + var_lab
    count = seg_vars[links] - seg_vars[links - 1]  # one row per variable of the piece before
    j = np.repeat(np.arange(len(links)), count)
    before = np.arange(int(count.sum())) + np.repeat(seg_vars[links - 1] - np.cumsum(count) + count, count)
    want = np.repeat(links, count) * m1 + var_lab[before]
    after = np.minimum(np.searchsorted(key, want), max(n_pairs - 1, 0))
    has = key[after] == want
    # Row entries in order: the switch (+1), z(s - 1, l) (-1), z(s, l) (+1) where s has label l.
    entry = np.stack([n_pairs + j, before, after], axis=1).ravel()
    sign = np.tile([1.0, -1.0, 1.0], len(before))
    keep = np.stack([np.ones(len(before), dtype=bool), np.ones(len(before), dtype=bool), has], axis=1).ravel()
    rows.append(np.repeat(n_rows + np.arange(len(before)), 3)[keep])
    cols.append(entry[keep])
    vals.append(sign[keep])
    n_rows += len(before)
    n_fixed = n_rows
    # Cliques: per label, the candidate segments alive at each candidate's start frame.
    for label in range(m):
        v = np.flatnonzero(var_lab == label)
        if len(v) < 2:
            continue
        s = var_seg[v]
        start, stop = segments.start[s], segments.stop[s]
        alive = (start[None, :] <= start[:, None]) & (start[:, None] < stop[None, :])  # (clique at i, member j)
        sizes = alive.sum(axis=1)
        keep = np.flatnonzero(sizes >= 2)
        if not len(keep):
            continue
        _, first = np.unique(np.packbits(alive[keep], axis=1), axis=0, return_index=True)
        for i in keep[np.sort(first)]:
            members = v[alive[i]]
            rows.append(np.full(len(members), n_rows))
            cols.append(members)
            vals.append(np.ones(len(members)))
            n_rows += 1
    a = csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n_rows, n_vars))
    lb_rows = np.concatenate([np.ones(n), np.zeros(n_rows - n)])
    ub_rows = np.concatenate([np.ones(n), np.full(n_fixed - n, np.inf), np.ones(n_rows - n_fixed)])
    lower = np.zeros(n_vars)
    for s, label in locked.items():
        col = m if label == NULL else label
        lower[np.flatnonzero((var_seg == s) & (var_lab == col))] = 1.0
    cost = np.concatenate([-weights[var_seg, var_lab], switch[links]])
    problem = {"constraints": LinearConstraint(a, lb_rows, ub_rows), "bounds": Bounds(lower, np.ones(n_vars)),
               "options": {"node_limit": int(node_limit)}}
    if relaxed or n_pairs > FRACTIONAL_PAIRS:
        lp = milp(cost, integrality=np.zeros(n_vars), **problem)
        # Rounded to ignore the last digits' noise: ties then go by gain, segment and label.
        values = None if lp.x is None else np.round(lp.x[:n_pairs], 6)
        too_hard = values is not None and int(((values > 0) & (values < 1)).sum()) > FRACTIONAL_PAIRS
        if relaxed or too_hard:
            return _greedy_assignment(weights, segments, var_seg, var_lab, locked, switch, values), not relaxed
    res = milp(cost, integrality=np.concatenate([np.ones(n_pairs), np.zeros(len(links))]), **problem)
    if res.status in (2, 3):  # all null but the locks is always a labeling: never here
        raise ValueError(f"no exclusive labeling exists: {res.message}")
    stopped = res.status != 0  # the work bound (HiGHS's node or solution limit) stopped the search
    greedy = _greedy_assignment(weights, segments, var_seg, var_lab, locked, switch) if stopped else None
    if res.x is None:
        return greedy, True
    out = np.full(n, m, dtype=np.int64)
    chosen = res.x[:n_pairs] > 0.5
    out[var_seg[chosen]] = var_lab[chosen]
    if greedy is not None and _objective(weights, greedy, switch) > _objective(weights, out, switch):
        out = greedy
    return out, stopped


def _objective(weights: np.ndarray, labels: np.ndarray, switch: np.ndarray) -> float:
    """The integer programme's objective of ``labels`` ``(S,)`` (null as ``M``): the weights taken,
    less the switches paid between linked pieces that differ."""
    taken = weights[np.arange(len(labels)), labels].sum()
    linked = np.flatnonzero(switch > 0)
    return float(taken - switch[linked][labels[linked] != labels[linked - 1]].sum())


def _greedy_assignment(weights: np.ndarray, segments: Segments, var_seg: np.ndarray, var_lab: np.ndarray,
                       locked: dict[int, int], switch: np.ndarray, priority: np.ndarray | None = None) -> np.ndarray:
    """An exclusive labeling (null as ``M``) without search: the locks, then the candidate
    (segment, label) pairs by ``priority`` ``(pairs,)`` where given, then by how much they beat
    null, best first (ties by segment and label),
    each taken where its segment is still free and no overlapping segment holds the label. The
    floor a bounded solve never falls below; deterministic."""
    n, m1 = weights.shape
    m = m1 - 1
    out = np.full(n, -1, dtype=np.int64)
    first = int(segments.start.min(initial=0))
    # Frames each label is held in (from the first segment's start): a slice tells whether a
    # segment's frames are free of it.
    held = np.zeros((m, int(segments.stop.max(initial=first)) - first), dtype=bool)
    start, stop = (segments.start - first).tolist(), (segments.stop - first).tolist()
    for s, label in sorted(locked.items()):
        out[s] = m if label == NULL else label
        if label != NULL:
            held[label, start[s]:stop[s]] = True
    real = var_lab < m
    seg_r, lab_r = var_seg[real], var_lab[real]
    gain = weights[seg_r, lab_r] - weights[seg_r, m]
    order = np.lexsort((lab_r, seg_r, -gain) + (() if priority is None else (-priority[real],)))
    order = order[gain[order] > 0]
    for s, label in zip(seg_r[order].tolist(), lab_r[order].tolist()):
        if out[s] >= 0 or held[label, start[s]:stop[s]].any():
            continue
        out[s] = label
        held[label, start[s]:stop[s]] = True
    out[out < 0] = m
    return out


def _interacting_groups(var_seg: np.ndarray, var_lab: np.ndarray, segments: Segments, m: int,
                        n: int, chain: np.ndarray) -> np.ndarray:
    """``(S,)`` group id: segments linked by a shared real candidate label over overlapping frames,
    or pieces of one trajectory (one ``chain``)."""
    parent = np.arange(n)
    first = np.flatnonzero(np.diff(chain, prepend=-1))
    parent[:] = first[chain]  # a chain's pieces start out in its first piece's group

    def find(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for label in np.unique(var_lab[var_lab < m]):
        segs = var_seg[var_lab == label]
        segs = segs[np.argsort(segments.start[segs], kind="stable")]
        reach, head = -1, -1
        for sg in segs.tolist():  # a sweep: overlapping runs of this label's candidates join up
            if segments.start[sg] < reach:
                a, b = find(head), find(sg)
                if a != b:
                    parent[b] = a
                reach = max(reach, int(segments.stop[sg]))
            else:
                head, reach = sg, int(segments.stop[sg])
    return np.array([find(i) for i in range(n)])


def _clashing(labels: np.ndarray, segments: Segments, m: int) -> np.ndarray:
    """Segments whose real label overlaps another segment with the same label."""
    out = np.zeros(len(labels), dtype=bool)
    named = np.flatnonzero(labels < m)
    for label in np.unique(labels[named]):
        idx = named[labels[named] == label]
        idx = idx[np.argsort(segments.start[idx], kind="stable")]
        if len(idx) < 2:
            continue
        running = np.maximum.accumulate(segments.stop[idx])
        hit = np.flatnonzero(segments.start[idx][1:] < running[:-1]) + 1
        for h in hit.tolist():  # the clash is with some earlier segment still running
            out[idx[h]] = True
            out[idx[:h][segments.stop[idx[:h]] > segments.start[idx[h]]]] = True
    return out


def tracklet_share(segments: Segments) -> np.ndarray:
    """float ``(S,)``: each segment's share of the frames of its tracklet, the run of segments of
    one slot that follow each other without a gap (tracklets end at gaps). A piece cut from a
    long trajectory is no flickering ghost: it pays only its share of the per-tracklet null
    prior. Cut at crossings, a piece paying the whole prior went null in 261 more han2018 samples.
    """
    group = np.cumsum(~_joined(segments)) - 1
    length = (segments.stop - segments.start).astype(np.float64)
    return length / np.bincount(group, weights=length)[group]


def vote(samples: Samples, segments: Segments, locked_at: np.ndarray, score: str = "likelihood", p: float = 2.0,
         q: float = -0.5, split_swaps: bool = True, refine: int = 3,
         null_prior: tuple[float, float] = (0.0, 0.0), crossings: dict[int, list[int]] | None = None,
         switch_cost: tuple[float, float] = (0.0, 0.0), exact_pairs: int | None = None
         ) -> tuple[Segments, np.ndarray, np.ndarray, dict]:
    """Trajectory voting end to end: split swaps, weigh, assign exclusively, refine where it clashed.

    A segment that lost its best label to an overlapping segment is cut at the edges of that
    overlap and the pieces decided again (at most ``refine`` rounds): a short overlap must not
    cost a long segment its label.

    Args:
        samples: the scored samples.
        segments: tracklets (already cut at the edges of user constraints).
        locked_at: int ``(F, P)``: the locked label of each sample (:data:`NULL` = ghost), or a
            value below -1 where unlocked.
        null_prior: ``(per tracklet, per sample)`` nats added to every segment's null weight: a
            label must beat null by this much. Frames are scored as if independent, so a ghost
            flickering for a few frames near a hidden marker's spot collects a few nats per frame
            for that marker; real markers collect several times more. The pieces of one tracklet
            (cut at swaps, crossings or constraints) share its part in proportion to their
            length (:func:`tracklet_share`). Fitted per layout on synthetic validation takes by
            ``python -m training.confidence``.
        crossings: ``{slot: [frames]}`` where two trajectories may have traded markers
            (:func:`..tracklets.find_crossings`); cut when ``split_swaps``.
        switch_cost: nats a trajectory pays to change its label where the vote cut it: at a
            crossing, and at any other cut (where its evidence flipped, or where it clashed).
            Per-frame evidence is shared by neighbouring frames, so a run of frames that read a
            pinched fingertip as the thumb's is no proof that the trajectory changed marker; a
            piece may still change label where its evidence outweighs the cost. The cuts of
            ``segments`` as given (a reviewer's splits and locks) are free.
        exact_pairs: clashes of more candidate pairs than this are settled by the integer
            programme's rounded relaxation (:func:`exclusive_assignment`): a first look.

    Returns:
        the final segments, their labels int64 ``(S,)``, the segment of each sample ``(n,)`` and
        facts (swaps split, refinement rounds, assignments stopped by their time limit).
    """
    free = _joins(segments)
    crossing_at: set[tuple[int, int]] = set()
    if split_swaps and crossings:
        segments = split_segments(segments, crossings)
        crossing_at = {(int(slot), int(f)) for slot, frames in crossings.items() for f in frames}
    seg = segment_of(segments, samples.frame, samples.slot)
    swaps = find_swaps(samples, seg, segments) if split_swaps else {}
    if swaps:
        segments = split_segments(segments, swaps)
        seg = segment_of(segments, samples.frame, samples.slot)
    facts = {"swaps_split": int(sum(len(v) for v in swaps.values())), "refined": 0, "work_limited": 0}
    if score == "likelihood":  # summed in float64 in every round: convert once
        samples = replace(samples, logp=samples.logp.astype(np.float64, copy=False))
    while True:
        weights, count = segment_weights(samples, seg, len(segments), score, p, q)
        weights[:, -1] += null_prior[0] * tracklet_share(segments) + null_prior[1] * count
        first_locked = locked_at[segments.start, segments.slot]
        locked = {int(i): int(first_locked[i]) for i in np.flatnonzero(first_locked >= NULL)}
        switch = switch_costs(segments, free, crossing_at, switch_cost)
        labels = exclusive_assignment(weights, segments, locked, switch=switch, facts=facts,
                                      exact_pairs=exact_pairs)
        labels[(count == 0) & (first_locked < NULL)] = NULL  # never scored (beyond the cap): no evidence
        if facts["refined"] >= refine or facts["work_limited"]:  # refining a bounded solve is more of the same
            break
        cuts = _clash_cuts(weights, labels, segments, first_locked >= NULL)
        if not cuts:
            break
        segments = split_segments(segments, cuts)
        seg = segment_of(segments, samples.frame, samples.slot)
        facts["refined"] += 1
    return segments, labels, seg, facts


def _joined(segments: Segments) -> np.ndarray:
    """bool ``(S,)``: segment ``s`` begins right where segment ``s - 1`` of its slot ends."""
    out = np.zeros(len(segments), dtype=bool)
    out[1:] = (segments.slot[1:] == segments.slot[:-1]) & (segments.start[1:] == segments.stop[:-1])
    return out


def _joins(segments: Segments) -> set[tuple[int, int]]:
    """``(slot, frame)`` where a segment begins right where the one before it in its slot ends."""
    j = np.flatnonzero(_joined(segments))
    return set(zip(segments.slot[j].tolist(), segments.start[j].tolist()))


def switch_costs(segments: Segments, free: set[tuple[int, int]], crossing_at: set[tuple[int, int]],
                 cost: tuple[float, float]) -> np.ndarray:
    """float ``(S,)``: what segment ``s`` pays for a label other than segment ``s - 1``'s: ``cost[0]``
    where a crossing cut them apart, ``cost[1]`` where any other cut of the vote did, 0 where they
    are not pieces of one trajectory or where the cut is in ``free``."""
    out = np.zeros(len(segments))
    for j in np.flatnonzero(_joined(segments)).tolist():
        at = (int(segments.slot[j]), int(segments.start[j]))
        if at not in free:
            out[j] = cost[0] if at in crossing_at else cost[1]
    return out


def _clash_cuts(weights: np.ndarray, labels: np.ndarray, segments: Segments,
                locked: np.ndarray) -> dict[int, list[int]]:
    """Where a segment lost its best label to overlapping segments: cut it at their edges."""
    m = weights.shape[1] - 1
    best = np.argmax(weights[:, :m], axis=1)
    lost = np.flatnonzero((labels != best) & (weights[np.arange(len(labels)), best] > weights[:, m]) & ~locked)
    cuts: dict[int, list[int]] = {}
    for s in lost:
        rivals = np.flatnonzero((labels == best[s]) & (segments.start < segments.stop[s])
                                & (segments.start[s] < segments.stop))
        edges = [int(e) for r in rivals for e in (segments.start[r], segments.stop[r])
                 if segments.start[s] < e < segments.stop[s]]
        if edges:
            cuts.setdefault(int(segments.slot[s]), []).extend(edges)
    return cuts


def label_conflicts(labels: np.ndarray, segments: Segments, m: int) -> bool:
    """True if two overlapping segments share a real label (``labels`` ``(S,)``; ``m`` or more: null)."""
    named = np.flatnonzero(labels < m)
    order = named[np.lexsort((segments.start[named], labels[named]))]
    # Sorted by start within a label; an overlap exists iff some start is before the running
    # maximum stop of the earlier segments of that label.
    for label in np.unique(labels[named]):
        idx = order[labels[order] == label]
        if len(idx) < 2:
            continue
        running = np.maximum.accumulate(segments.stop[idx])
        if (segments.start[idx][1:] < running[:-1]).any():
            return True
    return False


def check_constraints(constraints: list[Constraint], n_labels: int) -> None:
    """Reject constraints that cannot all hold: a label outside the layout, or one label locked on
    two slots over overlapping frames."""
    for c in constraints:
        if not (c.label == NULL or 0 <= c.label < n_labels):
            raise ValueError(f"constraint on slot {c.slot}: label {c.label} is not in the layout")
    named = [c for c in constraints if c.label >= 0]
    for i, a in enumerate(named):
        for b in named[i + 1:]:
            if a.label != b.label or a.slot == b.slot or b.start >= a.stop or a.start >= b.stop:
                continue
            raise ValueError(f"constraints conflict: label {a.label} is locked on slot {a.slot} (frames "
                             f"{a.start}-{a.stop - 1}) and on slot {b.slot} (frames {b.start}-{b.stop - 1})")
