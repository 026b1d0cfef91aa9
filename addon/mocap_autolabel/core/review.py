"""Review of a Labeling: confidence classes, and the user's corrections as constraints.

Every correction a reviewer makes is a :class:`~.labeling.Constraint` (or a split point) on
the take, never an edit of the result: re-solving with all of them reproduces each one exactly
and lets its consequences propagate (a label taken here is no longer available elsewhere).
Blender-free: the operators (``operators/corrections.py``, ``navigation.py``, ``label.py``) only call these.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .labeling import EMPTY, NULL, Constraint, Labeling, segments_from_runs

#: Confidence classes, in the order of :data:`KEY_TYPES`.
CONFIDENT, UNCERTAIN, VERY_UNCERTAIN, LOCKED = 0, 1, 2, 3
CLASS_NAMES = ("confident", "uncertain", "very uncertain", "locked")
#: Blender keyframe type of each class: plain keys where nothing is needed, colours where review is.
KEY_TYPES = ("KEYFRAME", "BREAKDOWN", "EXTREME", "JITTER")
#: Confidence at or above which a segment needs no look (the calibrated "sure" promise), and
#: below which it is very uncertain.
SURE, DOUBTFUL = 0.95, 0.5


def segment_classes(labeling: Labeling, sure: float = SURE, doubtful: float = DOUBTFUL) -> np.ndarray:
    """int8 ``(segments,)``: the confidence class of every segment."""
    out = np.where(labeling.confidence >= sure, CONFIDENT,
                   np.where(labeling.confidence >= doubtful, UNCERTAIN, VERY_UNCERTAIN)).astype(np.int8)
    out[labeling.locked] = LOCKED
    return out


def marker_classes(labeling: Labeling, sure: float = SURE) -> np.ndarray:
    """int8 ``(frames, M)``: the class of each layout marker's sample per frame, -1 where it is missing
    (confident at ``sure``: the reviewer's threshold, so the key colours follow it)."""
    seg = labeling.segment_ids()
    per = labeling.per_sample()
    classes = segment_classes(labeling, sure)
    out = np.full((labeling.n_frames, len(labeling.names)), -1, dtype=np.int8)
    f, s = np.nonzero(per >= 0)
    out[f, per[f, s]] = classes[seg[f, s]]
    return out


def null_classes(labeling: Labeling, sure: float = SURE) -> np.ndarray:
    """int8 ``(frames, points)``: the class of each unassigned (null) sample's segment, -1 elsewhere.

    An unlabeled piece that the review queue leaves out by default (a short ghost that continues no
    doubtful label and lies far from every missing marker: :func:`review_queue`) is confident: the ghosts
    the vote is sure about are not shown as uncertain."""
    classes = segment_classes(labeling, sure)
    queued = np.zeros(len(labeling), dtype=bool)
    queued[review_queue(labeling, sure)] = True
    classes[(labeling.label < 0) & ~queued & (classes != LOCKED)] = CONFIDENT
    out = labeling._paint(classes, -1, np.int8)
    out[labeling.per_sample() != NULL] = -1
    return out


def uncertain_segments(labeling: Labeling, sure: float = SURE) -> np.ndarray:
    """Indices of every unlocked segment below ``sure``, worst first (then by start frame).

    Unlabeled segments count too: an uncertain one may be a marker the labeler missed, and the
    command line and batch count them (:meth:`Labeling.uncertain`, one rule everywhere). What a
    reviewer is shown, and in which order, is :func:`review_queue`: a subset of these.
    """
    return labeling.uncertain(sure)


#: Unlabeled pieces shorter than this (frames) stay out of the review queue by default, unless they
#: continue a labeled segment in doubt, lie close to a marker the labeling lacks (:data:`QUEUE_NEAR_MM`)
#: or are more likely a marker than not. On the temporal benchmark's 316 raw han2018 takes most of the
#: uncertain unlabeled pieces were shorter, and the few of those that were a marker's samples are caught by
#: the continuation rule or the distance to a missing marker. ``benchmarks/review.py`` measures the queue.
QUEUE_MIN_FRAMES = 10
#: A short unlabeled piece is queued when one of its samples lies this close (mm) to where a marker that no
#: trajectory carries in that frame should be (:func:`missing_marker_distance`): a marker seen for a few
#: frames in the middle of its gap, which the vote left unlabeled. Where a hidden marker should be is only
#: known to a centimetre or two, and flicker ghosts near the hand sometimes fall there too: on the
#: benchmark's takes 25 mm catches most such markers while the short pieces it adds stay under a tenth of
#: the queue (``benchmarks/review.py``).
QUEUE_NEAR_MM = 25
#: A thumb marker's spot is known this much (mm) less well: the thumb moves against the fingers
#: whose motion carries a hidden marker's last position forward. On the temporal benchmark's raw
#: han2018 takes the thumb markers seen again in their gaps lay a median 28 mm from where they should
#: be (9 pieces), the other markers 18 mm (4 pieces); at 25 mm two of the thumb's were left out of
#: the queue, at 36 mm none (``benchmarks/review.py``).
THUMB_SLACK_MM = 11
#: How far in time (seconds) a missing marker is followed from where it was last or is next seen.
NEAR_WINDOW_S = 1.0
#: Chunk of (frame, marker) predictions computed at once (bounds the memory of a long take).
_CHUNK = 8192


def _carried(at: np.ndarray, present: np.ndarray, hand: np.ndarray, frame: np.ndarray, seen: np.ndarray,
             label: np.ndarray) -> np.ndarray:
    """float ``(E, 3)``: where each ``label`` seen at frame ``seen`` is at ``frame``: its position there moved
    as the other markers of its hand seen in both frames moved, the nearest to it weighing most
    (inverse square of their distance plus 1 cm); unmoved where none is seen in both."""
    rows = np.arange(len(label))
    xs, xf = at[seen], at[frame]  # (E, L, 3)
    both = present[frame] & present[seen] & (hand[None, :] == hand[label][:, None])
    both[rows, label] = False
    own = xs[rows, label]
    apart = np.linalg.norm(np.where(both[..., None], xs - own[:, None], 0.0), axis=2)
    weight = np.where(both, 1.0 / (apart + 0.01) ** 2, 0.0)
    moved = (weight[..., None] * np.where(both[..., None], xf - xs, 0.0)).sum(axis=1)
    total = weight.sum(axis=1)
    return own + moved / np.where(total > 0, total, 1.0)[:, None]


def missing_marker_distance(labeling: Labeling, positions: np.ndarray, hand_size: int, rate: float,
                            window_s: float = NEAR_WINDOW_S, slack_mm: np.ndarray | None = None) -> np.ndarray:
    """int32 ``(S,)``: for each unlabeled segment, the distance (mm, rounded) from its nearest sample to where
    a marker should be that no trajectory carries in that sample's frame, less that marker's ``slack_mm``
    (never below 0); -1 for labeled segments and where no marker is missing that was seen within
    ``window_s`` of that frame (:attr:`.labeling.Labeling.missing_mm`).

    Where the missing marker should be: its last position before the frame and its next one after (those
    within ``window_s``), each moved as its own hand's markers seen in both frames moved (:func:`_carried`),
    blended by time. Labels ``h * hand_size`` to ``(h + 1) * hand_size - 1`` are hand ``h``'s.

    Args:
        positions: ``(F, P, 3)`` the take's samples (metres).
        slack_mm: ``(hand_size,)`` how much less well each marker of a hand is predicted (mm), a layout's
            from :func:`marker_slack`; None: none.
    """
    n, n_labels = len(labeling), len(labeling.names)
    out = np.full(n, -1, dtype=np.int32)
    per = labeling.per_sample()
    null_f, null_s = np.nonzero(per == NULL)
    if not len(null_f) or not n_labels:
        return out
    frames = labeling.n_frames
    f_lab, s_lab = np.nonzero(per >= 0)
    lab = per[f_lab, s_lab].astype(np.int64)
    present = np.zeros((frames, n_labels), dtype=bool)
    present[f_lab, lab] = True
    at = np.full((frames, n_labels, 3), np.nan)
    at[f_lab, lab] = positions[f_lab, s_lab]
    hand = np.arange(n_labels) // max(int(hand_size), 1)
    index = np.arange(frames)[:, None]
    last = np.maximum.accumulate(np.where(present, index, -1), axis=0)
    after = np.minimum.accumulate(np.where(present, index, frames)[::-1], axis=0)[::-1]
    window = max(1, int(round(window_s * rate)))
    # Every (frame with an unlabeled sample, marker missing there and seen within the window).
    fr = np.unique(null_f)
    before_ok = ~present[fr] & (last[fr] >= 0) & (fr[:, None] - last[fr] <= window)
    after_ok = ~present[fr] & (after[fr] < frames) & (after[fr] - fr[:, None] <= window)
    row, label = np.nonzero(before_ok | after_ok)
    if not len(row):
        return out
    frame = fr[row]
    a = np.where(before_ok[row, label], last[fr][row, label], after[fr][row, label])
    b = np.where(after_ok[row, label], after[fr][row, label], a)
    share = np.where(b > a, (frame - a) / np.maximum(b - a, 1), 0.0)[:, None]
    where = np.empty((len(frame), 3))
    for c in range(0, len(frame), _CHUNK):
        part = slice(c, c + _CHUNK)
        from_a = _carried(at, present, hand, frame[part], a[part], label[part])
        from_b = _carried(at, present, hand, frame[part], b[part], label[part])
        where[part] = from_a * (1.0 - share[part]) + from_b * share[part]
    # Each unlabeled sample against every prediction of its frame (null_f is sorted, as frame is).
    lo, hi = np.searchsorted(frame, null_f, side="left"), np.searchsorted(frame, null_f, side="right")
    count = hi - lo
    has = count > 0
    sample = np.repeat(np.flatnonzero(has), count[has])
    pred = np.repeat(lo[has], count[has]) + np.arange(int(count[has].sum())) - \
        np.repeat(np.cumsum(count[has]) - count[has], count[has])
    dist = np.linalg.norm(where[pred] - positions[null_f[sample], null_s[sample]].astype(np.float64), axis=1)
    if slack_mm is not None:
        slack = np.asarray(slack_mm, dtype=np.float64)[label % max(int(hand_size), 1)] * 1e-3
        dist = np.maximum(dist - slack[pred], 0.0)
    nearest = np.full(len(null_f), np.inf)
    np.minimum.at(nearest, sample, dist)
    seg = labeling.segment_ids()[null_f, null_s]
    best = np.full(n, np.inf)
    np.minimum.at(best, seg, nearest)
    known = np.isfinite(best)
    out[known] = np.minimum(np.rint(best[known] * 1000.0), np.iinfo(np.int32).max).astype(np.int32)
    return out


def marker_slack(layout) -> np.ndarray:
    """float ``(M,)`` mm: each marker's :data:`THUMB_SLACK_MM` if it sits on the thumb, else 0."""
    return np.array([THUMB_SLACK_MM if m.bone.startswith("thumb") else 0.0 for m in layout.markers])


def _touches(slot: np.ndarray, start: np.ndarray, stop: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """bool ``(S,)``: segments that end where a ``mask`` segment of the same slot starts, or start where
    one ends (the same trajectory, no frame between)."""
    if not mask.any():
        return np.zeros(len(slot), dtype=bool)
    span = int(stop.max()) + 1
    ends, begins = slot[mask] * span + stop[mask], slot[mask] * span + start[mask]
    return np.isin(slot * span + start, ends) | np.isin(slot * span + stop, begins)


def rank_segments(slot, start, stop, label, confidence, locked, sure: float = SURE, *, labeled_only: bool = False,
                  min_frames: int = QUEUE_MIN_FRAMES, missing_mm=None, near_mm: int = QUEUE_NEAR_MM) -> np.ndarray:
    """The review queue over plain per-segment arrays (see :func:`review_queue`): the indices of the
    segments to show, in the order to look at them. ``missing_mm``: each segment's distance to a missing
    marker (:attr:`.labeling.Labeling.missing_mm`), or None where not known."""
    slot, start, stop = (np.asarray(a, dtype=np.int64).reshape(-1) for a in (slot, start, stop))
    label = np.asarray(label, dtype=np.int64).reshape(-1)
    confidence = np.asarray(confidence, dtype=np.float64).reshape(-1)
    locked = np.asarray(locked, dtype=bool).reshape(-1)
    length = stop - start
    unsure = (confidence < sure) & ~locked & (length > 0)
    labeled = unsure & (label >= 0)
    shown = labeled.copy()
    ghost = unsure & (label < 0)
    cut = ghost & _touches(slot, start, stop, labeled)
    near = np.zeros(len(slot), dtype=bool)
    if missing_mm is not None:
        mm = np.asarray(missing_mm, dtype=np.int64).reshape(-1)
        near = ghost & (mm >= 0) & (mm <= near_mm)
    if not labeled_only:
        shown |= ghost & ((length >= min_frames) | (confidence < DOUBTFUL) | cut | near)
    idx = np.flatnonzero(shown)
    ghost = label[idx] < 0
    # Labeled first, least confident first, then shortest (short labels are the likeliest wrong: a
    # quarter of the 1-9-frame ones were wrong on the temporal benchmark's takes, under 1 % of those of 30
    # frames or more); then unlabeled pieces: those cut from a doubtful label's trajectory (each of the 6 on
    # those takes was a marker's samples), then those close to a missing marker, then least sure they are no
    # marker, then longest. Ties by start, slot. Confidence as reports round it (4 decimals): a report's
    # entries rank as the labeling's (queue_entries).
    by_length, doubt = np.where(ghost, -length[idx], length[idx]), np.round(confidence[idx], 4)
    return idx[np.lexsort((slot[idx], start[idx], by_length, doubt, ~near[idx], ~cut[idx], ghost))]


def review_queue(labeling: Labeling, sure: float = SURE, *, labeled_only: bool = False,
                 min_frames: int = QUEUE_MIN_FRAMES, near_mm: int = QUEUE_NEAR_MM) -> np.ndarray:
    """Indices of the segments a reviewer should look at, in the order to look at them: the one list
    behind the panel's list, Previous / Next, the Timeline's marks and the HTML report.

    Of the unlocked segments below ``sure`` (:func:`uncertain_segments`):

    1. every labeled one, least confident first, then shortest: a label in doubt is what a review is
       for, and short labels are the likeliest wrong;
    2. then the unlabeled pieces that may be a marker: those that continue a labeled segment in doubt
       first (the vote cut one trajectory between a doubtful label and no label: one of the two is
       likely wrong), then those close to a marker the labeling lacks, then least sure, then longest.
       An unlabeled piece's confidence is how sure the vote is that it is no marker (the calibrated
       chance that leaving it unlabeled is right). It is shown when it continues a labeled segment in
       doubt, when it is ``min_frames`` long or longer, when a sample of it lies within ``near_mm`` of
       where a marker no trajectory carries in that frame should be (a marker seen again for a few frames
       in its gap: :attr:`.labeling.Labeling.missing_mm`; a labeling that does not know it, stored before
       it was recorded, goes without this rule), or when it is more likely a marker than not (below
       :data:`DOUBTFUL`). Other short ghosts are the flicker and spurious reflections that the vote leaves
       unlabeled: they do not appear as uncertain (:func:`null_classes`).

    Args:
        labeled_only: labeled segments alone.
        min_frames: the shortest unlabeled piece shown for its length alone.
        near_mm: the farthest a short piece may lie from a missing marker to be shown for it (-1: none).
    """
    return rank_segments(labeling.slot, labeling.start, labeling.stop, labeling.label, labeling.confidence,
                         labeling.locked, sure, labeled_only=labeled_only, min_frames=min_frames,
                         missing_mm=labeling.missing_mm, near_mm=near_mm)


def queue_entries(segments: list[dict], *, labeled_only: bool = False,
                  min_frames: int = QUEUE_MIN_FRAMES, near_mm: int = QUEUE_NEAR_MM) -> list[dict]:
    """The review queue of a report's uncertain segments (``Labeling.summary()["uncertain_segments"]``:
    dicts with ``slot``, ``start``, ``stop``, ``label`` (None: unlabeled), ``confidence`` and, for an
    unlabeled one where the labeling knew it, ``missing_mm``), in the order of :func:`review_queue`. Every
    given segment counts as uncertain (the report chose them at its own threshold), and the labeled segments
    a piece may continue are among them: the result is the labeling's :func:`review_queue` at that
    threshold. A report without ``missing_mm`` (written before it was recorded) ranks without that rule."""
    if not segments:
        return []
    col = {k: np.array([s[k] for s in segments]) for k in ("slot", "start", "stop", "confidence")}
    label = np.array([NULL if s["label"] is None else 0 for s in segments])
    unlabeled = [s for s in segments if s["label"] is None]
    missing = None
    if unlabeled and all("missing_mm" in s for s in unlabeled):
        missing = np.array([-1 if s["label"] is not None else s["missing_mm"] for s in segments])
    order = rank_segments(col["slot"], col["start"], col["stop"], label, col["confidence"],
                          np.zeros(len(segments), dtype=bool), np.inf, labeled_only=labeled_only,
                          min_frames=min_frames, missing_mm=missing, near_mm=near_mm)
    return [segments[i] for i in order]


def walk_uncertain(labeling: Labeling, sure: float, frame: int, current: tuple[int, int] | None = None,
                   previous: bool = False, *, labeled_only: bool = False,
                   min_frames: int = QUEUE_MIN_FRAMES) -> int | None:
    """The queued segment that Next (or Previous) goes to, or None at the end of the walk.

    The walk visits the :func:`review_queue` (with the same filters) in time order: by start frame,
    then by slot (a stable tie-break: several segments often start on one frame, and each must be
    reached).

    Args:
        frame: the current sample index.
        current: ``(start, slot)`` of the segment the walk stands on, where it still stands on it
            (its start is ``frame``); None when the reviewer moved elsewhere: then Next goes to the
            first segment starting at or after ``frame`` (one starting here included) and Previous
            to the last one starting at or before it.
    """
    idx = review_queue(labeling, sure, labeled_only=labeled_only, min_frames=min_frames)
    if not len(idx):
        return None
    start, slot = labeling.start[idx], labeling.slot[idx]
    if current is not None and current[0] == frame:
        here = (int(current[0]), int(current[1]))
        after = (start > here[0]) | ((start == here[0]) & (slot > here[1]))
        before = (start < here[0]) | ((start == here[0]) & (slot < here[1]))
    else:
        after, before = start >= frame, start <= frame
    pick = idx[before] if previous else idx[after]
    if not len(pick):
        return None
    order = np.lexsort((labeling.slot[pick], labeling.start[pick]))  # by start, then slot
    return int(pick[order[-1] if previous else order[0]])


def plural(n: int, word: str, many: str | None = None) -> str:
    """``"1 correction"``, ``"2 corrections"`` (``many`` for irregular plurals: trajectory, trajectories)."""
    return f"{n} {word if n == 1 else (many or word + 's')}"


@dataclass
class Review:
    """The reviewer's corrections on one take.

    Attributes:
        constraints: locked decisions, in the order they were made.
        splits: ``(slot, frame)`` points where a tracklet is cut before the decision.
    """

    constraints: list[Constraint] = field(default_factory=list)
    splits: list[tuple[int, int]] = field(default_factory=list)

    def _segment(self, labeling: Labeling, slot: int, frame: int) -> int:
        seg = np.flatnonzero((labeling.slot == slot) & (labeling.start <= frame) & (labeling.stop > frame))
        if not len(seg):
            raise ValueError(f"point slot {slot} has no sample at frame {frame}")
        return int(seg[0])

    def overridden_by(self, new: Constraint) -> list[Constraint]:
        """The earlier corrections that ``new`` overrides (in part): those on the same samples that
        decide otherwise, and those giving its label to another trajectory in the same frames."""
        out = []
        for c in self.constraints:
            overlap = c.stop > new.start and c.start < new.stop
            if overlap and ((c.slot == new.slot and c.label != new.label)
                            or (c.slot != new.slot and c.label == new.label != NULL)):
                out.append(c)
        return out

    def remove(self, index: int) -> Constraint:
        """Delete one correction (by its place in :attr:`constraints`); a re-solve then decides its
        samples again."""
        if not 0 <= index < len(self.constraints):
            raise ValueError(f"there is no correction number {index + 1} (the take has "
                             f"{plural(len(self.constraints), 'correction')})")
        return self.constraints.pop(index)

    def remove_at(self, slot: int, frame: int) -> list[Constraint]:
        """Delete every correction on ``slot`` that covers ``frame`` (Unlock); returns them."""
        gone = [c for c in self.constraints if c.slot == slot and c.start <= frame < c.stop]
        self.constraints = [c for c in self.constraints if c not in gone]
        return gone

    def _add(self, new: Constraint) -> Constraint:
        # A newer decision replaces an older one where they overlap: on the same samples, or
        # giving the same label to another slot (one label, one sample per frame).
        kept = []
        for c in self.constraints:
            overlap = c.stop > new.start and c.start < new.stop
            rival = c.slot == new.slot or (c.label == new.label != NULL)
            if not (overlap and rival):
                kept.append(c)
                continue
            if c.start < new.start:
                kept.append(Constraint(c.slot, c.start, new.start, c.label))
            if c.stop > new.stop:
                kept.append(Constraint(c.slot, new.stop, c.stop, c.label))
        self.constraints = kept + [new]
        return new

    def assign(self, labeling: Labeling, slot: int, frame: int, label: int) -> Constraint:
        """Give the tracklet in ``slot`` the ``label`` (or :data:`NULL`) from ``frame`` to the end of its segment."""
        seg = self._segment(labeling, slot, frame)
        return self._add(Constraint(slot, frame, int(labeling.stop[seg]), int(label)))

    def unlabel(self, labeling: Labeling, slot: int, frame: int) -> Constraint:
        """Mark the tracklet in ``slot`` a ghost from ``frame`` to the end of its segment."""
        return self.assign(labeling, slot, frame, NULL)

    def lock(self, labeling: Labeling, slot: int, frame: int) -> Constraint:
        """Keep the whole segment under (slot, frame) as it is now."""
        seg = self._segment(labeling, slot, frame)
        return self._add(Constraint(slot, int(labeling.start[seg]), int(labeling.stop[seg]), int(labeling.label[seg])))

    def swap(self, labeling: Labeling, label_a: int, label_b: int, frame: int) -> list[Constraint]:
        """Exchange two labels from ``frame`` on (to the end of each carrier's segment)."""
        per = labeling.per_sample()[frame]
        carriers = {lab: np.flatnonzero(per == lab) for lab in (label_a, label_b)}
        if not len(carriers[label_a]) and not len(carriers[label_b]):
            raise ValueError(f"neither label is present at frame {frame}")
        out = []
        for lab, other in ((label_a, label_b), (label_b, label_a)):
            for slot in carriers[lab]:
                out.append(self.assign(labeling, int(slot), frame, other))
        return out

    def split(self, labeling: Labeling, slot: int, frame: int) -> tuple[int, int]:
        """Cut the tracklet in ``slot`` before ``frame``: the two parts are decided separately."""
        seg = self._segment(labeling, slot, frame)
        if frame == labeling.start[seg]:
            raise ValueError(f"frame {frame} already starts a segment of slot {slot}")
        self.splits.append((int(slot), int(frame)))
        return self.splits[-1]

    def to_dict(self) -> dict:
        return {"constraints": [[c.slot, c.start, c.stop, c.label] for c in self.constraints],
                "splits": [list(s) for s in self.splits]}

    @classmethod
    def from_dict(cls, data: dict) -> Review:
        return cls([Constraint(*(int(v) for v in c)) for c in data.get("constraints", [])],
                   [(int(a), int(b)) for a, b in data.get("splits", [])])

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Flat int arrays (``constraints``: ``(n * 4,)``, ``splits``: ``(s * 2,)``), for storage
        where nested lists are not allowed (Blender custom properties)."""
        return {"constraints": np.array([[c.slot, c.start, c.stop, c.label] for c in self.constraints],
                                        dtype=np.int64).reshape(-1),
                "splits": np.array(self.splits, dtype=np.int64).reshape(-1)}

    @classmethod
    def from_arrays(cls, constraints, splits) -> Review:
        c = np.asarray(constraints, dtype=np.int64).reshape(-1, 4)
        s = np.asarray(splits, dtype=np.int64).reshape(-1, 2)
        return cls([Constraint(*(int(v) for v in row)) for row in c], [(int(a), int(b)) for a, b in s])


def _rebuild(labeling: Labeling, per: np.ndarray, conf: np.ndarray, locked: np.ndarray,
             cut: np.ndarray, edited: np.ndarray | None = None) -> Labeling:
    """A Labeling from edited per-sample arrays: a segment starts at every old segment start, at
    every ``cut`` and wherever the label changes; its confidence, lock and distance to a missing marker
    come from its first sample (no distance where that sample was ``edited``)."""
    begin = np.zeros(per.shape, dtype=bool)
    begin[labeling.start, labeling.slot] = True
    out = segments_from_runs(labeling.names, per, per != EMPTY, dict(labeling.info), split=begin | cut)
    out.confidence = conf[out.start, out.slot].astype(np.float32)
    out.locked = locked[out.start, out.slot]
    if labeling.missing_mm is not None:
        missing = labeling._paint(labeling.missing_mm, -1, np.int32)
        if edited is not None:
            missing[edited] = -1
        out.missing_mm = np.where(out.label < 0, missing[out.start, out.slot], -1).astype(np.int32)
    return out


def relabel_samples(labeling: Labeling, per: np.ndarray, edited: np.ndarray, cap: float) -> Labeling:
    """``labeling`` with the per-sample labels ``per`` ``(F, P)`` in place of its own: segments cut
    where the labels change, the ``edited`` samples' confidence at most ``cap`` (a check that moved
    labels: the reviewer sees them). Each segment keeps the evidence of the segment its first sample
    was on (its length its own): the no-hand rule reads it."""
    confidence = labeling.per_sample_confidence()
    confidence[edited] = np.minimum(confidence[edited], np.float32(cap))
    out = _rebuild(labeling, per, confidence, labeling.per_sample_locked(), np.zeros(per.shape, dtype=bool), edited)
    if labeling.evidence is not None:
        out.evidence = labeling.evidence[labeling.segment_ids()[out.start, out.slot]].copy()
        out.evidence[:, 3] = out.length
    return out


def apply_constraints(labeling: Labeling, constraints: list[Constraint]) -> Labeling:
    """The labeling with the user's new decisions made, and nothing else changed.

    Each constraint's samples get its label, confidence 1 and the lock. A label given to a slot is
    taken from whichever other slot carried it in those frames: those samples become null with
    confidence 0 (very uncertain: a re-solve may find them another label). Evidence is dropped
    (it described the old segments); an unlabeled segment's distance to a missing marker is kept where
    its samples were not edited.
    """
    per = labeling.per_sample()
    conf = labeling.per_sample_confidence()
    locked = labeling.per_sample_locked()
    changed = np.zeros(per.shape, dtype=bool)
    for c in constraints:
        rows = slice(c.start, c.stop)
        here = np.zeros(per.shape, dtype=bool)
        here[rows, c.slot] = per[rows, c.slot] != EMPTY
        if c.label != NULL:
            taken = np.zeros(per.shape, dtype=bool)
            taken[rows] = per[rows] == c.label
            taken &= ~here
            per[taken], conf[taken], locked[taken] = NULL, 0.0, False
            changed |= taken
        per[here], conf[here], locked[here] = c.label, 1.0, True
        changed |= here
    # Cut wherever an edited run starts or ends, so edited samples never share a segment with others.
    cut = np.zeros(per.shape, dtype=bool)
    cut[1:] = changed[1:] != changed[:-1]
    cut[0] = changed[0]
    out = _rebuild(labeling, per, conf, locked, cut, changed)
    out.info["constraints"] = labeling.info.get("constraints", 0) + len(constraints)
    return out


def apply_split(labeling: Labeling, slot: int, frame: int) -> Labeling:
    """The labeling with the segment of ``slot`` cut before ``frame`` (labels unchanged)."""
    cut = np.zeros((labeling.n_frames, labeling.n_points), dtype=bool)
    cut[frame, slot] = True
    return _rebuild(labeling, labeling.per_sample(), labeling.per_sample_confidence(), labeling.per_sample_locked(),
                    cut)


def labeling_to_arrays(labeling: Labeling) -> dict:
    """The Labeling as flat arrays plus its names and shape, for storage (see :func:`labeling_from_arrays`):
    ``missing_mm`` (integers) only where the labeling knows it."""
    out = {"names": list(labeling.names), "n_frames": labeling.n_frames, "n_points": labeling.n_points,
           "slot": labeling.slot, "start": labeling.start, "stop": labeling.stop, "label": labeling.label,
           "confidence": labeling.confidence, "locked": labeling.locked}
    if labeling.missing_mm is not None:
        out["missing_mm"] = labeling.missing_mm
    return out


def labeling_from_arrays(data, info: dict | None = None) -> Labeling:
    """Inverse of :func:`labeling_to_arrays` (any mapping whose arrays numpy can read). Stored without
    ``missing_mm`` (before it was recorded), or with one of another length, the labeling does not know it."""
    slot = np.asarray(data["slot"], dtype=np.int64)
    missing = np.asarray(data["missing_mm"], dtype=np.int32).reshape(-1) if "missing_mm" in data else None
    if missing is not None and missing.shape != slot.shape:
        missing = None
    return Labeling(names=list(data["names"]), n_frames=int(data["n_frames"]), n_points=int(data["n_points"]),
                    slot=slot, start=np.asarray(data["start"], dtype=np.int64),
                    stop=np.asarray(data["stop"], dtype=np.int64), label=np.asarray(data["label"], dtype=np.int16),
                    confidence=np.asarray(data["confidence"], dtype=np.float32),
                    locked=np.asarray(data["locked"], dtype=bool), info=dict(info or {}), missing_mm=missing)


def changed_labels(before: Labeling, after: Labeling, sure_before: float = SURE,
                   sure_after: float | None = None) -> np.ndarray:
    """Layout labels whose samples or classes differ between two labelings of the same take (classes
    taken at each one's confidence threshold: a new threshold alone recolours some markers)."""
    pb, pa = before.per_sample(), after.per_sample()
    cb = marker_classes(before, sure_before)
    ca = marker_classes(after, sure_before if sure_after is None else sure_after)
    moved = set(np.unique(pb[pb != pa])) | set(np.unique(pa[pb != pa]))
    moved |= set(np.flatnonzero((cb != ca).any(axis=0)))
    return np.array(sorted(int(v) for v in moved if v >= 0), dtype=np.int64)


def remap_review(review: Review, old_names: list[str], new_names: list[str]) -> tuple[Review, list[Constraint]]:
    """The corrections of a take relabeled with another layout, and those that cannot follow.

    A label keeps its meaning where the new layout has a marker of the same name; ghost
    (:data:`NULL`) decisions and splits hold in every layout. A correction naming a label the new
    layout lacks is returned as dropped (the caller says so: a correction is never lost silently).
    """
    index = {name: i for i, name in enumerate(new_names)}
    kept, dropped = [], []
    for c in review.constraints:
        if c.label == NULL:
            kept.append(c)
        elif old_names[c.label] in index:
            kept.append(Constraint(c.slot, c.start, c.stop, index[old_names[c.label]]))
        else:
            dropped.append(c)
    return Review(kept, list(review.splits)), dropped


def describe(c: Constraint, label_names: list[str], point_names: list[str], first: int = 0) -> str:
    """A correction in the reviewer's words: ``"ThumbTip on *3, frames 100-1199"`` (frames as the
    scene shows them: ``first`` is the frame of sample 0, the range is inclusive)."""
    what = "unlabeled" if c.label == NULL else label_names[c.label]
    return f"{what} on {point_names[c.slot]}, frames {c.start + first}-{c.stop - 1 + first}"


@dataclass(frozen=True)
class BadRun:
    """A run of frames that needs a look: ``[start, stop)`` sample indices, the most uncertain samples
    and missing labels in one of its frames, and its ``score`` (the sum over its frames of both)."""

    start: int
    stop: int
    uncertain: int
    missing: int
    score: int


def frame_trouble(labeling: Labeling, sure: float = SURE, *, labeled_only: bool = False,
                  min_frames: int = QUEUE_MIN_FRAMES) -> tuple[np.ndarray, np.ndarray]:
    """int ``(frames,)`` twice: per frame, the samples of segments in the review queue (labeled or not, as
    :func:`review_queue` with these filters shows them), and the labels missing inside their own span (a
    label is missing at a frame between its first and last sample where no sample carries it: a gap; a
    label the take never shows is not counted, it would mark every frame)."""
    queued = np.zeros(len(labeling), dtype=bool)
    queued[review_queue(labeling, sure, labeled_only=labeled_only, min_frames=min_frames)] = True
    per = labeling.per_sample()
    uncertain = labeling._paint(queued, False, bool).sum(axis=1).astype(np.int64)
    m = len(labeling.names)
    present = np.zeros((labeling.n_frames, m), dtype=bool)
    f, s = np.nonzero(per >= 0)
    present[f, per[f, s]] = True
    seen = present.any(axis=0)
    first = np.where(seen, present.argmax(axis=0), labeling.n_frames)
    last = np.where(seen, labeling.n_frames - 1 - present[::-1].argmax(axis=0), -1)
    frames = np.arange(labeling.n_frames)[:, None]
    inside = (frames >= first[None]) & (frames <= last[None])
    missing = (inside & ~present).sum(axis=1).astype(np.int64)
    return uncertain, missing


def bad_runs(labeling: Labeling, sure: float = SURE, limit: int | None = None, *, labeled_only: bool = False,
             min_frames: int = QUEUE_MIN_FRAMES) -> list[BadRun]:
    """The runs of consecutive frames with queued samples or missing labels (:func:`frame_trouble`),
    worst (highest score) first, at most ``limit``."""
    uncertain, missing = frame_trouble(labeling, sure, labeled_only=labeled_only, min_frames=min_frames)
    score = uncertain + missing
    bad = np.concatenate([[False], score > 0, [False]])
    edges = np.flatnonzero(np.diff(bad.astype(np.int8)))
    runs = []
    for start, stop in zip(edges[::2], edges[1::2], strict=True):
        runs.append(BadRun(int(start), int(stop), int(uncertain[start:stop].max()), int(missing[start:stop].max()),
                           int(score[start:stop].sum())))
    runs.sort(key=lambda r: (-r.score, r.start))
    return runs[:limit] if limit is not None else runs
