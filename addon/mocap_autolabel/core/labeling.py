"""The Labeling: one decision (a label or null, with a confidence) per tracklet segment.

A *segment* is a run of frames of one point slot: a tracklet, or a piece of one when the
tracklet was split (a swap inside it, or the edge of a user's constraint). Everything the
pipeline decides, and everything a reviewer changes, is said in segments.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from .errors import MocapInputError
from .layout import Layout
from .take import Take

NULL = -1  #: the label of a ghost / unassigned segment
EMPTY = -2  #: per-sample value where a slot has no sample


@dataclass(frozen=True)
class Constraint:
    """A user's decision: slot ``slot`` in frames ``[start, stop)`` is ``label`` (``NULL`` = ghost).

    Frames are 0-based indices into ``Take.positions``. Constraints name slots and frames, not
    segment ids, so they stay meaningful when the segmentation changes.
    """

    slot: int
    start: int
    stop: int
    label: int

    def __post_init__(self) -> None:
        if self.stop <= self.start:
            raise ValueError(f"constraint on slot {self.slot}: empty frame range [{self.start}, {self.stop})")


@dataclass
class Labeling:
    """Decisions for every segment of a take, as parallel arrays ordered by (slot, start).

    Attributes:
        names: the layout's label names (``M``).
        n_frames, n_points: the take's shape.
        slot, start, stop: int64 ``(n,)``: each segment's slot and frame range ``[start, stop)``.
        label: int16 ``(n,)``: label index, or :data:`NULL`.
        confidence: float32 ``(n,)`` in [0, 1]: the chance that the decision is right (calibrated
            where a calibration exists for the method; see ``core/temporal/confidence.py``).
        locked: bool ``(n,)``: decided by a user constraint.
        info: how it was made (method, temporal mode, timings...), for reports.
        evidence: float32 ``(n, 4)`` or None: what the confidence is computed from (see
            ``core/temporal/confidence.py: segment_evidence``).
        missing_mm: int32 ``(n,)`` or None: for each unlabeled segment, how far (mm) its nearest
            sample lies from where a marker the labeling lacks in that frame should be, -1 where no
            such marker was seen near in time (and for labeled segments); the review queue shows a
            short unlabeled piece close to a missing marker (``core/review.py:
            missing_marker_distance``). None: not known (a labeling stored before it was recorded).
        held: int64 ``(n,)`` or None: frames of the vote's segment each segment was cut from, where
            frames at its edges were cut off for review (``core/temporal/confidence.py:
            split_doubtful_edges``); the next vote of the pass reads how long a label was held from it.
            None: every segment is as the vote made it (:attr:`length`).
    """

    names: list[str]
    n_frames: int
    n_points: int
    slot: np.ndarray
    start: np.ndarray
    stop: np.ndarray
    label: np.ndarray
    confidence: np.ndarray
    locked: np.ndarray
    info: dict
    evidence: np.ndarray | None = None
    missing_mm: np.ndarray | None = None
    held: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.slot.shape[0])

    @property
    def length(self) -> np.ndarray:
        return self.stop - self.start

    def _paint(self, values: np.ndarray, fill, dtype) -> np.ndarray:
        out = np.full((self.n_frames, self.n_points), fill, dtype=dtype)
        lengths = self.length
        seg = np.repeat(np.arange(len(self)), lengths)
        offset = np.arange(int(lengths.sum())) - np.repeat(np.cumsum(lengths) - lengths, lengths)
        out[self.start[seg] + offset, self.slot[seg]] = values[seg]
        return out

    def per_sample(self) -> np.ndarray:
        """int16 ``(frames, points)``: the label of every sample, :data:`NULL`, or :data:`EMPTY` where
        the slot has no sample."""
        return self._paint(self.label, EMPTY, np.int16)

    def per_sample_confidence(self) -> np.ndarray:
        """float32 ``(frames, points)``: the confidence of every sample's segment, NaN where none."""
        return self._paint(self.confidence, np.nan, np.float32)

    def per_sample_locked(self) -> np.ndarray:
        """bool ``(frames, points)``: whether every sample's segment is locked by a reviewer."""
        return self._paint(self.locked, False, bool)

    def segment_ids(self) -> np.ndarray:
        """int32 ``(frames, points)``: the segment of every sample, -1 where none."""
        return self._paint(np.arange(len(self)), -1, np.int32)

    def label_range(self, first: int, stop: int) -> Labeling:
        """The segments labeled ``first`` to ``stop - 1`` (one hand of a two-hand labeling), relabeled
        from 0, with those names; the rest of the take is left out."""
        keep = (self.label >= first) & (self.label < stop)
        evidence = None if self.evidence is None else self.evidence[keep]
        missing = None if self.missing_mm is None else self.missing_mm[keep]
        return Labeling(names=self.names[first:stop], n_frames=self.n_frames, n_points=self.n_points,
                        slot=self.slot[keep], start=self.start[keep], stop=self.stop[keep],
                        label=(self.label[keep] - first).astype(np.int16), confidence=self.confidence[keep],
                        locked=self.locked[keep], info=self.info, evidence=evidence, missing_mm=missing)

    def uncertain(self, confident: float = 0.95) -> np.ndarray:
        """Indices of the segments a reviewer should look at: unlocked, below ``confident``, labeled or
        not (an uncertain unlabeled trajectory may be a missed marker), worst first, then by start."""
        idx = np.flatnonzero((self.confidence < confident) & ~self.locked & (self.length > 0))
        return idx[np.lexsort((self.start[idx], self.confidence[idx]))]

    def summary(self, confident: float = 0.95, first_frame: int = 0,
                points: list[str] | None = None) -> dict:
        """Counts for reports: segments, labeled samples, the share of labeled samples at or above
        ``confident``, and the uncertain segments (labeled or not, worst first; see :meth:`uncertain`).

        Each uncertain segment gives its ``slot``, its ``start``/``stop`` sample indices
        (0-based, stop exclusive), ``frame_start``/``frame_end`` in the take's own frame numbers
        (``first_frame`` is the frame of sample 0, as the file and Blender count; both inclusive),
        its ``label`` (None: unlabeled), the ``point`` that shows it in the labeled C3D and in
        Blender (the label, or the unlabeled point's name from ``points``, default ``*<slot>``) and
        its ``confidence``; an unlabeled one also its ``missing_mm`` where the labeling knows it (see
        :attr:`missing_mm`: the review queue's entries rank the same from the report).
        """
        named = self.label >= 0
        samples = self.length
        sure = named & (self.confidence >= confident)
        uncertain = []
        for i in self.uncertain(confident):
            label = self.names[self.label[i]] if self.label[i] >= 0 else None
            point = label or (points[self.slot[i]] if points is not None else f"*{int(self.slot[i])}")
            uncertain.append({"slot": int(self.slot[i]), "start": int(self.start[i]), "stop": int(self.stop[i]),
                              "frame_start": int(self.start[i]) + int(first_frame),
                              "frame_end": int(self.stop[i]) - 1 + int(first_frame),
                              "label": label, "point": point, "confidence": round(float(self.confidence[i]), 4)})
            if label is None and self.missing_mm is not None:
                uncertain[-1]["missing_mm"] = int(self.missing_mm[i])
        return {
            "segments": len(self),
            "labeled_segments": int(named.sum()),
            "null_segments": int((~named).sum()),
            "labeled_samples": int(samples[named].sum()),
            "null_samples": int(samples[~named].sum()),
            "confident_share": float(samples[sure].sum() / max(samples[named].sum(), 1)),
            "uncertain_segments": uncertain,
        }


#: A point name that says nothing (``*12``, as capture systems call unlabeled trajectories).
_ANONYMOUS = re.compile(r"\*\d+")


def unlabeled_point_names(names: list[str], labels: list[str]) -> list[str]:
    """The name of each point slot's unlabeled samples, in the labeled C3D and in Blender.

    A name the file gave (``right_elbow``, ``pillow_top``) is kept; an anonymous one (``*N``,
    empty) becomes ``*<slot>``, so that one ``*N`` means the same trajectory in the scene, the
    report and the export. A file name that is also a label of the layout, or a second slot of
    the same name, would make two points of one name: those become ``*<slot>`` too.
    """
    taken = set(labels)
    out = []
    for slot, name in enumerate(names):
        name = name.strip()
        if not name or _ANONYMOUS.fullmatch(name) or name in taken:
            name = f"*{slot}"
        taken.add(name)
        out.append(name)
    return out


def labeled_take(take: Take, labeling: Labeling) -> Take:
    """The labeled take: the layout's M points by name (NaN where missing), then one point per input
    slot holding that slot's unassigned samples (slots with none are left out), named by
    :func:`unlabeled_point_names`: the file's own name, or ``*<slot>``.

    Every input sample ends in exactly one output point (the test suite checks it on real files).
    """
    per = labeling.per_sample()
    m = len(labeling.names)
    valid = take.valid
    named = valid & (per >= 0)
    rest = valid & ~named
    out_named = np.full((take.n_frames, m, 3), np.nan, dtype=np.float32)
    f, p = np.nonzero(named)
    lab = per[f, p].astype(np.int64)
    if len(np.unique(f * m + lab)) != len(f):
        raise ValueError("labeling gives one label to two samples of the same frame")
    out_named[f, lab] = take.positions[f, p]
    keep = np.flatnonzero(rest.any(axis=0))
    rest_names = unlabeled_point_names(take.names, labeling.names)
    out_rest = np.where(rest[:, keep, None], take.positions[:, keep], np.nan).astype(np.float32)
    residuals = None
    if take.residuals is not None:
        res_named = np.full((take.n_frames, m), np.nan, dtype=np.float32)
        res_named[f, lab] = take.residuals[f, p]
        res_rest = np.where(rest[:, keep], take.residuals[:, keep], np.nan).astype(np.float32)
        residuals = np.concatenate([res_named, res_rest], axis=1)
    return Take(positions=np.concatenate([out_named, out_rest], axis=1),
                names=list(labeling.names) + [rest_names[i] for i in keep], rate=take.rate,
                first_frame=take.first_frame, source_units=take.source_units, residuals=residuals,
                source=take.source, vendor=take.vendor)


def segments_from_runs(names: list[str], labels: np.ndarray, valid: np.ndarray, info: dict,
                       split: np.ndarray | None = None) -> Labeling:
    """A Labeling from per-sample labels ``(F, P)``: one segment per run of one label in one slot
    (confidences 0, for the caller to fill).

    Args:
        labels: int ``(F, P)`` label per sample (ignored where not ``valid``).
        valid: bool ``(F, P)``.
        split: optional bool ``(F, P)``: also start a new segment where True (a tracklet start).
    """
    frames, points = valid.shape
    lab = np.where(valid, labels, EMPTY).astype(np.int64)
    change = np.ones_like(valid)
    change[1:] = lab[1:] != lab[:-1]
    if split is not None:
        change |= split
    begin = valid & change
    # Row-major order over (slot, frame) gives segments ordered by (slot, start).
    slot, start = np.nonzero(begin.T)
    seg = np.cumsum(begin.T.ravel()) - 1
    n = len(slot)
    length = np.bincount(seg[valid.T.ravel()], minlength=n)
    return Labeling(names=list(names), n_frames=frames, n_points=points, slot=slot.astype(np.int64),
                    start=start.astype(np.int64), stop=(start + length).astype(np.int64),
                    label=lab.T[slot, start].astype(np.int16), confidence=np.zeros(n, dtype=np.float32),
                    locked=np.zeros(n, dtype=bool), info=info)


def layout_markers(take: Take, layout: Layout) -> np.ndarray:
    """``(F, M, 3)`` positions of a labeled take in layout order (metres, NaN where missing).

    Raises:
        MocapInputError: the take lacks some of the layout's marker names.
    """
    where = {n: i for i, n in enumerate(take.names)}
    missing = [n for n in layout.names if n not in where]
    if missing:
        more = f" and {len(missing) - 5} more" if len(missing) > 5 else ""
        raise MocapInputError(take.source, f"is not labeled with layout {layout.name!r}: it lacks "
                                           f"{', '.join(missing[:5])}{more}")
    return take.positions[:, [where[n] for n in layout.names]].astype(float)
