"""``nearest`` (Feit et al. 2016): nearest-neighbour tracking from labeled frames, with gates.

A tracker, not a per-frame labeler: it needs the labels of one frame (the first, or user
"fallback" frames it restarts from) and carries them forward. A point takes the label of the
nearest predicted marker only if no other point is nearer to that marker, the distance is
within a gate (wider when the marker was missing in the previous frame), and the point lies
within a margin of the previous frame's bounding box. A missing marker is predicted from its
parent and child on the same digit (the average of the two predictions), else it stays put.
"""

from __future__ import annotations

import numpy as np

from ..layout import Layout
from .base import Labeler

_DIGITS = ("thumb", "index", "middle", "ring", "little")


def digit_chains(layout: Layout) -> tuple[np.ndarray, np.ndarray]:
    """Parent and child marker of every marker (-1 if none): neighbours along the same digit.

    Markers on a digit's bones are ordered proximal to distal by bone order and position along
    the bone. Palm markers have neither.
    """
    from ..hand.skeleton import BONE_INDEX

    m = len(layout)
    parent, child = np.full(m, -1), np.full(m, -1)
    for digit in _DIGITS:
        on = [i for i, mk in enumerate(layout.markers) if mk.bone.startswith(digit)]
        on.sort(key=lambda i: (BONE_INDEX[layout.markers[i].bone], layout.markers[i].along))
        for a, b in zip(on, on[1:]):
            child[a], parent[b] = b, a
    return parent, child


class NearestLabeler(Labeler):
    """Feit's tracker behind the labeler protocol.

    Args:
        layout: the marker layout.
        start: ``(M, 3)`` labeled positions (NaN if a marker is missing) of the first frame given
            to :meth:`scores`.
        fallback: optional ``{frame index: (M, 3)}`` fully labeled frames; at these frames the
            tracker restarts from the given labels (the user's corrections).
        gate: metres a marker may move between frames and keep its label.
        gate_missing: the gate for a marker missing in the previous frame.
        box_margin: metres around the previous frame's labeled bounding box where points may lie.
    """

    name = "nearest"

    def __init__(self, layout: Layout, start: np.ndarray | None = None, fallback: dict[int, np.ndarray] | None = None,
                 gate: float = 0.02, gate_missing: float = 0.035, box_margin: float = 0.03):
        self.layout = layout
        self.start = None if start is None else np.asarray(start, dtype=np.float64)
        self.fallback = dict(fallback or {})
        self.gate, self.gate_missing, self.box_margin = gate, gate_missing, box_margin
        self.parent, self.child = digit_chains(layout)

    def _predict(self, last: np.ndarray, seen: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """Where every marker should be now: its last position, or extrapolated from parent and child."""
        pred = last.copy()
        for j in np.flatnonzero(~seen):
            guesses = [last[r] + offsets[j, n] for n, r in enumerate((self.parent[j], self.child[j]))
                       if r >= 0 and seen[r] and np.isfinite(offsets[j, n]).all()]
            if guesses:
                pred[j] = np.mean(guesses, axis=0)
        return pred

    def scores(self, points: np.ndarray, mask: np.ndarray) -> np.ndarray:
        frames, k, _ = points.shape
        m = len(self.layout)
        out = np.full((frames, k, m + 1), -10.0, dtype=np.float32)
        out[:, :, m] = 0.0
        if self.start is None and 0 not in self.fallback:
            raise ValueError("nearest needs the labels of the first frame (start=...) or a fallback frame 0")
        last = np.full((m, 3), np.nan)
        seen = np.zeros(m, dtype=bool)
        offsets = np.full((m, 2, 3), np.nan)  # marker minus parent / child, when last seen together
        for f in range(frames):
            known = self.fallback.get(f, self.start if f == 0 else None)
            p = points[f][mask[f]].astype(np.float64)
            rows = np.flatnonzero(mask[f])
            if known is not None:
                # A labeled frame: take each label's nearest point (within a millimetre).
                d = np.linalg.norm(p[:, None] - known[None], axis=2)
                d = np.where(np.isfinite(d), d, np.inf)
                lab = np.full(len(p), -1)
                if len(p):
                    j = np.argmin(d, axis=1)
                    ok = d[np.arange(len(p)), j] < 1e-3
                    lab[ok] = j[ok]
            else:
                lab = self._track(p, last, seen, offsets)
            labeled = lab >= 0
            out[f, rows[labeled], lab[labeled]] = 10.0
            out[f, rows[labeled], m] = -10.0
            now = np.full((m, 3), np.nan)
            now[lab[labeled]] = p[labeled]
            seen_now = np.isfinite(now).all(axis=1)
            for n, rel in enumerate((self.parent, self.child)):
                ok = seen_now & (rel >= 0)
                ok[ok] &= seen_now[rel[ok]]
                offsets[ok, n] = now[ok] - now[rel[ok]]
            last = np.where(seen_now[:, None], now, self._predict(last, seen, offsets))
            seen = seen_now
        return out

    def _track(self, p: np.ndarray, last: np.ndarray, seen: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        lab = np.full(len(p), -1)
        pred = self._predict(last, seen, offsets)
        known = np.isfinite(pred).all(axis=1)
        if not len(p) or not known.any():
            return lab
        d = np.linalg.norm(p[:, None] - pred[None], axis=2)
        d[:, ~known] = np.inf
        near_label = np.argmin(d, axis=1)  # nearest marker of each point
        near_point = np.argmin(d, axis=0)  # nearest point of each marker
        i = np.arange(len(p))
        dist = d[i, near_label]
        gate = np.where(seen[near_label], self.gate, self.gate_missing)
        box = last[seen] if seen.any() else pred[known]
        lo, hi = box.min(axis=0) - self.box_margin, box.max(axis=0) + self.box_margin
        inside = ((p >= lo) & (p <= hi)).all(axis=1)
        ok = (near_point[near_label] == i) & (dist <= gate) & inside
        lab[ok] = near_label[ok]
        return lab
