"""The entry points the CLI, batch and Blender share.

``label_take``: a raw take to a Labeling. ``solve_take``: a labeled take to a solved hand.

Take -> tracklets -> per-frame scores (any labeler) -> user constraints -> temporal decision
(trajectory voting, N-best Viterbi, or none) -> calibrated confidence per segment.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from .errors import MocapInputError
from .hand.calibrate import Calibration, calibrate
from .hand.ik import GATE, MIN_MARKERS, Fit, HandSolver
from .hands import (
    HandNaming,
    Hands,
    SideEvidence,
    decide_sides,
    find_hands,
    handedness,
    identity_swaps,
    replace_valid,
    swap_frames,
    swap_ranges,
)
from .labelers import METHODS, FrameBatch, Labeler, make_labeler, pack_frames
from .labelers.assign import assign, row_log_probabilities
from .labeling import EMPTY, NULL, Constraint, Labeling, layout_markers, segments_from_runs
from .layout import Layout
from .props import Prop, find_props, prop_mask, rigid_groups
from .take import Take
from .temporal.confidence import (
    load_calibration,
    load_continuity,
    load_null_prior,
    load_partner,
    load_switch_cost,
    segment_evidence,
)
from .temporal.continuity import continuity_logp
from .temporal.partners import RigidPairs, partner_logp, rigid_pairs, take_distances
from .temporal.stride import stride_for, strided_scores
from .temporal.voting import (
    LOG_FLOOR,
    Samples,
    Segments,
    check_constraints,
    split_segments,
    vote,
)
from .tracklets import find_crossings, find_tracklets
from .windows import WINDOW_FRAMES, label_in_windows, relabel_around

#: Temporal modes: ``vote`` (trajectory voting with exclusivity, the default), ``viterbi``
#: (Alexanderson's N-best + Kalman), ``none`` (per-frame labels as they come).
TEMPORAL = ("vote", "viterbi", "none")

#: Observations scored per frame at most: beyond this, the points nearest the frame's median
#: (the hand) are kept, so a take with thousands of ghosts per frame costs bounded time.
MAX_POINTS_PER_LABEL = 3


def _cap(layout: Layout) -> int:
    return max(MAX_POINTS_PER_LABEL * len(layout), len(layout) + 24)


def _pack(take: Take, cap: int, chunk: int = 4096) -> FrameBatch:
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


def _take_key(take: Take) -> tuple:
    """What identifies a take's positions for the caches below (a re-solve labels the same ones)."""
    return take.positions.shape, take.rate, hash(take.positions.tobytes())


#: Takes whose per-take results are remembered (a re-solve after a reviewer's correction labels
#: the same positions again).
REMEMBERED_TAKES = 4


def _remembered(cache: dict, key: tuple, make: Callable[[], object]):
    """``make()`` for ``key``, kept in ``cache`` for the last :data:`REMEMBERED_TAKES` keys."""
    if key not in cache:
        while len(cache) >= REMEMBERED_TAKES:
            cache.pop(next(iter(cache)))
        cache[key] = make()
    return cache[key]


#: The crossings of the last few takes (a tenth of a second on a 10,000-frame take).
_CROSSINGS: dict[tuple, dict[int, list[int]]] = {}


def _crossings(take: Take) -> dict[int, list[int]]:
    found = _remembered(_CROSSINGS, _take_key(take), lambda: find_crossings(take))
    return {slot: list(frames) for slot, frames in found.items()}  # callers may extend theirs


#: The hands found in the last few takes.
_HANDS: dict[tuple, Hands] = {}


def _hands(take: Take, layout: Layout, hands: str | int, ignore: np.ndarray | None,
           swaps: np.ndarray | None = None) -> Hands:
    """:func:`.hands.find_hands`, remembered for the last few takes (a copy: callers change ``both``)."""
    key = (*_take_key(take), tuple(layout.names), str(hands),
           None if ignore is None else ignore.tobytes(), None if swaps is None else swaps.tobytes())
    found = _remembered(_HANDS, key, lambda: find_hands(take, layout, hands, ignore=ignore, swaps=swaps))
    return replace(found, both=found.both.copy(), hand=found.hand.copy(), info=dict(found.info))


#: The rigid groups of the last few takes (:func:`.props.rigid_groups`: the take's own, whatever
#: its labels; 0.2 s of a 10,000-frame two-hand take).
_RIGID_GROUPS: dict[tuple, list[np.ndarray]] = {}


def _labeler(method: str, layout: Layout, model, fit: np.ndarray | None, start: np.ndarray | None, take: Take,
             batch):
    if method == "gmm":
        if fit is None:  # no take of the performer: the layout's synthetic range of motion stands in
            return _matched_side(_rom_gmm(layout), batch)
        lab = make_labeler("gmm", layout)
        try:
            lab.fit(fit)
        except ValueError as exc:  # the fitting take lacks what the GMMs need (the rigid triangle, samples)
            raise MocapInputError("--fit", f"cannot fit gmm on this labeled take: {exc}") from None
        return lab
    if method == "nearest":
        if start is None:  # seed the tracker with our own labels of the first frame that has points
            first = int(np.argmax(batch.mask.any(axis=1)))
            seed = make_labeler("set", layout)
            labels, _ = assign(seed.scores(batch.points[first:first + 1], batch.mask[first:first + 1]),
                               batch.mask[first:first + 1])
            start = np.full((len(layout), 3), np.nan)
            ok = labels[0] >= 0
            start[labels[0][ok]] = batch.points[first][ok]
        return make_labeler("nearest", layout, start=start)
    return make_labeler(method, layout, model)


#: ``gmm`` labelers fitted on a layout's synthetic range of motion, by layout name and content: a
#: fit takes seconds, and batch runs and Blender re-solves label many takes with one layout.
_ROM_GMMS: dict[tuple[str, str], Labeler] = {}
#: Hand sizes (relative to the range of motion's average hand) and sides tried for a take labeled
#: by a range-of-motion ``gmm``: its Gaussians sit in metres in the back-of-hand frame, so a hand
#: 10 % smaller than the fitted one leaves its markers outside them (two synthetic takes of
#: 0.165 and 0.171 m hands: 2.6 and 0.0 % right unscaled).
ROM_SCALES = (0.88, 0.94, 1.0, 1.06, 1.12)


def _rom_gmm(layout: Layout) -> Labeler:
    """A right-hand ``gmm`` labeler fitted on ``layout``'s synthetic range of motion (cached)."""
    from .synth.generate import range_of_motion

    key = (layout.name, repr(layout.names))
    if key not in _ROM_GMMS:
        _ROM_GMMS[key] = make_labeler("gmm", layout).fit(range_of_motion(layout, side="right"))
    return _ROM_GMMS[key]


class _Fitted(Labeler):
    """Another labeler's scores of the take brought to the hand it was fitted on: positions divided
    by ``scale`` and, for a left hand, mirrored in x (the model's hands are exact mirrors, so one
    right-hand fit serves both sides)."""

    def __init__(self, inner: Labeler, scale: float = 1.0, mirror: bool = False) -> None:
        self.inner, self.layout, self.name = inner, inner.layout, inner.name
        self.factor = np.array([-1.0 if mirror else 1.0, 1.0, 1.0]) / scale

    def scores(self, points: np.ndarray, mask: np.ndarray) -> np.ndarray:
        return self.inner.scores((points * self.factor).astype(points.dtype), mask)


def _matched_side(labeler: Labeler, batch: FrameBatch, sample: int = 100) -> Labeler:
    """``labeler`` (fitted on the average right hand) scaled and mirrored as best fits up to
    ``sample`` frames spread over the take, judged by the total score of each frame's best
    assignment: hand size and side are not known before labeling. (The count of labeled points
    picked the wrong side of a left-hand take: 7.9 % right against 62.2 % mirrored.)"""
    rows = np.unique(np.linspace(0, len(batch.mask) - 1, min(sample, len(batch.mask))).astype(int))
    points, mask = batch.points[rows], batch.mask[rows]
    best, best_total = labeler, -np.inf
    for mirror in (False, True):
        for scale in ROM_SCALES:
            candidate = _Fitted(labeler, scale, mirror)
            scores = candidate.scores(points, mask)
            labels, _ = assign(scores, mask)
            col = np.where(labels >= 0, labels, scores.shape[2] - 1)
            total = np.take_along_axis(scores, col[..., None], axis=2)[..., 0][mask].sum()
            if total > best_total:
                best, best_total = candidate, total
    return best


def _apply_constraints(scores: np.ndarray, slots: np.ndarray, mask: np.ndarray,
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


#: Per-frame labelers that label two hands (each hand's points scored on their own, then decided jointly).
JOINT_METHODS = ("set", "perm", "cnn")
#: The hands' second look is taken right after the first vote, before the evidence of partners
#: and continuity is read off it (one vote fewer: 1.3 s of a 10,000-frame take), where it offers
#: at most this share of that vote's segments to both hands: hands apart, as han2018's (about 1 %
#: of segments, labels identical to a look after the whole labeling). Hands that touch (5-40 %)
#: take it after the whole labeling, as that evidence then reads off fewer wrong nulls
#: (interacting synthetic takes: 99.72 % of instances against 99.57 % looking early).
LOOK_EARLY_SHARE = 0.03
#: Log-score of a label of the other hand (below the vote's floor: never chosen per frame).
_OTHER_HAND = -30.0


class _HandLabels:
    """The labels a take is decided over: the layout's M for one hand, 2M for two (hand 0's first,
    in the order of :func:`.hands.find_hands` until the sides are known)."""

    def __init__(self, layout: Layout, hands: int):
        self.layout, self.hands = layout, hands
        m = len(layout)
        self.names = list(layout.names) if hands == 1 else [f"{h}:{n}" for h in range(hands) for n in layout.names]
        self.m = m

    def __len__(self) -> int:
        return self.m * self.hands

    def rigid_pairs(self) -> RigidPairs:
        """The layout's rigid pairs, once per hand (never across hands)."""
        one = rigid_pairs(self.layout)
        if self.hands == 1:
            return one
        return RigidPairs(np.concatenate([one.pairs + h * self.m for h in range(self.hands)]),
                          np.tile(one.distance, self.hands), np.tile(one.tolerance, self.hands))

    def hand_pairs(self, rigid: RigidPairs, h: int) -> RigidPairs:
        """The pairs of ``rigid`` (from :meth:`rigid_pairs`) within hand ``h``; all of them for one hand."""
        if self.hands == 1:
            return rigid
        own = rigid.pairs[:, 0] // self.m == h
        return RigidPairs(rigid.pairs[own], rigid.distance[own], rigid.tolerance[own])

    def to_internal(self, label: int, order: list[int]) -> int:
        """A final label (sides' order: left hand first) as the internal one (hands' order)."""
        if label < 0:
            return label
        final_hand, index = divmod(label, self.m)
        return order.index(final_hand) * self.m + index


def _hand_order(sides: Sequence[str]) -> list[int]:
    """Final place of each hand (left first) from the hands' sides in their found order."""
    return [0 if s == "left" else 1 for s in sides]


def other_named_points(take: Take, layout: Layout, naming: HandNaming | None = None) -> np.ndarray | None:
    """bool ``(P,)``: slots the file already names that are no marker of ``layout`` (in any side's
    naming): a labeled body or prop, kept out of the hands. None where there are none, or where
    keeping them out would leave under half the layout's markers in the median frame (then the
    names are another labeling of the hand, and everything is relabeled)."""
    from .hands import NAMINGS, SIDES

    own = set(layout.names)
    for conv in ([naming] if naming is not None else [HandNaming(k) for k in NAMINGS]):
        for side in SIDES:
            own.update(conv.names(side, layout))
    out = ~take.unlabeled & np.array([n not in own for n in take.names], dtype=bool)
    if not out.any():
        return None
    # Named points are a body around the hand only where the hand is left to label: a file whose
    # every point has a name of its own (a hand labeled with another layout's names) is relabeled.
    offered = take.valid[:, ~out].sum(axis=1)
    if np.median(offered[take.valid.any(axis=1)]) < len(layout) / 2:
        return None
    return out


def _hand_scores(take: Take, layout: Layout, members: np.ndarray, batch: FrameBatch, labeler: Labeler,
                 rows: np.ndarray, segments: Segments, stride: int, every: np.ndarray) -> np.ndarray:
    """One hand's scores ``(R, K, M + 1)`` of the ``rows`` (frame indices) of the joint ``batch``, in
    its columns: the points ``members`` (bool ``(F, P)``) offers to the hand, scored by ``labeler``
    on their own (every ``stride``-th frame of each of the ``segments``, and every frame where
    ``every`` (bool ``(F,)``): :func:`.temporal.stride.strided_scores`); NaN where the hand was not
    offered the point."""
    m = len(layout)
    mask, slots = batch.mask[rows], batch.slots[rows]
    frames, k = mask.shape
    out = np.full((frames, k, m + 1), np.nan, dtype=np.float32)
    column = np.full((frames, take.n_points), -1, dtype=np.int64)  # joint column of each (frame, slot)
    f_idx, k_idx = np.nonzero(mask)
    column[f_idx, slots[f_idx, k_idx]] = k_idx
    positions = np.where(members[rows][..., None], take.positions[rows], np.nan).astype(np.float32)
    part = _pack(replace(take, positions=positions, residuals=None, filled=None), _cap(layout))
    scores = strided_scores(labeler.scores, part, segments, stride, frames=rows, every=every[rows])
    pf, pk = np.nonzero(part.mask)
    jk = column[pf, part.slots[pf, pk]]
    ok = jk >= 0
    out[pf[ok], jk[ok]] = scores[pf[ok], pk[ok]]
    return out


#: One take's per-hand scores with the points each hand was offered: labeling the take again
#: (the hands traded places; a reviewer's re-solve) scores only the frames whose points changed.
_HAND_SCORES: dict[tuple, list[tuple[np.ndarray, np.ndarray]]] = {}
#: Bytes of scores kept at most (a long take's are scored afresh rather than held).
HAND_SCORES_BYTES = 256 * 2 ** 20


#: Hands whose centres are nearer than this (metres) are scored on every frame, whatever the
#: stride: where they touch, which points a hand holds changes from frame to frame.
NEAR_HANDS = 0.15


def _hands_near(found: Hands) -> np.ndarray:
    """bool ``(F,)``: frames where the two hands' centres are nearer than :data:`NEAR_HANDS`."""
    with np.errstate(invalid="ignore"):
        return np.linalg.norm(found.centre[:, 0] - found.centre[:, 1], axis=1) < NEAR_HANDS


def _all_hand_scores(take: Take, layout: Layout, members: np.ndarray, batch: FrameBatch, labeler: Labeler,
                     segments: Segments, stride: int, every: np.ndarray,
                     known: Sequence[tuple[np.ndarray, np.ndarray]] = ()) -> np.ndarray:
    """:func:`_hand_scores` of every frame, re-using ``known`` ``(members, scores)`` of this take
    and those kept of the last take labeled, where a hand was offered the same points (the frames
    where it was not are scored again). ``known`` scores not kept are the caller's to give up:
    one is changed in place (a long take's are hundreds of megabytes)."""
    key = (*_take_key(take), getattr(labeler, "path", id(labeler)), batch.mask.shape, tuple(layout.names), stride)
    kept = _HAND_SCORES.get(key, [])
    best, changed = None, None
    for old_members, old_scores in [*known, *kept]:
        rows = np.flatnonzero((old_members != members).any(axis=1))
        if changed is None or len(rows) < len(changed):
            best, changed = old_scores, rows
    if best is None or len(changed) > 0.5 * len(members):
        scores = _hand_scores(take, layout, members, batch, labeler, np.arange(take.n_frames), segments, stride, every)
    else:
        scores = best.copy() if any(best is s for _, s in kept) else best
        if len(changed):
            scores[changed] = _hand_scores(take, layout, members, batch, labeler, changed, segments, stride,
                                           every)
    if scores.nbytes * 4 <= HAND_SCORES_BYTES:  # both hands, before and after a second look
        if key not in _HAND_SCORES:
            _HAND_SCORES.clear()
            _HAND_SCORES[key] = []
        entries = _HAND_SCORES[key]
        entries.append((members.copy(), scores))
        del entries[:-4]
    return scores


def _joint_scores(hand_scores: Sequence[np.ndarray], found: Hands, batch: FrameBatch,
                  rows: np.ndarray) -> np.ndarray:
    """Joint per-frame scores ``(R, K, 2M + 1)`` of the ``rows`` of a two-hand take from each hand's
    scores (:func:`_hand_scores`, all frames): a sample offered to both hands gets both, each at
    half the weight; a sample of no hand is null."""
    m = hand_scores[0].shape[2] - 1
    slots = batch.slots[rows]
    frames, k = slots.shape
    both = found.both[rows][np.arange(frames)[:, None], np.maximum(slots, 0)] & (slots >= 0)
    weight = np.where(both, np.log(0.5), 0.0).astype(np.float32)
    joint = np.full((frames, k, 2 * m + 1), _OTHER_HAND, dtype=np.float32)
    null = np.full((frames, k), -np.inf)
    for h, scores in enumerate(hand_scores):
        scores = scores[rows]
        seen = ~np.isnan(scores[..., m])
        joint[seen, h * m:(h + 1) * m] = scores[seen, :m] + weight[seen, None]
        null[seen] = np.logaddexp(null[seen], scores[seen, m] + weight[seen])
    joint[..., 2 * m] = np.where(np.isfinite(null), null, 0.0)
    return joint


def _offer_nulls(found: Hands, labeling: Labeling, take: Take, most: float = np.inf) -> tuple[int, np.ndarray]:
    """Offer to both hands the samples of null segments whose trajectory went to one hand but
    passes within :data:`.hands.HAND_RADIUS` of the other hand's centre; returns how many segments,
    and the frames they hold (to score again). Changes ``found.both`` in place, unless more than
    ``most`` segments would be offered (then nothing is offered and no frames are returned)."""
    from .hands import HAND_RADIUS

    per = labeling.per_sample()
    seg = labeling.segment_ids()
    null = (per == NULL) & (found.hand >= 0) & ~found.both
    f, p = np.nonzero(null)
    other = 1 - found.hand[f, p].astype(np.int64)
    centre = found.centre[f, other]
    near = np.linalg.norm(take.positions[f, p] - centre, axis=1) < HAND_RADIUS  # NaN centre: not near
    chosen = np.unique(seg[f[near], p[near]])
    if not len(chosen):
        return 0, np.zeros(0, dtype=np.int64)
    if len(chosen) > most:
        return int(len(chosen)), np.zeros(0, dtype=np.int64)
    offer = np.isin(seg, chosen) & null
    found.both |= offer
    return int(len(chosen)), np.flatnonzero(offer.any(axis=1))


def _handedness(take: Take, layout: Layout, labeling: Labeling, hands: int) -> np.ndarray:
    """int8 ``(F, hands)``: the handedness of each hand's labeled markers per frame
    (:func:`.hands.handedness`; 0 throughout for a layout of fewer than four markers)."""
    m = len(layout)
    per = labeling.per_sample()
    right = np.zeros((take.n_frames, hands), dtype=np.int8)
    if m < 4:
        return right
    for h in range(hands):
        observed = np.full((take.n_frames, m, 3), np.nan)
        f, p = np.nonzero((per >= h * m) & (per < (h + 1) * m))
        observed[f, per[f, p] - h * m] = take.positions[f, p]
        right[:, h] = handedness(observed, layout)
    return right


def _name_hands(take: Take, layout: Layout, labeling: Labeling, found: Hands, sides: Sequence[str] | None,
                naming: HandNaming | None, swaps: np.ndarray | None) -> Labeling:
    """Decide the sides of the hands, put the left hand's labels first and name them; facts in
    ``info["hands"]`` (with ``swaps``, the frames where the hands found traded places)."""
    from .hands import DEFAULT_NAMING, sided_layout_names

    m = len(layout)
    facts = {key: found.info[key] for key in ("present_share", "median_markers", "forced", "both_tracklets",
                                              "cuts", "warning") if key in found.info}
    facts["count"] = found.count
    if found.count == 1 and naming is None and sides is None:
        labeling.info["hands"] = facts
        return labeling
    right = _handedness(take, layout, labeling, found.count)
    evidence = [SideEvidence.of(r) for r in right.T]
    side_list, side_facts = decide_sides(evidence, None if sides is None else list(sides))
    if swaps is not None and swaps.any():
        facts["swaps"] = swap_ranges(swaps)
    facts.update(side_facts)
    facts["by_hand_order"] = list(side_list)
    if found.count == 2:
        naming = naming or HandNaming(DEFAULT_NAMING)
        order = _hand_order(side_list)
        if order != [0, 1]:
            hand, index = np.divmod(labeling.label.astype(np.int64), m)
            moved = np.where(labeling.label >= 0, np.array(order)[np.clip(hand, 0, 1)] * m + index, labeling.label)
            labeling.label = moved.astype(np.int16)
        side_list = ["left", "right"]
    facts["naming"] = naming.template if naming is not None else None
    labeling.names = sided_layout_names(layout, side_list, naming)
    facts["sides"] = side_list if found.count == 2 else facts["sides"]
    labeling.info["hands"] = facts
    return labeling


def label_take(take: Take, layout: Layout, method: str = "set", temporal: str = "vote",
               constraints: Sequence[Constraint] = (), model: str | None = None, fit: np.ndarray | None = None,
               start: np.ndarray | None = None, score: str = "likelihood", p: float = 2.0, q: float = -0.5,
               n_best: int = 5, split_swaps: bool = True, labeler: Labeler | None = None, calibrate: bool = True,
               validate: bool = False, hand: Calibration | None = None, splits: Sequence[tuple[int, int]] = (),
               null_prior: tuple[float, float] | None = None, switch_cost: tuple[float, float] | None = None,
               partner: tuple[float, float] | None = None, continuity: tuple[float, float] | None = None,
               progress: Callable[[str], None] | None = None,
               done: Callable[[float], None] | None = None, hands: str | int = "auto",
               sides: Sequence[str] | None = None, naming: HandNaming | str | None = None,
               keep_named: bool = True, props: bool = True, exclude: np.ndarray | None = None,
               hand_swaps: Sequence[Sequence[int]] | None = None, window: int | None = WINDOW_FRAMES,
               previous: Labeling | None = None, stride: int | None = None) -> Labeling:
    """Label every sample of ``take`` with ``layout``'s labels or null.

    Args:
        take: the raw take (metres).
        layout: the marker layout.
        method: per-frame labeler, one of ``METHODS`` (``set``, ``perm``, ``cnn``, ``gmm``, ``nearest``).
        temporal: one of :data:`TEMPORAL`.
        constraints: the user's locked decisions; honoured exactly.
        model: ONNX model for ``set`` / ``perm`` / ``cnn`` (default: the shipped one).
        fit: ``(F, M, 3)`` labeled positions of the subject (``gmm`` needs them).
        start: ``(M, 3)`` labeled first frame for ``nearest`` (default: ``set``'s labels of it).
        score: voting score, ``"likelihood"`` (ours) or ``"power"`` (Ghorbani's, with ``p``, ``q``).
        n_best: hypotheses per frame for ``viterbi``.
        split_swaps: split a tracklet where its evidence flips for good, and where two tracklets
            that pass close may have traded markers (:func:`.tracklets.find_crossings`); ``vote`` only.
        labeler: a ready labeler to use instead of building one from ``method`` (e.g. a ``gmm``
            fitted once for a performer and used for all their takes).
        calibrate: map raw segment confidences through the shipped calibration, where one exists.
        validate: IK validation (:mod:`.validate`, ``vote`` only): fit the hand to the labels, vote
            again with the fit's evidence, and downgrade segments the hand cannot explain.
        hand: the performer's calibration for ``validate`` (default: calibrated on this take).
        splits: ``(slot, frame)`` points where a reviewer cut a tracklet: decided in two parts.
        null_prior: ``(per segment, per sample)`` nats a label must beat null by in the ``vote``
            with the ``likelihood`` score (:func:`.temporal.voting.vote`); default: the one fitted
            for this method and layout, shipped beside the confidence calibration.
        switch_cost: ``(at a crossing, at any other cut)`` nats a trajectory pays to change label
            between pieces the vote cut it into (``vote`` with ``likelihood`` only); default: the
            one fitted for this method and layout, shipped beside the null prior.
        partner: ``(inside, outside)`` nats per sample for (against) a label whose rigid partner
            (a marker of the same bone) the first vote labeled at (not at) the pair's distance in
            that frame; the vote then runs again (:mod:`.temporal.partners`; ``vote`` with
            ``likelihood`` only). Default: the one fitted for this method and layout, shipped
            beside the null prior.
        continuity: ``(inside, outside)`` nats per sample near a trajectory's ends for (against) a
            label whose last sample before it (first after it), carried by its neighbours' motion,
            lands (does not land) on the trajectory's end (:mod:`.temporal.continuity`); read off
            the first vote with the partners' evidence. Default: the one fitted for this method
            and layout, shipped beside the null prior.
        progress: called with a short message at each stage.
        done: called with the share of the work done (0 to 1) as it goes: per batch of frames
            while an ONNX model scores them (most of the time of a long take), then per stage.
        hands: ``"auto"`` finds how many hands of ``layout`` the take holds (:func:`.hands.find_hands`);
            1 or 2 force it. Two hands are labeled jointly: ``2M`` labels, the left hand's first,
            named with ``naming``'s side tokens; no trajectory takes labels of both hands at once.
        sides: the side of each hand found, in the order of :func:`.hands.find_hands` (hands by the
            mean x of their centre); default: decided by the markers' handedness
            (:func:`.hands.side_evidence`, :func:`.hands.decide_sides`).
        naming: a :class:`.hands.HandNaming` (or its pattern) for the labels' names; two hands
            always get one (default ``L_``/``R_`` prefixes); one hand keeps plain names unless given.
        keep_named: points the file already names that are not ``layout``'s markers (a labeled
            body, a named prop) are kept out of the hands and stay null; False offers them too.
        props: look for rigid props among the trajectories (:mod:`.props`): a rigid group the
            labeler mostly left null, some of which took hand labels, is kept out and the take
            labeled again; ``info["props"]`` lists them.
        exclude: bool ``(F, P)``: samples kept out of the hands (null), e.g. a prop's.
        hand_swaps: frame ranges ``[start, stop)`` where the two hands found trade places (where
            they touch, the tracker of :func:`.hands.find_hands` can carry each hand's identity on
            with the other). None: found from a first labeling's handedness
            (:func:`.hands.identity_swaps`), and where there are any the take is labeled again
            with them; ``info["hands"]["swaps"]`` lists them. ``()``: none.
        window: a take of more frames is labeled in overlapping windows of this many
            (:mod:`.windows`: memory bounded by a window); None labels it whole. ``nearest``,
            which starts from the take's first frame, labels it whole.
        previous: an earlier labeling of this take (a reviewer's re-solve): only the frames around
            the corrections changed since (its ``info["locks"]`` and ``info["splits"]``) are
            labeled again and ``previous`` is kept elsewhere (:func:`.windows.relabel_around`);
            the take is labeled whole where that cannot be done.
        stride: with ``temporal="vote"``, the labeler scores every ``stride``-th frame of each
            trajectory and the samples between take their neighbours' scores
            (:mod:`.temporal.stride`; 1 scores every frame); default: a frame every 1/30 s
            (:func:`.temporal.stride.stride_for` the take's rate) with ``set``, every frame with
            the published methods.

    Returns:
        the :class:`Labeling`; ``info`` holds the settings and the time of each stage, and
        ``info["hands"]`` the hands found (count, sides with their evidence).
    """
    args = dict(locals())  # to label again without the props found, or in windows
    constraints = args["constraints"] = list(constraints)
    # The corrections the labeling honours, as given (a re-solve labels again what changed since).
    locks = [[int(c.slot), int(c.start), int(c.stop), int(c.label)] for c in constraints]
    cut_at = [[int(slot), int(frame)] for slot, frame in splits]

    def recorded(labeling: Labeling) -> Labeling:
        labeling.info["locks"], labeling.info["splits"] = locks, cut_at
        return labeling

    if method not in METHODS:
        raise ValueError(f"unknown labeling method {method!r}; choose one of {', '.join(METHODS)}")
    if temporal not in TEMPORAL:
        raise ValueError(f"unknown temporal mode {temporal!r}; choose one of {', '.join(TEMPORAL)}")
    valid = take.valid
    if take.n_frames == 0 or take.n_points == 0 or not valid.any():
        raise MocapInputError(take.source, "the take has no marker samples to label")
    constraints = list(constraints)
    for c in constraints:
        if not (0 <= c.slot < take.n_points and 0 <= c.start < c.stop <= take.n_frames):
            raise ValueError(f"constraint {c} lies outside the take ({take.n_frames} frames, {take.n_points} slots)")
    if validate and temporal != "vote":
        raise ValueError("validate needs temporal='vote'")
    args["previous"] = None  # what follows labels the take (or its parts) whole
    if previous is not None and exclude is None and not validate and method not in ("nearest", "gmm"):
        # The stretch takes its count of hands and their sides from ``previous``.
        options = {key: value for key, value in args.items()
                   if key not in ("take", "layout", "previous", "window", "hands", "sides")}
        local = relabel_around(label_take, take, layout, previous, **options)
        if local is not None:
            return recorded(local)
    if window is not None and take.n_frames > window and method != "nearest":
        options = {key: value for key, value in args.items() if key not in ("take", "layout", "window", "previous")}
        return recorded(label_in_windows(label_take, take, layout, window, **options))
    say = progress or (lambda _msg: None)
    share = done or (lambda _share: None)
    # Shares of the work at each stage's start: scoring is most of a take's time with the ONNX
    # models (0.3 s of 0.45 s for the 1,200-frame demo take); validation costs a hand calibration.
    scored, decided = (0.5, 0.7) if validate else (0.7, 1.0)
    times: dict[str, float] = {}
    t0 = time.perf_counter()

    naming = HandNaming(naming) if isinstance(naming, str) else naming
    ignore = other_named_points(take, layout, naming) if keep_named else None
    if exclude is not None:
        ignore = exclude | (False if ignore is None else ignore[None, :])
    say("finding hands")
    swaps = None if hand_swaps is None else swap_frames(hand_swaps, take.n_frames)
    found = _hands(take, layout, hands, ignore, swaps)
    times["hands"] = time.perf_counter() - t0
    if found.count == 2 and method not in JOINT_METHODS:
        raise ValueError(f"two hands are labeled with {', '.join(JOINT_METHODS)}, not {method!r} "
                         f"(or force one hand: hands=1)")
    if found.count == 2 and validate:
        raise ValueError("IK validation works on one hand; the take holds two (force one hand: hands=1)")
    hand_labels = _HandLabels(layout, found.count)
    check_constraints(constraints, len(hand_labels))
    if found.count == 2 and constraints and sides is None:
        # Corrections name final labels (left hand first): the sides must be known before the vote.
        first = label_take(take, layout, method, temporal, model=model, hands=2, keep_named=keep_named,
                           naming=naming, hand_swaps=hand_swaps).info["hands"]
        sides = first["by_hand_order"]
        if swaps is None:
            swaps = swap_frames(first.get("swaps", []), take.n_frames)
            found = _hands(take, layout, hands, ignore, swaps)
    order = _hand_order(sides) if found.count == 2 and sides is not None else None
    if order is not None:
        constraints = [replace(c, label=hand_labels.to_internal(c.label, order)) for c in constraints]
    t = time.perf_counter()
    say("packing frames")
    if ignore is not None and ignore.any():
        take_in = replace_valid(take, valid & ~(ignore if ignore.ndim == 2 else ignore[None, :]))
    else:
        take_in = take
    batch = _pack(take_in, _cap(layout) * found.count)
    points, mask, slots = batch.points, batch.mask, batch.slots
    tracklets = find_tracklets(take)
    cuts: dict[int, list[int]] = {}
    for c in constraints:
        cuts.setdefault(c.slot, []).extend([c.start, c.stop])
    for slot, frame in list(splits) + found.cuts:
        cuts.setdefault(int(slot), []).append(int(frame))
    segments = split_segments(Segments(tracklets.slot.astype(np.int64), tracklets.start, tracklets.stop), cuts)
    if temporal != "vote":
        stride = 1  # the other modes decide frame by frame
    elif stride is None:
        # Ours; the published labelers score every frame, as their papers do.
        stride = stride_for(take.rate) if method == "set" else 1
    times["pack"] = time.perf_counter() - t

    say(f"scoring {take.n_frames} frames with {method}")
    t = time.perf_counter()
    share(0.02)
    if found.count == 2:
        labeler = labeler or make_labeler(method, layout, model)
        every = np.arange(take.n_frames)
        scored_members = [found.members(h) for h in range(2)]
        near = _hands_near(found)
        hand_scores = [_all_hand_scores(take_in, layout, scored_members[h], batch, labeler, segments, stride, near)
                       for h in range(2)]
        joint = scores = _joint_scores(hand_scores, found, batch, every)
    else:
        labeler = labeler or _labeler(method, layout, model, fit, start, take, batch)
        hooked = done is not None and hasattr(labeler, "on_batch")
        if hooked:  # ONNX labelers report each batch of frames
            labeler.on_batch = lambda part: share(0.02 + (scored - 0.02) * part)
        try:
            scores = strided_scores(labeler.scores, batch, segments, stride)
        finally:
            if hooked:
                labeler.on_batch = None
    share(scored)
    scores = _apply_constraints(scores, slots, mask, constraints)
    times["scores"] = time.perf_counter() - t
    crossings = _crossings(take) if split_swaps and temporal == "vote" else {}

    locked_at = np.full(valid.shape, EMPTY, dtype=np.int16)  # the locked label of each sample
    for c in constraints:
        locked_at[c.start:c.stop, c.slot] = np.where(valid[c.start:c.stop, c.slot], c.label, EMPTY)
    info = {"method": method, "temporal": temporal, "layout": layout.name, "frames": take.n_frames,
            "slots": take.n_points, "constraints": len(constraints), "stride": stride}

    if null_prior is None:
        null_prior = load_null_prior(method, temporal, layout.name) if score == "likelihood" else (0.0, 0.0)
    info["null_prior"] = [float(v) for v in null_prior]
    if switch_cost is None:
        switch_cost = load_switch_cost(method, temporal, layout.name) if score == "likelihood" else (0.0, 0.0)
    info["switch_cost"] = [float(v) for v in switch_cost]
    if partner is None:
        partner = load_partner(method, temporal, layout.name) if score == "likelihood" else (0.0, 0.0)
    info["partner"] = [float(v) for v in partner]
    if continuity is None:
        continuity = load_continuity(method, temporal, layout.name) if score == "likelihood" else (0.0, 0.0)
    info["continuity"] = [float(v) for v in continuity]

    f_idx, k_idx = np.nonzero(mask)

    def offered_to() -> np.ndarray | None:
        """bool ``(n, hands)``: the hands each scored sample is offered to (None: one hand)."""
        if found.count == 1:
            return None
        return np.stack([found.members(h)[f_idx, slots[f_idx, k_idx]] for h in range(2)], axis=1)

    member = offered_to()

    def decide(scores: np.ndarray, first: Labeling | None = None, samples: Samples | None = None,
               again: Callable[[Labeling], tuple[Samples, np.ndarray] | None] | None = None) -> Labeling:
        return _decide(scores, batch, take, hand_labels, method, temporal, segments, locked_at, info, score, p, q,
                       split_swaps, n_best, calibrate, null_prior, crossings, switch_cost, partner,
                       continuity, first, samples, member, again)

    def hands_again(looked_at: Labeling, early: bool = False) -> tuple[Samples, np.ndarray] | None:
        """A marker given to the wrong hand is one its labeler rejects: the trajectories
        ``looked_at`` left null near the other hand are offered to both hands and scored again.
        ``early``: ``looked_at`` is the first vote, and the evidence of partners and continuity is
        still to be read off it; where more than :data:`LOOK_EARLY_SHARE` of its segments would
        be offered (hands that touch), nothing is done: the look waits for the whole labeling."""
        nonlocal hand_scores, joint, scores, member, samples
        most = LOOK_EARLY_SHARE * len(looked_at) if early else np.inf
        offered, rows = _offer_nulls(found, looked_at, take_in, most)
        if offered > most:
            return None
        info["hands_offered_again"] = offered
        if not offered:
            return None
        say("temporal step: both hands again")
        t = time.perf_counter()
        # A hand whose points did not change keeps its scores (those of a long take are not kept
        # between calls: passed on here).
        hand_scores = [_all_hand_scores(take_in, layout, found.members(h), batch, labeler, segments, stride, near,
                                        [(scored_members[h], hand_scores[h])]) for h in range(2)]
        joint = joint.copy()
        joint[rows] = _joint_scores(hand_scores, found, batch, rows)
        member = offered_to()
        scores = _apply_constraints(joint, slots, mask, constraints)
        samples = score_samples(scores, batch, rows, samples)
        times["hands_again"] = time.perf_counter() - t
        return samples, member

    say(f"temporal step: {temporal}")
    t = time.perf_counter()
    samples = score_samples(scores, batch)
    early = (lambda first: hands_again(first, early=True)) if found.count == 2 and temporal == "vote" else None
    labeling = decide(scores, samples=samples, again=early)
    times["temporal"] = time.perf_counter() - t - times.get("hands_again", 0.0)

    def traded_places() -> np.ndarray | None:
        """Where the hands touched, the tracker may have carried each hand's identity on with the
        other: the labeled markers' handedness says where (bool ``(F,)``; None: nowhere)."""
        if found.count != 2 or swaps is not None:
            return None
        traded = identity_swaps(_handedness(take, layout, labeling, 2), found.centre)
        return traded if traded.any() else None

    traded = traded_places()  # before more work is spent on this labeling
    if found.count == 2 and traded is None and "hands_offered_again" not in info:
        # The hands' second look after the whole labeling (hands that touch, or no vote to look
        # again after), and the labeling again with its evidence.
        rescored = hands_again(labeling)
        if rescored is not None:
            labeling = decide(scores, first=labeling, samples=rescored[0])
            traded = traded_places()  # the hands' second look labels more of a hand that traded places
    if traded is not None:
        # The first labeling's arrays go before the take is labeled again (a long take's are gigabytes).
        del scores, joint, hand_scores, samples, labeling, batch, points, mask, slots, member, f_idx, k_idx
        say("labeling again: the hands traded places where they touched")
        again = label_take(**{**args, "hand_swaps": swap_ranges(traded), "labeler": labeler})
        again.info["seconds"]["total"] = round(time.perf_counter() - t0, 4)
        again.info["seconds"]["traded_places"] = round(sum(times.values()), 4)
        share(1.0)
        return recorded(again)
    share(decided)
    if validate:
        say("validating with the hand fit")
        t = time.perf_counter()
        from .validate import downgrade, fit_labeling, fit_scores, segment_residuals

        hand, hand_fit = fit_labeling(take, layout, labeling, hand)
        labeling = decide(scores + fit_scores(points, mask, hand_fit.markers, spread=hand_fit.overall_rms()))
        residuals = segment_residuals(take, labeling, hand_fit)
        info["validation"] = {"hand_length_mm": round(hand.length * 1000, 2), "side": hand.side,
                              "marker_rms_mm": round(hand_fit.overall_rms() * 1000, 3),
                              "downgraded_segments": downgrade(labeling, residuals)}
        times["validate"] = time.perf_counter() - t
    t = time.perf_counter()
    labeling = _name_hands(take, layout, labeling, found, sides, naming, swaps)
    times["sides"] = time.perf_counter() - t
    if found.count == 2 and str(hands) == "auto" and not constraints:
        # Two hands must explain the take better than one: a hand with more markers than the
        # layout (a han19 glove labeled with glove13) also splits into two groups of points.
        two = labeling.summary()["confident_share"]
        if two < DOUBTFUL_SHARE:
            say("checking against one hand")
            single = label_take(take, layout, method, temporal, model=model, score=score, p=p, q=q, n_best=n_best,
                                split_swaps=split_swaps, labeler=labeler, calibrate=calibrate, splits=splits,
                                null_prior=null_prior, switch_cost=switch_cost, partner=partner,
                                continuity=continuity, hands=1, naming=naming, keep_named=keep_named)
            one = single.summary()["confident_share"]
            if two < one + CLEARLY_BETTER / 3:
                single.info["hands"].update(two_hands_rejected={"two": round(two, 4), "one": round(one, 4)})
                single.info["seconds"]["total"] = round(time.perf_counter() - t0, 4)
                share(1.0)
                return recorded(single)
    if props and temporal == "vote":
        t = time.perf_counter()
        found_props = _props(take, tracklets, labeling, len(hand_labels))
        times["props"] = time.perf_counter() - t
        if found_props:
            say(f"labeling again without {len(found_props)} rigid prop(s)")
            again = label_take(**{**args, "props": False,
                                  "exclude": prop_mask(found_props, take.n_frames, take.n_points)
                                  | (False if exclude is None else exclude)})
            again.info["props"] = [p.as_dict() for p in found_props]
            again.info["seconds"]["total"] = round(time.perf_counter() - t0, 4)
            share(1.0)
            return recorded(again)
    share(1.0)
    times["total"] = time.perf_counter() - t0
    info["seconds"] = {key: round(v, 4) for key, v in times.items()}
    return recorded(labeling)


def _props(take: Take, tracklets, labeling: Labeling, n_labels: int) -> list[Prop]:
    """The rigid props of a labeled take (:func:`.props.find_props`), judged by the labels its
    trajectories mostly took."""
    per = labeling.per_sample()
    ids = tracklets.id_map(take.n_frames, take.n_points)
    f, p = np.nonzero(ids >= 0)
    votes = np.bincount(ids[f, p].astype(np.int64) * (n_labels + 1) + (per[f, p].astype(np.int64) + 1),
                        minlength=len(tracklets) * (n_labels + 1)).reshape(len(tracklets), n_labels + 1)
    positions = np.where(take.valid[..., None], take.positions, np.nan)
    groups = _remembered(_RIGID_GROUPS, _take_key(take), lambda: rigid_groups(positions, tracklets, take.rate))
    return find_props(positions, tracklets, take.rate, votes.argmax(axis=1) - 1, groups=groups)


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


def _decide(scores: np.ndarray, batch: FrameBatch, take: Take, labels: _HandLabels, method: str, temporal: str,
            segments: Segments, locked_at: np.ndarray, info: dict, score: str, p: float, q: float,
            split_swaps: bool, n_best: int, calibrate: bool, null_prior: tuple[float, float],
            crossings: dict[int, list[int]], switch_cost: tuple[float, float],
            partner: tuple[float, float] | None, continuity: tuple[float, float],
            first: Labeling | None = None, samples: Samples | None = None,
            member: np.ndarray | None = None,
            again: Callable[[Labeling], tuple[Samples, np.ndarray] | None] | None = None) -> Labeling:
    """Per-frame scores ``(F, K, M + 1)`` to a Labeling with calibrated confidences. With ``first``
    (an earlier labeling of the take), the evidence of rigid partners and continuity is read off it
    and one vote is held, instead of a first vote to read it off. ``samples``: the scores as
    :func:`score_samples` gives them, where the caller has them already. ``member``: bool
    ``(n, hands)``, the hands each sample is offered to (two hands; None: one). ``again``: called
    with the first vote's labeling (no confidences); where it returns new ``(samples, member)``
    (the same samples, scored again), the last vote is held on those."""
    points, mask, slots = batch.points, batch.mask, batch.slots
    valid = take.valid
    layout, n_labels = labels.layout, len(labels)
    f_idx, k_idx = np.nonzero(mask)
    if samples is None:
        samples = score_samples(scores, batch)
    if temporal == "vote":
        def run_vote(scored: Samples) -> tuple[Segments, np.ndarray, np.ndarray, dict]:
            return vote(scored, segments, locked_at, score, p, q, split_swaps, null_prior=null_prior,
                        crossings=crossings, switch_cost=switch_cost)

        rigid = labels.rigid_pairs() if partner and any(partner) else None
        with_rigid, with_continuity = rigid is not None and len(rigid) > 0, any(continuity)
        if first is not None and (with_rigid or with_continuity):
            facts = {"time_limited": 0}
            ids = first.segment_ids()[samples.frame, samples.slot]
            per = np.where(ids >= 0, first.label[np.maximum(ids, 0)], NULL).astype(np.int64)
            held = np.where(ids >= 0, first.length[np.maximum(ids, 0)], 0)
        else:
            decided, label, seg, facts = run_vote(samples)
            per = np.where(seg >= 0, label[np.maximum(seg, 0)], NULL)
        rescored = None
        if again is not None and first is None:
            rescored = again(Labeling(names=labels.names, n_frames=take.n_frames, n_points=take.n_points,
                                      slot=decided.slot, start=decided.start, stop=decided.stop,
                                      label=label.astype(np.int16), confidence=np.zeros(len(decided), np.float32),
                                      locked=np.zeros(len(decided), dtype=bool), info={}))
            if rescored is not None:
                samples, member = rescored
        if with_rigid or with_continuity or rescored is not None:
            # Vote again with the evidence of rigid partners and of continuity, read off the first
            # vote's labels.
            extra = np.zeros_like(samples.logp)
            at = points[f_idx, k_idx].astype(np.float64)
            # Each hand's evidence for the samples offered to it (the others score its labels at the
            # floor, far below anything the evidence adds).
            m = labels.m
            rows = [None] if member is None else [np.flatnonzero(member[:, h]) for h in range(labels.hands)]
            if with_rigid:
                rigid = take_distances(rigid, at, samples.frame, per, n_labels)
                for h, sel in enumerate(rows):  # one entry per hand
                    extra += partner_logp(at, samples.frame, per, n_labels, labels.hand_pairs(rigid, h), *partner,
                                          rows=sel)
            if with_continuity:
                held_for = held if first is not None else \
                    np.where(seg >= 0, (decided.stop - decided.start)[np.maximum(seg, 0)], 0)
                # Per hand: a marker's neighbours, whose motion carries it across a gap, are its own hand's.
                for h in range(labels.hands):
                    own = np.where((per >= h * m) & (per < (h + 1) * m), per - h * m, NULL)
                    extra[:, h * m:(h + 1) * m] += continuity_logp(at, samples.frame, samples.slot, own, held_for,
                                                                   segments, m, take.rate, *continuity,
                                                                   rows=rows[h])[:, :m]
            if extra.any() or first is not None or rescored is not None:
                stopped = facts["time_limited"]
                # Summed in float64 at once: the vote sums in float64 (one copy fewer of a large array).
                total = np.add(samples.logp, extra, dtype=np.float64)
                decided, label, seg, facts = run_vote(replace(samples, logp=total))
                facts["time_limited"] += stopped
        info.update(facts)
        first_locked = locked_at[decided.start, decided.slot]
        labeling = Labeling(names=labels.names, n_frames=take.n_frames, n_points=take.n_points,
                            slot=decided.slot, start=decided.start, stop=decided.stop,
                            label=label.astype(np.int16), confidence=np.zeros(len(decided), dtype=np.float32),
                            locked=first_locked != EMPTY, info=info)
    else:
        per = np.full(valid.shape, NULL, dtype=np.int16)
        if temporal == "viterbi":
            from .temporal.viterbi import viterbi_labels

            frame_labels = viterbi_labels(scores, mask, points, take.rate, n_best=n_best)
            per[f_idx, slots[f_idx, k_idx]] = frame_labels[f_idx, k_idx]
        else:
            per[samples.frame, samples.slot] = samples.label
        split = np.zeros(valid.shape, dtype=bool)
        split[segments.start, segments.slot] = True
        labeling = segments_from_runs(labels.names, per, valid, info, split=split)
        labeling.locked = locked_at[labeling.start, labeling.slot] != EMPTY
    labeling.evidence = segment_evidence(labeling, samples)
    labeling.confidence = labeling.evidence[:, 0].copy()  # the mean probability, until calibrated
    calibration = load_calibration(method, temporal, layout.name) if calibrate else None
    if calibration is not None:
        labeling.confidence = calibration(labeling.evidence, labeled=labeling.label >= 0)
    labeling.confidence[labeling.locked] = 1.0
    info["confidence"] = "calibrated" if calibration is not None else "raw (no calibration for this method)"
    if calibration is not None and calibration.never_sure:
        info["never_confident"] = True  # front ends say why every segment is uncertain
    return labeling


def time_limit_warning(labeling: Labeling) -> str | None:
    """A one-line warning when the vote's assignment was stopped by its time limit, else None."""
    from .temporal.voting import MILP_SECONDS

    stopped = labeling.info.get("time_limited", 0)
    if not stopped:
        return None
    return (f"the vote's exclusive assignment stopped at its {MILP_SECONDS:g} s limit {stopped} time(s): the "
            f"labels are the best found by then (takes of hands need far less; is this a hand?)")


#: Below this share of confident labeled samples, the other layouts are tried. Wrong layouts give
#: 0-12 % on our takes, but short right ones can too (8 of the 316 han2018 raw takes, 20-49 %),
#: so a low share alone says nothing: another layout must do clearly better.
DOUBTFUL_SHARE = 0.5
#: How much more of the samples another layout must label confidently to be suggested.
CLEARLY_BETTER = 0.3
#: Frames of the take the other layouts are tried on (about half a second each).
CHECK_FRAMES = 2000


@dataclass(frozen=True)
class LayoutDoubt:
    """Another layout fits the take clearly better: ``better`` labels ``better_share`` of its labeled
    samples confidently where ``layout`` labels ``share``. ``str()`` is the one-line warning."""

    layout: str
    share: float
    better: str
    better_share: float

    def __str__(self) -> str:
        return (f"only {100 * self.share:.1f} % of labeled samples are confident with layout {self.layout!r}, "
                f"and {100 * self.better_share:.1f} % with {self.better!r}: is this a {self.better} take?")


def layout_doubt(take: Take, layout: Layout, labeling: Labeling, confident: float = 0.95) -> LayoutDoubt | None:
    """A :class:`LayoutDoubt` when another built-in layout fits ``take`` clearly better, else None.

    Nothing is tried while at least :data:`DOUBTFUL_SHARE` of the labeled samples are confident.
    Below it, every built-in layout with a shipped ``set`` model labels the take's first
    :data:`CHECK_FRAMES` frames; one whose confident share is at least :data:`DOUBTFUL_SHARE` and
    :data:`CLEARLY_BETTER` above ``layout``'s (on the same frames) is named.
    """
    share = labeling.summary(confident)["confident_share"]
    if share >= DOUBTFUL_SHARE:
        return None
    from .labelers.onnx_labeler import shipped_model
    from .layout import builtin_layouts, load_layout

    excerpt = replace(take, positions=take.positions[:CHECK_FRAMES],
                      residuals=None if take.residuals is None else take.residuals[:CHECK_FRAMES], filled=None)
    shares = {}
    for name in builtin_layouts():
        if name != layout.name and os.path.isfile(shipped_model("set", name)):
            try:
                shares[name] = label_take(excerpt, load_layout(name)).summary(confident)["confident_share"]
            except MocapInputError:  # e.g. no samples in the excerpt
                continue
    best = max(shares, key=shares.get, default=None)
    if best is None or shares[best] < DOUBTFUL_SHARE:
        return None
    labeled = labeling.per_sample()[:CHECK_FRAMES] >= 0
    own = (labeled & (labeling.per_sample_confidence()[:CHECK_FRAMES] >= confident)).sum() / max(labeled.sum(), 1)
    if shares[best] - own < CLEARLY_BETTER:
        return None
    return LayoutDoubt(layout.name, float(share), best, float(shares[best]))


#: A hand is "found" when at least this share of frames has at least half the layout labeled, all
#: within HAND_REACH (metres) of their median: a hand is about 0.2 m long, a body capture labeled
#: as a hand spreads its "labels" over half a metre or more.
HAND_FRAMES, HAND_REACH = 0.3, 0.25
#: A labeled marker counts towards "a hand is here" only if its segment's mean per-frame
#: probability (its calibrated confidence for :data:`LOW_PROBABILITY` methods) is at least this: a
#: full-body capture labeled with a hand layout gets labels, but ones its labeler does not believe
#: (``set``: median 0.26 on ezc3d's Vicon.c3d; 0.98 and up on hands).
BELIEVED = 0.5
#: Methods whose per-frame probabilities are low even where they are right (median 0.25 for
#: ``perm`` and 0.39 for ``cnn`` on the demo take, which they label 92 % right): their segments are
#: believed by calibrated confidence, which there reaches 0.5 in every frame. Not for ``set``: a
#: han19 take labeled with glove13 has calibrated confidences of 0.5 on labels that are wrong.
LOW_PROBABILITY = ("perm", "cnn")


@dataclass(frozen=True)
class HandCheck:
    """Whether a labeled take holds a hand: ``share`` of its frames look like one (see
    :data:`HAND_FRAMES`); ``better`` names a layout that fits clearly better, if one does.
    ``str()`` of a failed check is the one-line reason, for errors in the CLI, batch and Blender."""

    share: float
    layout: str
    better: str | None = None

    @property
    def found(self) -> bool:
        return self.share >= HAND_FRAMES

    def __str__(self) -> str:
        return self.describe()

    def describe(self, use: str = "--layout {}") -> str:
        """The one line; ``use`` says how to pick the better layout where one fits (the command
        line's flag by default; Blender names its panel field)."""
        if self.found:
            return f"a hand in {100 * self.share:.0f} % of frames"
        hint = (f"'{self.better}' fits better: use {use.format(self.better)}" if self.better else
                f"is this a {self.layout} take?")
        return (f"no hand found: only {100 * self.share:.0f} % of frames have half of the {self.layout} markers "
                f"labeled with some confidence within {HAND_REACH:g} m of each other ({hint})")


def _believed(labeling: Labeling, m: int) -> np.ndarray:
    """bool ``(F, M)``: where each label sits on a segment whose mean probability (calibrated
    confidence for :data:`LOW_PROBABILITY` methods) reaches :data:`BELIEVED`."""
    seg = labeling.segment_ids()  # (F, P)
    frame, slot = np.nonzero(seg >= 0)
    s = seg[frame, slot]
    low = labeling.info.get("method") in LOW_PROBABILITY
    belief = labeling.confidence if low else labeling.evidence[:, 0]
    keep = (labeling.label[s] >= 0) & (belief[s] >= BELIEVED)
    out = np.zeros((labeling.n_frames, m), dtype=bool)
    out[frame[keep], labeling.label[s[keep]]] = True
    return out


def hand_share(markers: np.ndarray, believed: np.ndarray | None = None) -> float:
    """Share of frames whose labeled markers ``(F, M, 3)`` (metres, NaN = not labeled) look like one
    hand: at least half of the M labeled, all within :data:`HAND_REACH` of their median.
    ``believed`` ``(F, M)`` bool keeps only those markers (see :data:`BELIEVED`)."""
    import warnings

    if believed is not None:
        markers = np.where(believed[..., None], markers, np.nan)
    if not len(markers):
        return 0.0
    count = np.isfinite(markers[..., 0]).sum(axis=1)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # frames with no labeled marker
        centre = np.nanmedian(markers, axis=1, keepdims=True)
        reach = np.nanmax(np.linalg.norm(markers - centre, axis=2), axis=1)
    return float(((count >= markers.shape[1] / 2) & (reach <= HAND_REACH)).mean())


def check_hand(take: Take, layout: Layout, labeling: Labeling, doubt: LayoutDoubt | None = None,
               labeled: Take | None = None) -> HandCheck:
    """The no-hand rule the CLI, batch and Blender share: a labeling of ``take`` in which under
    :data:`HAND_FRAMES` of the frames hold half of ``layout``'s markers, believed and within
    :data:`HAND_REACH` of each other, found no hand (a body capture, a prop, the wrong layout),
    however many labels it gave. ``doubt`` (from :func:`layout_doubt`) names the better layout;
    ``labeled``, ``labeled_take(take, labeling)`` where the caller has it already."""
    from .labeling import labeled_take

    m = len(layout)
    markers = (labeled if labeled is not None else labeled_take(take, labeling)).positions[:, :m]
    return HandCheck(hand_share(markers, _believed(labeling, m)), layout.name, doubt.better if doubt else None)


def hand_checks(take: Take, layout: Layout, labeling: Labeling,
                doubt: LayoutDoubt | None = None) -> list[tuple[str, HandCheck]]:
    """:func:`check_hand` per hand: ``[("", check)]`` for one hand, ``[("left", ...), ("right", ...)]``
    for a two-hand labeling (each hand's labels on their own)."""
    hands = labeling.info.get("hands", {})
    if hands.get("count", 1) < 2:
        return [("", check_hand(take, layout, labeling, doubt))]
    m = len(layout)
    return [(side, check_hand(take, layout, labeling.label_range(h * m, (h + 1) * m), doubt))
            for h, side in enumerate(hands["sides"])]


@dataclass
class HandSolve:
    """A hand solved over a labeled take.

    Attributes:
        calibration: the performer's hand and markers it was solved with.
        fit: poses ``(F, 26)``, fitted markers and residuals per frame.
        layout: the marker layout.
        rate: frames per second; first_frame: the take's first frame number.
        seconds: wall time of each stage.
        hand_solver: the solver the fit came from; None: the calibration's (:meth:`solver`).
    """

    calibration: Calibration | None
    fit: Fit
    layout: Layout
    rate: float
    first_frame: int
    seconds: dict
    hand_solver: HandSolver | None = None

    def solver(self) -> HandSolver:
        """The calibrated hand and its markers, as solved."""
        if self.hand_solver is None:
            self.hand_solver = self.calibration.solver(self.layout)
        return self.hand_solver

    def report(self) -> dict:
        """Per-frame and overall marker RMS in millimetres, per-marker RMS, calibration, timings."""
        fit = self.fit
        rms = fit.rms * 1000
        gate = np.isfinite(rms) & (rms > GATE * 1000)
        with np.errstate(invalid="ignore"):
            per_marker = np.sqrt(np.nanmean(np.where(fit.solved[:, None], fit.residuals, np.nan) ** 2, axis=0)) * 1000
        return {
            "layout": self.layout.name,
            "frames": len(rms),
            "solved_frames": int(fit.solved.sum()),
            "marker_rms_mm": round(fit.overall_rms() * 1000, 4),
            "frames_over_gate": int(gate.sum()),
            "gate_mm": GATE * 1000,
            "per_marker_rms_mm": {n: (round(float(v), 4) if np.isfinite(v) else None)
                                  for n, v in zip(self.layout.names, per_marker)},
            "per_frame_rms_mm": [round(float(v), 3) if np.isfinite(v) else None for v in rms],
            "calibration": self.calibration.to_dict(),
            "seconds": self.seconds,
        }


#: The share of a solve's time its calibration takes (measured on the demo and glove takes: 75-80 %).
CALIBRATE_SHARE = 0.75


def solve_take(take: Take, layout: Layout, calibration: Calibration | None = None,
               calibrate_seconds: float | None = None, reference: Sequence[int] | None = None,
               contacts: Sequence[tuple[int, str]] = (), side: str | None = None,
               smooth_hz: float = 10.0, progress: Callable[[str, float], None] | None = None) -> HandSolve:
    """Fit the hand to a labeled take: calibrate (unless given a calibration), then solve every frame.

    Args:
        take: a labeled take whose point names include every marker of ``layout``.
        layout: the marker layout.
        calibration: a performer's calibration to reuse; None calibrates on this take.
        calibrate_seconds: calibrate on the take's first seconds only (default: all of it).
        reference: frames (0-based) in which the hand is flat (see :func:`calibrate`).
        contacts: pinch frames ``(frame, finger)`` for the calibration (see :func:`calibrate`).
        side: ``left``/``right``; detected from the markers when None.
        smooth_hz: low-pass cut-off for the pose track (0: none).
        progress: called with a stage message and the share of the work done (0-1) as the solve
            goes (a calibration is about three quarters of it: 20 s of 25 s on the 1,200-frame
            demo take); it may raise to stop the solve (a cancelled :class:`~.jobs.Job` does).
    """
    say = progress or (lambda _msg, _share: None)
    observed = layout_markers(take, layout)
    if not (np.isfinite(observed).all(axis=-1).sum(axis=1) >= MIN_MARKERS).any():
        raise MocapInputError(take.source, f"no frame shows {MIN_MARKERS} or more of the layout's markers")
    seconds = {}
    start = time.perf_counter()
    if calibration is None:
        say("calibrating the hand", 0.0)
        stop = len(observed) if calibrate_seconds is None else max(1, int(round(calibrate_seconds * take.rate)))
        bad = [f for f, _ in contacts if not 0 <= f < stop]
        if bad:
            raise MocapInputError(take.source, f"pinch frames {bad[:5]} lie outside the calibration frames "
                                               f"0-{stop - 1}")
        calibration = calibrate(observed[:stop], layout, side=side, contacts=contacts,
                                reference=None if reference is None else np.asarray(reference),
                                progress=lambda done: say(f"calibrating the hand ({100 * done:.0f} %)",
                                                          CALIBRATE_SHARE * done))
    else:
        calibration.check(layout, "calibration")
        if side is not None and side != calibration.side:
            raise MocapInputError("calibration", f"is for a {calibration.side} hand, not a {side} one")
    seconds["calibrate"] = round(time.perf_counter() - start, 4)
    start = time.perf_counter()
    share0 = CALIBRATE_SHARE if seconds["calibrate"] > 0.05 else 0.0  # where the frames' share starts
    say("solving frames", share0)
    solver = calibration.solver(layout)
    fit = solver.solve(
        observed, rate=take.rate, smooth_hz=smooth_hz,
        progress=lambda done: say(f"solving frames ({100 * done:.0f} %)", share0 + (1 - share0) * done))
    seconds["solve"] = round(time.perf_counter() - start, 4)
    return HandSolve(calibration, fit, layout, float(take.rate), int(take.first_frame), seconds, solver)


def solve_hands(take: Take, layout: Layout, naming: HandNaming | None = None,
                calibrations: dict[str, Calibration] | None = None, **options) -> list[tuple[str, HandSolve]]:
    """Solve every hand of a labeled take: ``[(side, HandSolve)]``, side ``""`` for a take labeled
    with plain names (one hand), else ``"left"`` / ``"right"`` read off the names
    (:func:`.hands.split_hands`); each hand calibrated on its own (size, side, marker offsets)
    unless ``calibrations[side]`` is given. ``options`` go to :func:`solve_take`."""
    from .hands import split_hands

    out = []
    for side, one in split_hands(take, layout, naming):
        given = (calibrations or {}).get(side)
        kwargs = dict(options)
        if side and kwargs.get("side") is None:
            kwargs["side"] = side
        try:
            out.append((side, solve_take(one, layout, calibration=given, **kwargs)))
        except MocapInputError as exc:
            raise MocapInputError(take.source, f"{side} hand: {exc.problem}" if side else exc.problem) from exc
    return out
