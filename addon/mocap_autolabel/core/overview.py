"""A take at a glance: the class of every label at every frame (confident, uncertain, gap...), for pictures."""

from __future__ import annotations

import numpy as np

from .labeling import Labeling
from .take import Take

#: Classes of :func:`label_classes`, in the order of :data:`CLASS_NAMES`.
ABSENT, GAP, CONFIDENT, UNCERTAIN, VERY_UNCERTAIN, LOCKED, FILLED = range(7)
CLASS_NAMES = ("absent", "gap", "confident", "uncertain", "very uncertain", "locked", "filled")
#: Below this a labeled sample is "very uncertain" (as Blender's review colours: extreme keys).
VERY_UNCERTAIN_BELOW = 0.5


def label_classes(labeling: Labeling, confident: float = 0.95, filled: np.ndarray | None = None) -> np.ndarray:
    """int8 ``(labels, frames)``: what each label has at each frame.

    ``CONFIDENT`` / ``UNCERTAIN`` / ``VERY_UNCERTAIN`` (below :data:`VERY_UNCERTAIN_BELOW`) / ``LOCKED``
    where a segment carries the label (by its calibrated confidence against ``confident``); ``GAP``
    where the label has no sample between its first and last labeled frame; ``ABSENT`` outside them.
    ``filled``: bool ``(labels, frames)``, samples a gap filler made up (shown as ``FILLED``), or None.
    """
    m, n = len(labeling.names), labeling.n_frames
    out = np.full((m, n), ABSENT, dtype=np.int8)
    keep = (labeling.label >= 0) & (labeling.length > 0)
    start, stop, label = labeling.start[keep], labeling.stop[keep], labeling.label[keep].astype(np.int64)
    conf, locked = labeling.confidence[keep], labeling.locked[keep]
    cls = np.where(locked, LOCKED, np.where(conf >= confident, CONFIDENT,
                                            np.where(conf >= VERY_UNCERTAIN_BELOW, UNCERTAIN, VERY_UNCERTAIN)))
    lengths = stop - start
    seg = np.repeat(np.arange(len(start)), lengths)
    frame = start[seg] + np.arange(int(lengths.sum())) - np.repeat(np.cumsum(lengths) - lengths, lengths)
    present = np.zeros((m, n), dtype=bool)
    present[label[seg], frame] = True
    first = np.where(present.any(axis=1), present.argmax(axis=1), n)
    last = np.where(present.any(axis=1), n - 1 - present[:, ::-1].argmax(axis=1), -1)
    frames = np.arange(n)
    out[(frames >= first[:, None]) & (frames <= last[:, None])] = GAP
    out[label[seg], frame] = cls[seg]
    if filled is not None:
        out[np.asarray(filled, dtype=bool) & (out == GAP)] = FILLED
    return out


def label_fills(names: list[str], take: Take) -> np.ndarray | None:
    """bool ``(labels, frames)``: the samples of each of ``names`` that a gap filler made up in
    ``take`` (its points named as the labels; :attr:`.take.Take.filled`), for :func:`label_classes`'s
    ``filled``; None when the take marks no fills."""
    if take.filled is None:
        return None
    column = {n: i for i, n in enumerate(take.names)}
    out = np.zeros((len(names), take.n_frames), dtype=bool)
    for i, name in enumerate(names):
        if name in column:
            out[i] = take.filled[:, column[name]]
    return out
