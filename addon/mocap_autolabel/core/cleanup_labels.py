"""The cleanup tools' edits of a labeling (:mod:`.cleanup` finds what to edit; this says how the
labeling and the reviewer's corrections take it).

- **Suspect samples** (:func:`mark_suspects`; spikes and jumps of :func:`.cleanup.find_spikes`):
  each run of them on one trajectory becomes a segment of its own, cut before and after (the cuts
  are the reviewer's splits, :class:`.review.Review`, so a re-solve decides the piece on its own),
  with the confidence :data:`SUSPECT_CONFIDENCE`: very uncertain, so its keys take the review colour
  and the review queue (the panel's list, Previous / Next, the Timeline's marks) shows it. Its label
  stays as it was.
- **Short fragments** (:func:`short_segments`, :func:`unlabel_segments`): the labeled segments whose
  samples lie in a run of their label shorter than ``min_frames`` (a label's run: consecutive frames
  with a sample, whichever trajectory carries it) are unlabeled by correction (a lock to "no label"),
  so a re-solve keeps them off the label.
- **Quick labeling** (:func:`label_segment`): a trajectory's segment gets a label by correction,
  as Assign Label gives one, but the whole segment, not from a frame on.

Locked samples (the reviewer's decisions) are never touched: they are counted and left as they are.
Blender-free.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .labeling import EMPTY, NULL, Constraint, Labeling, segments_from_runs
from .review import Review

#: The confidence of a piece of suspect samples: 0, as the samples a correction takes a label from
#: (:func:`.review.apply_constraints`): very uncertain until a re-solve decides them again.
SUSPECT_CONFIDENCE = 0.0


def carriers(labeling: Labeling) -> np.ndarray:
    """int ``(F, L)``: the point slot that carries each label at each frame, -1 where none does."""
    per = labeling.per_sample()
    out = np.full((labeling.n_frames, len(labeling.names)), -1, dtype=np.int64)
    f, s = np.nonzero(per >= 0)
    out[f, per[f, s]] = s
    return out


def to_slots(labeling: Labeling, mask: np.ndarray, labels: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The samples of bool ``mask (F, k)`` over the labels ``labels`` (default all ``L``) as
    ``(frames, slots)``: int ``(n,)`` each, the trajectory that carries each one (samples of a
    label no trajectory carries there are left out)."""
    car = carriers(labeling)
    if labels is not None:
        car = car[:, np.asarray(labels, dtype=np.int64)]
    f, k = np.nonzero(np.asarray(mask, dtype=bool))
    slots = car[f, k]
    keep = slots >= 0
    return f[keep], slots[keep]


@dataclass(frozen=True)
class Marked:
    """What :func:`mark_suspects` did: ``samples`` marked, ``locked`` suspect samples left as they
    are (the reviewer's decisions), ``cuts`` new splits."""

    samples: int
    locked: int
    cuts: int


def mark_suspects(labeling: Labeling, review: Review, suspect: np.ndarray) -> tuple[Labeling, Marked]:
    """The labeling with the suspect labeled samples cut out and marked very uncertain.

    Args:
        suspect: bool ``(F, P)``: samples (frames by point slot) to mark; unlabeled, missing and
            locked ones are left as they are.
        review: the take's corrections: the cuts are added to its splits (in place).

    Returns:
        the new labeling (labels unchanged; the pieces of suspect samples are segments of their own
        at :data:`SUSPECT_CONFIDENCE`, unlocked; evidence dropped, as a correction drops it), and
        the counts.
    """
    suspect = np.asarray(suspect, dtype=bool)
    if suspect.shape != (labeling.n_frames, labeling.n_points):
        raise ValueError(f"suspect must be (frames, points) = {(labeling.n_frames, labeling.n_points)}, "
                         f"got {suspect.shape}")
    per = labeling.per_sample()
    present = per != EMPTY
    locked = labeling.per_sample_locked()
    conf = labeling.per_sample_confidence()
    labeled = suspect & (per >= 0)
    mark = labeled & ~locked
    begin = np.zeros(per.shape, dtype=bool)
    begin[labeling.start, labeling.slot] = True
    cut = np.zeros(per.shape, dtype=bool)
    cut[1:] = (mark[1:] != mark[:-1]) & present[1:] & present[:-1]  # where a run of marks starts or ends
    new = cut & ~begin
    known = set(review.splits)
    for frame, slot in zip(*np.nonzero(new)):
        if (int(slot), int(frame)) not in known:
            review.splits.append((int(slot), int(frame)))
    out = segments_from_runs(labeling.names, per, present, dict(labeling.info), split=begin | cut)
    out.confidence = conf[out.start, out.slot].astype(np.float32)
    out.locked = locked[out.start, out.slot]
    mine = mark[out.start, out.slot]
    out.confidence[mine] = np.minimum(out.confidence[mine], SUSPECT_CONFIDENCE)
    return out, Marked(int(mark.sum()), int((labeled & locked).sum()), int(new.sum()))


def short_segments(labeling: Labeling, min_frames: int, labels=None) -> tuple[np.ndarray, np.ndarray]:
    """The labeled segments whose samples lie in a run of their label shorter than ``min_frames``
    (:func:`.cleanup.short_fragments` over the labels' samples), of the labels ``labels`` (default
    all): int ``(n,)`` indices of the unlocked ones, and of the locked ones (left as they are)."""
    from .cleanup import short_fragments

    valid = carriers(labeling) >= 0
    short = short_fragments(valid, min_frames=min_frames)
    if labels is not None:
        chosen = np.zeros(valid.shape[1], dtype=bool)
        chosen[np.asarray(labels, dtype=np.int64)] = True
        short &= chosen[None, :]
    lab = labeling.label.astype(np.int64)
    # a segment lies inside one run of its label: its first sample says
    hit = (lab >= 0) & (labeling.length > 0)
    hit[hit] = short[labeling.start[hit], lab[hit]]
    return np.flatnonzero(hit & ~labeling.locked), np.flatnonzero(hit & labeling.locked)


def unlabel_segments(labeling: Labeling, review: Review, segments) -> list[Constraint]:
    """Unlabel whole ``segments`` by correction (added to ``review``); the constraints made, for
    :func:`.review.apply_constraints`."""
    return [review.unlabel(labeling, int(labeling.slot[i]), int(labeling.start[i])) for i in segments]


def segment_at(labeling: Labeling, slot: int, index: int) -> int:
    """The segment of ``slot`` that holds sample ``index``; ValueError where the slot has none."""
    seg = np.flatnonzero((labeling.slot == slot) & (labeling.start <= index) & (labeling.stop > index))
    if not len(seg):
        raise ValueError(f"point slot {slot} has no sample at frame {index}")
    return int(seg[0])


def label_segment(labeling: Labeling, review: Review, slot: int, index: int, label: int) -> Constraint:
    """Give the whole segment of ``slot`` under sample ``index`` the ``label`` (or :data:`NULL`) by
    correction (added to ``review``): quick labeling. A label taken from another trajectory in those
    frames leaves that one unlabeled (:func:`.review.apply_constraints`)."""
    if not (label == NULL or 0 <= label < len(labeling.names)):
        raise ValueError(f"there is no label number {label} (the layout has {len(labeling.names)})")
    seg = segment_at(labeling, slot, index)
    return review.assign(labeling, slot, int(labeling.start[seg]), int(label))
