"""The shared assignment step: scores over labels plus "null" -> one label per observation."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from .null import NULL

#: Stands in for "impossible" in cost matrices (finite, so the solver never sees inf - inf).
_FORBIDDEN = 1e9


def row_probabilities(scores: np.ndarray) -> np.ndarray:
    """Softmax over the last axis of log-domain ``scores`` ``(..., M + 1)``."""
    s = scores - scores.max(axis=-1, keepdims=True)
    e = np.exp(s)
    return e / e.sum(axis=-1, keepdims=True)


def row_log_probabilities(scores: np.ndarray) -> np.ndarray:
    """Log-softmax over the last axis of log-domain ``scores`` ``(..., M + 1)``, in float32 (the
    temporal step floors them at -12 nats: float32's 1e-7 relative error is far below anything it
    decides, and half the memory traffic of float64)."""
    s = np.asarray(scores, dtype=np.float32)
    s = s - s.max(axis=-1, keepdims=True)
    s -= np.log(np.exp(s).sum(axis=-1, keepdims=True))
    return s


def assign_frame(scores: np.ndarray) -> np.ndarray:
    """Best one-to-one labeling of one frame's ``(k, M + 1)`` scores (valid rows only).

    Each label takes at most one observation; any number of observations may be null. Solved as a
    rectangular assignment in which observation ``i`` also has its own private null column.

    Returns:
        int ``(k,)``: label per observation, :data:`NULL` for null.
    """
    k, m1 = scores.shape
    m = m1 - 1
    cost = np.full((k, m + k), _FORBIDDEN)
    cost[:, :m] = -scores[:, :m]
    cost[np.arange(k), m + np.arange(k)] = -scores[:, m]
    rows, cols = linear_sum_assignment(cost)
    out = np.full(k, NULL, dtype=np.int64)
    out[rows] = np.where(cols < m, cols, NULL)
    return out


def assign(scores: np.ndarray, mask: np.ndarray,
           log_probabilities: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Turn per-frame scores into labels and confidences.

    Frames whose row-wise best labels already form a one-to-one labeling take them directly
    (most frames of a good labeler); the rest are solved with the Hungarian algorithm.

    Args:
        scores: ``(F, K, M + 1)`` log-domain scores (see :meth:`Labeler.scores`).
        mask: bool ``(F, K)``.
        log_probabilities: ``row_log_probabilities(scores[mask])`` where the caller has them already.

    Returns:
        labels: int16 ``(F, K)``: label index, :data:`NULL` for null and for padding.
        confidence: float32 ``(F, K)`` in [0, 1]: the softmax probability of the given label
        (null included) within the observation's row; 0 for padding.
    """
    scores = np.asarray(scores)
    frames, k, m1 = scores.shape
    m = m1 - 1
    best = np.argmax(scores, axis=2)
    best = np.where(mask, best, m)
    # A frame conflicts when two observations want the same real label.
    wanted = np.bincount((np.arange(frames)[:, None] * m1 + best).ravel(), minlength=frames * m1).reshape(frames, m1)
    conflict = (wanted[:, :m] > 1).any(axis=1)
    labels = np.where(best == m, NULL, best)
    for f in np.flatnonzero(conflict):
        rows = np.flatnonzero(mask[f])
        labels[f, rows] = assign_frame(scores[f, rows].astype(np.float64))
    labels[~mask] = NULL
    confidence = np.zeros((frames, k), dtype=np.float32)
    column = np.where(labels[mask] == NULL, m, labels[mask])
    if log_probabilities is None:
        rows = row_probabilities(scores[mask].astype(np.float64))
        confidence[mask] = rows[np.arange(len(rows)), column]
    else:
        confidence[mask] = np.exp(log_probabilities[np.arange(len(log_probabilities)), column])
    return labels.astype(np.int16), confidence
