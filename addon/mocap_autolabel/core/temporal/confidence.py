"""Calibrated segment confidence: the chance that a segment's decision is right.

The raw score of a segment is the mean per-frame probability of its chosen label. A calibration
maps it, per segment-length band, to the share of validation segments that were entirely right
(isotonic regression, then each block lowered to the lower end of its 95 % Wilson interval, so
that thin evidence never earns a high confidence). Calibrations are built from synthetic
validation takes (``python -m training.confidence``) and shipped in ``models/confidence.json``.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass

import numpy as np

#: Segment-length bands (frames): short runs are judged apart from long tracklets.
LENGTH_EDGES = (5, 30)


@dataclass
class Calibration:
    """Per length band, a monotone map from raw score to confidence (knots ``x`` -> ``y``)."""

    x: list[list[float]]
    y: list[list[float]]
    segments: int = 0
    source: str = ""

    def __call__(self, raw: np.ndarray, length: np.ndarray) -> np.ndarray:
        band = np.searchsorted(LENGTH_EDGES, length, side="right")
        out = np.empty(len(raw), dtype=np.float32)
        for b in range(len(LENGTH_EDGES) + 1):
            sel = band == b
            if sel.any():
                out[sel] = np.interp(raw[sel], self.x[b], self.y[b])
        return out

    def as_dict(self) -> dict:
        return {"length_edges": list(LENGTH_EDGES), "x": self.x, "y": self.y, "segments": self.segments,
                "source": self.source}


def _wilson_lower(correct: np.ndarray, n: np.ndarray, z: float = 1.96) -> np.ndarray:
    p = correct / np.maximum(n, 1)
    centre = p + z * z / (2 * n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return (centre - half) / (1 + z * z / n)


def fit_calibration(raw: np.ndarray, length: np.ndarray, correct: np.ndarray, source: str = "") -> Calibration:
    """Fit the maps from validation segments: raw scores ``(n,)``, lengths ``(n,)`` and whether each
    segment was entirely right ``(n,)``."""
    from scipy.optimize import isotonic_regression

    band = np.searchsorted(LENGTH_EDGES, length, side="right")
    xs, ys = [], []
    for b in range(len(LENGTH_EDGES) + 1):
        sel = band == b
        if sel.sum() < 10:  # too little evidence: no confidence at all in this band
            xs.append([0.0, 1.0])
            ys.append([0.0, 0.0])
            continue
        order = np.argsort(raw[sel], kind="stable")
        r, c = raw[sel][order], correct[sel][order].astype(float)
        fit = isotonic_regression(c).x
        # Blocks of equal fitted value: lower each to its Wilson bound, keep the map monotone.
        edges = np.flatnonzero(np.diff(fit) != 0) + 1
        starts, stops = np.concatenate([[0], edges]), np.concatenate([edges, [len(fit)]])
        n = (stops - starts).astype(float)
        lower = np.maximum.accumulate(_wilson_lower(fit[starts] * n, n))
        x = np.concatenate([[r[s], r[e - 1]] for s, e in zip(starts, stops)])
        y = np.repeat(lower, 2)
        x = np.concatenate([[0.0], x, [1.0]])
        y = np.concatenate([[0.0], y, [y[-1]]])
        x = np.maximum.accumulate(x)
        xs.append([round(float(v), 6) for v in x])
        ys.append([round(float(v), 6) for v in y])
    return Calibration(xs, ys, int(len(raw)), source)


CALIBRATIONS = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                            "models", "confidence.json")


def calibration_key(method: str, temporal: str, layout: str) -> str:
    return f"{method}/{temporal}/{layout}"


def load_calibration(method: str, temporal: str, layout: str, path: str = CALIBRATIONS) -> Calibration | None:
    """The shipped calibration for a method, temporal mode and layout, or None."""
    try:
        with open(path, encoding="utf-8") as fh:
            table = json.load(fh)
    except (OSError, ValueError):
        return None
    entry = table.get(calibration_key(method, temporal, layout))
    if entry is None or tuple(entry.get("length_edges", ())) != LENGTH_EDGES:
        return None
    return Calibration(entry["x"], entry["y"], entry.get("segments", 0), entry.get("source", ""))
