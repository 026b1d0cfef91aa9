"""Calibrated segment confidence: the chance that a segment's decision is right.

Each segment's evidence (:func:`segment_evidence`) is the mean per-frame probability of its
label, the share of its frames whose own best labeling agrees, the mean log-probability margin
of its label over the next best, and its length. A calibration combines them by a logistic
regression, then maps that score, per segment-length band, to the share of validation
segments that were entirely right (isotonic regression, each block lowered to the lower end of
its 95 % Wilson interval, so that thin evidence never earns a high confidence). On top, the
score from which on validation segments were right at least 99.9 % of the time (one-sided
Wilson bound) maps to at least 0.95 and every lower score to less: "0.95 or more" is a promise
a reviewer can skip on. Calibrations are
built from synthetic validation takes (``python -m training.confidence``) and shipped in
``models/confidence.json``. Without one, the confidence is the mean probability alone.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass

import numpy as np

#: Segment-length bands (frames): short runs are judged apart from long tracklets.
LENGTH_EDGES = (5, 30)
#: A confidence of at least SURE promises that such segments were right at least SURE_ACCURACY of
#: the time on validation data (a lower confidence bound, not the point estimate): reviewers may
#: skip them. Below SURE the confidence is the calibrated chance of being right. The promise made
#: to users is 99.9 %. A margin (99.95 %) moved the real figure by only 0.01 points, and one
#: wrong segment scored near the top then left no segment sure at all.
SURE, SURE_ACCURACY = 0.95, 0.999
#: A marker label held for fewer than this many frames is never "sure", whatever its evidence: every
#: sure-but-wrong label seen on the han2018 raw takes (8 over two model versions, then 3 of the 117 sure
#: labels of 5-10 frames) was a 2-10-frame ghost with perfect per-frame evidence, sitting where a hidden
#: marker would be: short labels fall short of the promise (:data:`SURE_ACCURACY`). Such labels are few
#: and quick to check. Null decisions of short ghosts keep their calibration, and the sure threshold is
#: fitted on the segments that may be sure.
SHORT_LABEL = 11


#: The most frames at a labeled segment's start or end cut off into a segment of their own where the
#: per-frame labeling gives them another label (:func:`split_doubtful_edges`).
DISPUTED_END = 3


def _split_at(labeling, head: np.ndarray, tail: np.ndarray):
    """``labeling`` with the first ``head`` and last ``tail`` frames ``(S,)`` of each segment cut off into
    segments of their own (same label, lock and confidence; no evidence; ``held``: the whole segment's
    frames)."""
    from ..labeling import Labeling

    n = len(labeling)
    pieces = 1 + (head > 0) + (tail > 0)
    idx = np.repeat(np.arange(n), pieces)
    part = np.arange(len(idx)) - np.repeat(np.cumsum(pieces) - pieces, pieces)  # 0, 1, 2 within a segment
    kind = np.where(np.repeat(head > 0, pieces), part, part + 1)  # 0 head, 1 middle, 2 tail
    a, b, h, t = labeling.start[idx], labeling.stop[idx], head[idx], tail[idx]
    start = np.where(kind == 0, a, np.where(kind == 1, a + h, b - t))
    stop = np.where(kind == 0, a + h, np.where(kind == 1, b - t, b))
    missing = None if labeling.missing_mm is None else labeling.missing_mm[idx]
    held = labeling.length if labeling.held is None else labeling.held
    return Labeling(names=labeling.names, n_frames=labeling.n_frames, n_points=labeling.n_points,
                    slot=labeling.slot[idx], start=start, stop=stop, label=labeling.label[idx],
                    confidence=labeling.confidence[idx], locked=labeling.locked[idx], info=labeling.info,
                    evidence=None, missing_mm=missing, held=held[idx])


def split_doubtful_edges(labeling, samples, stride: int, max_frames: int = DISPUTED_END):
    """``labeling`` with the frames at the edges of its labeled segments that the rest of the segment
    cannot vouch for cut off into short segments of their own (same labels; each then gets its own
    evidence, and a short label is never sure: :data:`SHORT_LABEL`):

    - up to ``max_frames`` at a segment's start or end whose per-frame labels differ from the
      segment's: a trajectory that starts on another marker, or takes one over for its last frames;
    - where the vote changed a trajectory's label from one marker's to another's (a swap), the
      ``stride - 1`` frames on each side of the cut: the labeler scored every ``stride``-th frame,
      so the swap may lie anywhere among them.

    The labels do not change. Returns ``labeling`` itself where nothing is cut.

    Args:
        samples: the scored samples (:class:`.voting.Samples`: ``frame``, ``slot``, ``label``).
        stride: frames between scored ones (:func:`.stride.stride_for`).
    """
    n = len(labeling)
    if not n or not len(samples.frame):
        return labeling
    own = np.full((labeling.n_frames, labeling.n_points), -3, dtype=np.int32)  # -3: no sample
    own[samples.frame, samples.slot] = samples.label
    length = labeling.stop - labeling.start
    label = labeling.label.astype(np.int32)
    candidate = (label >= 0) & ~labeling.locked & (length > 1)
    head = np.zeros(n, dtype=np.int64)
    tail = np.zeros(n, dtype=np.int64)
    for k in range(max_frames):
        inside = candidate & (k < length - 1)
        at_head = own[np.minimum(labeling.start + k, labeling.n_frames - 1), labeling.slot]
        at_tail = own[np.maximum(labeling.stop - 1 - k, 0), labeling.slot]
        head += inside & (head == k) & (at_head != -3) & (at_head != label)
        tail += inside & (tail == k) & (at_tail != -3) & (at_tail != label)
    if stride > 1:
        # Swap cuts: a labeled segment followed on the same trajectory by another label, no frame between
        # (segments are ordered by slot, then start).
        s, a, b = labeling.slot, labeling.start, labeling.stop
        cut = (s[1:] == s[:-1]) & (a[1:] == b[:-1]) & (label[1:] != label[:-1]) & (label[1:] >= 0) & (label[:-1] >= 0)
        before, after = np.flatnonzero(cut), np.flatnonzero(cut) + 1
        tail[before] = np.maximum(tail[before], stride - 1) * candidate[before]
        head[after] = np.maximum(head[after], stride - 1) * candidate[after]
    # A cut must leave frames in the middle: a segment doubtful from end to end is judged whole.
    whole = head + tail >= length
    head[whole] = 0
    tail[whole] = 0
    if not (head.any() or tail.any()):
        return labeling
    return _split_at(labeling, head, tail)


EVIDENCE = ("mean probability", "agreement", "margin", "length")


def segment_evidence(labeling, samples) -> np.ndarray:
    """float32 ``(S, 4)``: per segment, the mean probability of its label over its scored samples,
    the share of them whose per-frame labeling agrees, the mean log-probability margin of its
    label over the best other column (clipped to +-10), and its length in frames. Segments with
    no scored sample get zeros (and their length)."""
    n = len(labeling)
    seg = labeling.segment_ids()[samples.frame, samples.slot]
    ok = seg >= 0
    seg, rows = seg[ok], np.flatnonzero(ok)
    m = samples.logp.shape[1] - 1
    label = labeling.label[seg].astype(np.int64)
    col = np.where(label < 0, m, label)
    lp = samples.logp if len(rows) == len(samples.frame) else samples.logp[rows]  # no copy when all are in
    at = (np.arange(len(rows)), col)
    chosen = lp[at].astype(np.float64)
    # The best other column: the row's best with its label's column left out.
    others = np.array(lp)  # a copy: one pass, where a partition for the second best took five
    others[at] = -np.inf
    best_other = others.max(axis=1).astype(np.float64)
    margin = np.clip(chosen - best_other, -10.0, 10.0)
    agree = samples.label[rows] == label
    count = np.maximum(np.bincount(seg, minlength=n), 1)
    out = np.zeros((n, 4), dtype=np.float32)
    out[:, 0] = np.bincount(seg, weights=np.exp(chosen), minlength=n) / count
    out[:, 1] = np.bincount(seg, weights=agree, minlength=n) / count
    out[:, 2] = np.bincount(seg, weights=margin, minlength=n) / count
    out[:, 3] = labeling.length
    return out


def _features(evidence: np.ndarray) -> np.ndarray:
    e = np.asarray(evidence, dtype=np.float64)
    return np.column_stack([e[:, 0], e[:, 1], e[:, 2] / 10.0, np.log1p(e[:, 3]) / 5.0, np.ones(len(e))])


def _score(evidence: np.ndarray, weights) -> np.ndarray:
    """The logistic score of each segment's evidence, in (0, 1)."""
    return 1.0 / (1.0 + np.exp(-_features(evidence) @ np.asarray(weights)))


def _short_labels(evidence: np.ndarray, labeled: np.ndarray | None) -> np.ndarray:
    """bool ``(S,)``: segments given a marker's label for fewer than :data:`SHORT_LABEL` frames
    (never "sure"); none when ``labeled`` is not known."""
    if labeled is None:
        return np.zeros(len(evidence), dtype=bool)
    return np.asarray(labeled, dtype=bool) & (np.asarray(evidence)[:, 3] < SHORT_LABEL)


@dataclass
class Calibration:
    """Logistic weights over the evidence, then per length band a monotone map from that score
    to confidence (knots ``x`` -> ``y``)."""

    weights: list[float]
    x: list[list[float]]
    y: list[list[float]]
    sure: list[float]  # per band, the score from which confidence is at least SURE (2.0: never)
    segments: int = 0
    source: str = ""

    def __call__(self, evidence: np.ndarray, labeled: np.ndarray | None = None) -> np.ndarray:
        """Confidence ``(S,)`` of segments with ``evidence`` ``(S, 4)``; ``labeled`` ``(S,)`` bool
        marks those given a marker's label (not null): such a segment shorter than
        :data:`SHORT_LABEL` frames is never "sure"."""
        raw = _score(evidence, self.weights)
        band = np.searchsorted(LENGTH_EDGES, evidence[:, 3], side="right")
        short_label = _short_labels(evidence, labeled)
        out = np.empty(len(raw), dtype=np.float32)
        for b in range(len(LENGTH_EDGES) + 1):
            sel = band == b
            if sel.any():
                y = np.interp(raw[sel], self.x[b], self.y[b])
                sure = (raw[sel] >= self.sure[b]) & ~short_label[sel]
                out[sel] = np.where(sure, np.maximum(y, SURE), np.minimum(y, SURE - 1e-3))
        return out

    @property
    def never_sure(self) -> bool:
        """True when no segment can reach :data:`SURE`: on the validation takes no score band of
        this method's segments was right :data:`SURE_ACCURACY` of the time (``perm`` and ``cnn``:
        every segment is left for review, and that is the honest answer)."""
        return all(s > 1.0 for s in self.sure)

    def as_dict(self) -> dict:
        return {"length_edges": list(LENGTH_EDGES), "evidence": list(EVIDENCE), "weights": self.weights,
                "x": self.x, "y": self.y, "sure": self.sure, "sure_accuracy": SURE_ACCURACY,
                "segments": self.segments, "source": self.source}


def _wilson_lower(correct: np.ndarray, n: np.ndarray, z: float = 1.96) -> np.ndarray:
    p = correct / np.maximum(n, 1)
    centre = p + z * z / (2 * n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return (centre - half) / (1 + z * z / n)


def _fit_logistic(x: np.ndarray, y: np.ndarray, l2: float = 1e-3) -> np.ndarray:
    from scipy.optimize import minimize

    def loss(w):
        z = x @ w
        p = 1.0 / (1.0 + np.exp(-z))
        nll = np.mean(np.logaddexp(0.0, z) - y * z) + l2 * (w[:-1] @ w[:-1])
        grad = x.T @ (p - y) / len(y) + 2 * l2 * np.concatenate([w[:-1], [0.0]])
        return nll, grad

    # Every evidence column is "more is better" (a longer segment with the same per-frame evidence
    # is no less likely right): non-negative weights keep the score monotone in each. Unbounded,
    # the length weight fitted slightly negative once the vote's null prior had removed most
    # short wrong segments, and 2,400-frame real tracklets with 99.6 % mean probability fell
    # just short of "sure".
    bounds = [(0.0, None)] * (x.shape[1] - 1) + [(None, None)]
    return minimize(loss, np.zeros(x.shape[1]), jac=True, method="L-BFGS-B", bounds=bounds).x


def fit_calibration(evidence: np.ndarray, correct: np.ndarray, labeled: np.ndarray | None = None,
                    source: str = "") -> Calibration:
    """Fit the maps from validation segments: their evidence ``(n, 4)`` (see :func:`segment_evidence`),
    whether each segment was entirely right ``(n,)`` and, optionally, whether it was given a
    marker's label ``(n,)``: short marker labels are never sure (:data:`SHORT_LABEL`), so the sure
    threshold is set on the other segments alone."""
    from scipy.optimize import isotonic_regression

    correct = np.asarray(correct, dtype=bool)
    eligible = ~_short_labels(evidence, labeled)
    # Rounded as stored: the sure threshold below must hold for the weights that are shipped.
    weights = [round(float(w), 6) for w in _fit_logistic(_features(evidence), correct.astype(float))]
    raw = _score(evidence, weights)
    length = evidence[:, 3]
    band = np.searchsorted(LENGTH_EDGES, length, side="right")
    xs, ys, sure = [], [], []
    for b in range(len(LENGTH_EDGES) + 1):
        sel = band == b
        if sel.sum() < 10:  # too little evidence: no confidence at all in this band
            xs.append([0.0, 1.0])
            ys.append([0.0, 0.0])
            sure.append(2.0)
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
        sure.append(0.0)
    # The lowest score from which segments were right often enough (one-sided bound), over all
    # bands together: the score includes length, and the promise is about all segments.
    order = np.argsort(-raw[eligible], kind="stable")
    right = np.cumsum(correct[eligible][order])
    ranked = raw[eligible][order]
    # Only at the last of equal scores: every segment scored at the threshold is sure, so all of
    # them must be in the count (saturated scores come in large ties).
    group_end = np.append(ranked[1:] < ranked[:-1], True)
    ok = np.flatnonzero(group_end & (_wilson_lower(right, np.arange(1, len(ranked) + 1), z=1.0) >= SURE_ACCURACY))
    tau = float(ranked[ok[-1]]) if len(ok) else 2.0
    sure = [2.0 if s == 2.0 else tau for s in sure]
    return Calibration(weights, xs, ys, sure, int(len(raw)), source)


CALIBRATIONS = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                            "models", "confidence.json")


def calibration_key(method: str, temporal: str, layout: str) -> str:
    return f"{method}/{temporal}/{layout}"


def _entry(method: str, temporal: str, layout: str, path: str) -> dict | None:
    """The calibration file's entry for a method, temporal mode and layout, or None."""
    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh).get(calibration_key(method, temporal, layout))
    except (OSError, ValueError):
        return None


def load_calibration(method: str, temporal: str, layout: str, path: str = CALIBRATIONS) -> Calibration | None:
    """The shipped calibration for a method, temporal mode and layout, or None."""
    entry = _entry(method, temporal, layout, path)
    if entry is None or tuple(entry.get("length_edges", ())) != LENGTH_EDGES or "sure" not in entry:
        return None
    return Calibration(entry["weights"], entry["x"], entry["y"], entry["sure"], entry.get("segments", 0),
                       entry.get("source", ""))


def _fitted_pair(method: str, temporal: str, layout: str, path: str, key: str) -> tuple[float, float]:
    pair = (_entry(method, temporal, layout, path) or {}).get(key, (0.0, 0.0))
    return float(pair[0]), float(pair[1])


def load_null_prior(method: str, temporal: str, layout: str, path: str = CALIBRATIONS) -> tuple[float, float]:
    """The shipped null prior ``(per segment, per sample)`` of a method, temporal mode and layout
    (see :func:`.voting.vote`); no prior where none was fitted."""
    return _fitted_pair(method, temporal, layout, path, "null_prior")


def load_switch_cost(method: str, temporal: str, layout: str, path: str = CALIBRATIONS) -> tuple[float, float]:
    """The shipped switch cost ``(at a crossing, at any other cut)`` of a method, temporal mode and
    layout (see :func:`.voting.vote`); free switches where none was fitted."""
    return _fitted_pair(method, temporal, layout, path, "switch_cost")


def load_partner(method: str, temporal: str, layout: str, path: str = CALIBRATIONS) -> tuple[float, float]:
    """The shipped rigid-partner evidence ``(inside, outside)`` nats per sample of a method,
    temporal mode and layout (see :mod:`.partners`); none where none was fitted."""
    return _fitted_pair(method, temporal, layout, path, "partner")


def load_occlusion_prior(method: str, temporal: str, layout: str, path: str = CALIBRATIONS) -> tuple[float, float]:
    """The shipped occlusion prior ``(knee in breaks a second, nats per sample per break a second
    above it)`` of a method, temporal mode and layout (see :func:`..stages.decide.null_prior`);
    none where none was fitted."""
    return _fitted_pair(method, temporal, layout, path, "occlusion_prior")


def load_continuity(method: str, temporal: str, layout: str, path: str = CALIBRATIONS) -> tuple[float, float]:
    """The shipped continuity evidence ``(inside, outside)`` nats per sample of a method, temporal
    mode and layout (see :mod:`.continuity`); none where none was fitted."""
    return _fitted_pair(method, temporal, layout, path, "continuity")
