"""Which trajectory holds a marker, checked by the template hand.

On sparse sets a ghost that rides with the hand (a ring, a watch, a reflection) can look to a
labeler that sees one frame at a time like a fingertip: it takes the marker's label for a whole
trajectory, and the marker's own trajectory is left null. The average template hand, solved on a
few frames of a null trajectory with that trajectory in a label's place, fits clearly better there
than with the trajectory that holds the label: the null one takes the label over its frames (see
:func:`better_holders`). Fingertips alone cannot say so (a finger bends to reach most places near
the hand): only layouts with a hand cluster are checked.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..layout import Layout
from .ik import HandSolver
from .skeleton import HandModel

#: Frames of a null trajectory the template hand is solved on (evenly spread over it).
FRAMES = 8
#: Null trajectories shorter than this (frames) are not checked: a label needs a trajectory to vote on.
MIN_FRAMES = 10
#: Null trajectories checked per hand at most (the longest first): a bound on the work, never on time.
MOST = 24
#: A null trajectory takes a label where the hand's median RMS residual with it in the label's
#: place is at most this share of the residual with the labeling's own. On han2018's tips + hand
#: cluster takes the ghosts' pieces fitted at 0.1-0.5 of the labeling's residual, and no right
#: label came within 0.7.
MARGIN = 0.7
#: ... and at least this much lower (metres): near the noise a ratio says nothing.
MIN_GAIN = 0.002
#: Labeled markers a frame must show to be solved on.
SEEN = 5


@dataclass(frozen=True)
class Holder:
    """A null trajectory piece (``slot``, frames ``[start, stop)``) that should hold ``label``; the
    template hand's median RMS residual (metres) with it (``fitted``) and with the labeling's own
    holder (``before``)."""

    slot: int
    start: int
    stop: int
    label: int
    fitted: float
    before: float


def better_holders(positions: np.ndarray, observed: np.ndarray, candidates: list[tuple[int, int, int]],
                   layout: Layout, side: str) -> list[Holder]:
    """The null trajectory pieces that fit the template hand clearly better (:data:`MARGIN`,
    :data:`MIN_GAIN`) in a label's place than the labeling's own holder of that label, best first.

    Args:
        positions: ``(F, P, 3)`` the take's points (metres).
        observed: ``(F, M, 3)`` the hand's labeled markers (metres, NaN where unlabeled).
        candidates: ``(slot, start, stop)`` the null trajectory pieces to try.
        layout: the hand's layout (``M`` markers).
        side: the hand's side.
    """
    hand = HandModel(side=side)
    solver = HandSolver(hand, layout.place(hand)[0])
    m = len(layout)
    seen = np.isfinite(observed[..., 0]).sum(axis=1)
    tried = []  # (slot, start, stop, labels, stack (1 + L, k, M, 3): 0 as labeled, then each label taken)
    for slot, start, stop in candidates:
        frames = np.arange(start, stop)
        frames = frames[(seen[frames] >= min(SEEN, m - 1)) & np.isfinite(positions[frames, slot, 0])]
        if len(frames) < 3:
            continue
        frames = frames[np.linspace(0, len(frames) - 1, min(FRAMES, len(frames))).astype(int)]
        base = observed[frames]
        # Labels held in most of these frames: the piece would take them over.
        labels = np.flatnonzero(np.isfinite(base[..., 0]).mean(axis=0) >= 0.5)
        if not len(labels):
            continue
        stack = np.repeat(base[None], len(labels) + 1, axis=0)
        stack[np.arange(1, len(labels) + 1), :, labels] = positions[frames, slot]
        tried.append((slot, start, stop, labels, stack))
    if not tried:
        return []
    # Every piece's hypotheses in one solve: its chunks run side by side.
    flat = np.concatenate([stack.reshape(-1, m, 3) for *_, stack in tried])
    residuals = solver.evaluate(solver.cold_start(flat), flat).residuals
    found = []
    at = 0
    for slot, start, stop, labels, stack in tried:
        own = residuals[at:at + stack.shape[0] * stack.shape[1]].reshape(stack.shape[:3])
        at += stack.shape[0] * stack.shape[1]
        with np.errstate(invalid="ignore"):
            rms = np.median(np.sqrt(np.nanmean(own ** 2, axis=2)), axis=1)
        if not np.isfinite(rms).all():
            continue
        best = int(np.argmin(rms[1:]))
        if rms[1 + best] <= min(MARGIN * rms[0], rms[0] - MIN_GAIN):
            found.append(Holder(int(slot), int(start), int(stop), int(labels[best]), float(rms[1 + best]),
                                float(rms[0])))
    return sorted(found, key=lambda h: (h.fitted / h.before, h.slot, h.start))
