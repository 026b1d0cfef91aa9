"""The labeler protocol: a batch of frames in, log-domain scores over labels plus "null" out.

Every method (neural, GMM, nearest-neighbour) implements :meth:`Labeler.scores`; the shared
:func:`~.assign.assign` step turns scores into labels, so temporal methods and the review tools
never care which labeler made them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from ..layout import Layout
from ..take import Take
from .assign import assign
from .null import NULL as NULL  # re-exported: the protocol's "null" label


@dataclass
class FrameBatch:
    """The observations of many frames, packed to the left and padded to ``K`` per frame.

    Attributes:
        points: float32 ``(F, K, 3)`` metres; 0 where ``mask`` is False.
        mask: bool ``(F, K)``: True for a real observation.
        slots: int32 ``(F, K)``: the take's point slot of each observation, -1 for padding.
    """

    points: np.ndarray
    mask: np.ndarray
    slots: np.ndarray

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def __getitem__(self, index: slice) -> FrameBatch:
        return FrameBatch(self.points[index], self.mask[index], self.slots[index])


def pack_frames(positions: np.ndarray, max_points: int | None = None) -> FrameBatch:
    """Pack a take's ``(F, P, 3)`` positions (NaN = missing) into a :class:`FrameBatch`.

    ``K`` is the largest number of valid points in any frame (at least 1), or ``max_points``
    when given; frames with more valid points than ``max_points`` keep the ones nearest their
    densest point (the hand: its markers crowd together, ghosts and other markers spread out).
    """
    positions = np.asarray(positions, dtype=np.float32)
    valid = np.isfinite(positions).all(axis=2)
    frames, n_points = valid.shape
    counts = valid.sum(axis=1)
    k = max(1, int(counts.max(initial=0)))
    if max_points is not None and k > max_points:
        keep = np.argsort(~valid, axis=1, kind="stable")[:, :max_points]  # valid slots first
        ok = np.take_along_axis(valid, keep, axis=1)
        for f in np.flatnonzero(counts > max_points):
            chosen = _densest(positions[f], valid[f], max_points)
            keep[f] = 0
            keep[f, :len(chosen)] = chosen
            ok[f] = np.arange(max_points) < len(chosen)
        order = np.argsort(np.where(ok, keep, n_points + keep), axis=1, kind="stable")
        keep, valid = np.take_along_axis(keep, order, axis=1), np.take_along_axis(ok, order, axis=1)
        slots = keep
        k = max_points
    else:
        slots = np.broadcast_to(np.arange(n_points), (frames, n_points))
    # Stable sort puts valid samples first and keeps slot order among them.
    order = np.argsort(~valid, axis=1, kind="stable")[:, :k]
    slots = np.take_along_axis(slots, order, axis=1).astype(np.int32)
    mask = np.take_along_axis(valid, order, axis=1)
    points = np.take_along_axis(positions, slots[..., None].astype(np.int64), axis=1)
    points = np.where(mask[..., None], points, 0.0).astype(np.float32)
    slots[~mask] = -1
    return FrameBatch(points, mask, slots)


def _densest(points: np.ndarray, valid: np.ndarray, n: int, radius: float = 0.08, reach: float = 0.3) -> np.ndarray:
    """Indices of at most ``n`` valid points: those nearest the point with the most neighbours
    within ``radius``, none further than ``reach`` from it (a hand spans about 0.2 m)."""
    from scipy.spatial import cKDTree

    idx = np.flatnonzero(valid)
    tree = cKDTree(points[idx])
    crowd = tree.query_ball_point(points[idx], radius, return_length=True)
    centre = points[idx[int(np.argmax(crowd))]]
    dist, near = tree.query(centre, k=min(n, len(idx)))
    return idx[np.atleast_1d(near)[np.atleast_1d(dist) <= reach]]


def frames_from_take(take: Take, max_points: int | None = None) -> FrameBatch:
    """All frames of ``take`` as a :class:`FrameBatch` (see :func:`pack_frames`)."""
    return pack_frames(take.positions, max_points)


class Labeler(ABC):
    """Scores every observation of a frame against the ``M`` labels of a layout and "null".

    Subclasses set :attr:`layout` and implement :meth:`scores`. Frames are given in time order,
    so trackers (``nearest``) may carry state from frame to frame within one call.
    """

    #: The method's name as the CLI and the add-on select it.
    name: str = ""
    layout: Layout
    #: One model for every layout (``set_any``), not one made for this layout.
    layout_conditioned: bool = False

    @abstractmethod
    def scores(self, points: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """Log-domain scores.

        Args:
            points: float32 ``(F, K, 3)`` metres.
            mask: bool ``(F, K)``.

        Returns:
            float32 ``(F, K, M + 1)``: column ``j < M`` scores label ``j``, column ``M`` scores
            "null". Higher is better; rows of padded observations are ignored.
        """

    def label(self, batch: FrameBatch) -> tuple[np.ndarray, np.ndarray]:
        """Per-frame labels and confidences of ``batch`` (see :func:`~.assign.assign`)."""
        return self.label_points(batch.points, batch.mask)

    def label_points(self, points: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Labels int16 ``(F, K)`` (:data:`NULL` for null) and confidences ``(F, K)`` of padded observations."""
        return assign(self.scores(points, mask), mask)


class RememberingLabeler(Labeler):
    """Another labeler whose last scores are kept: a re-solve of the same take (after a user's
    correction) then skips the per-frame network entirely, which is most of the time.

    The last ``keep`` inputs are remembered: a take of two hands scores each hand's points on
    their own, one after the other, and would otherwise never find the scores it asks for.
    """

    def __init__(self, inner: Labeler, keep: int = 2) -> None:
        self.inner, self.layout, self.name = inner, inner.layout, inner.name
        self.layout_conditioned = getattr(inner, "layout_conditioned", False)  # a labeler may be duck-typed
        self.keep = keep
        self._remembered: list[tuple[tuple, np.ndarray]] = []  # (key, scores), the latest last

    def scores(self, points: np.ndarray, mask: np.ndarray) -> np.ndarray:
        key = (points.shape, hash(points.tobytes()), hash(mask.tobytes()))
        for i, (known, scores) in enumerate(self._remembered):
            if known == key:
                self._remembered.append(self._remembered.pop(i))
                return scores.copy()
        scores = self.inner.scores(points, mask)
        self._remembered = (self._remembered + [(key, scores)])[-self.keep:]
        return scores.copy()
