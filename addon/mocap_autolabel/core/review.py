"""Review of a Labeling: confidence classes, and the user's corrections as constraints.

Every correction a reviewer makes is a :class:`~.labeling.Constraint` (or a split point) on
the take, never an edit of the result: re-solving with all of them reproduces each one exactly
and lets its consequences propagate (a label taken here is no longer available elsewhere).
Blender-free: the operators in ``operators/review.py`` only call these.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .labeling import NULL, Constraint, Labeling

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


def marker_classes(labeling: Labeling) -> np.ndarray:
    """int8 ``(frames, M)``: the class of each layout marker's sample per frame, -1 where it is missing."""
    seg = labeling.segment_ids()
    per = labeling.per_sample()
    classes = segment_classes(labeling)
    out = np.full((labeling.n_frames, len(labeling.names)), -1, dtype=np.int8)
    f, s = np.nonzero(per >= 0)
    out[f, per[f, s]] = classes[seg[f, s]]
    return out


def uncertain_segments(labeling: Labeling, sure: float = SURE) -> np.ndarray:
    """Indices of the unlocked labeled segments below ``sure``, worst first (then by start frame)."""
    idx = np.flatnonzero((labeling.label >= 0) & (labeling.confidence < sure) & ~labeling.locked)
    return idx[np.lexsort((labeling.start[idx], labeling.confidence[idx]))]


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

    def _add(self, new: Constraint) -> Constraint:
        # A newer decision on the same samples replaces the older one where they overlap.
        kept = []
        for c in self.constraints:
            if c.slot != new.slot or c.stop <= new.start or c.start >= new.stop:
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


def changed_labels(before: Labeling, after: Labeling) -> np.ndarray:
    """Layout labels whose samples or classes differ between two labelings of the same take."""
    pb, pa = before.per_sample(), after.per_sample()
    cb, ca = marker_classes(before), marker_classes(after)
    moved = set(np.unique(pb[pb != pa])) | set(np.unique(pa[pb != pa]))
    moved |= set(np.flatnonzero((cb != ca).any(axis=0)))
    return np.array(sorted(int(v) for v in moved if v >= 0), dtype=np.int64)
