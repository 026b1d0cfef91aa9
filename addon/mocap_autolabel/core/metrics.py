"""Labeling accuracy with the names METHODS.md defines (per instance = frame x label)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .tracklets import mask_runs


@dataclass
class LabelingScore:
    """Counts and rates of one labeling against ground truth.

    Instances are (frame, label) pairs. ``correct`` includes labels correctly left empty.
    Ghost precision/recall judge the null decision per observation; occlusion precision/recall
    judge "label left empty" per instance.
    """

    instances: int
    correct: int
    erroneous: int
    false_marker: int
    false_occlusion: int
    frames: int
    frames_all_correct: int
    ghosts: int
    ghost_precision: float
    ghost_recall: float
    occlusions: int
    occlusion_precision: float
    occlusion_recall: float

    @property
    def accuracy(self) -> float:
        """Share of instances that are correct."""
        return self.correct / max(self.instances, 1)

    @property
    def frame_accuracy(self) -> float:
        """Share of frames in which every label is correct."""
        return self.frames_all_correct / max(self.frames, 1)

    def as_dict(self) -> dict:
        return {**asdict(self), "accuracy": self.accuracy, "frame_accuracy": self.frame_accuracy}


def per_label(labels: np.ndarray, mask: np.ndarray, n_labels: int) -> np.ndarray:
    """Invert per-observation labels ``(F, K)`` into the observation of each label ``(F, M)``, -1 if none.

    Labels outside ``[0, M)`` (null, ghost, padding) are ignored. If two observations carry
    the same label (ground truth after a merge), the later one wins.
    """
    frames, k = labels.shape
    out = np.full((frames, n_labels + 1), -1, dtype=np.int64)
    lab = np.where(mask & (labels >= 0) & (labels < n_labels), labels, n_labels).astype(np.int64)
    f = np.repeat(np.arange(frames), k)
    out[f, lab.ravel()] = np.tile(np.arange(k), frames)
    return out[:, :n_labels]


def score_labeling(predicted: np.ndarray, truth: np.ndarray, mask: np.ndarray, n_labels: int) -> LabelingScore:
    """Compare labels per observation.

    Args:
        predicted: int ``(F, K)`` label per observation, negative = null.
        truth: int ``(F, K)`` the true label, negative = ghost / not a marker of the layout.
        mask: bool ``(F, K)`` real observations.
        n_labels: ``M``.
    """
    p = per_label(predicted, mask, n_labels)
    t = per_label(truth, mask, n_labels)
    correct = p == t
    erroneous = (p >= 0) & (t >= 0) & (p != t)
    false_marker = (p >= 0) & (t < 0)
    false_occlusion = (p < 0) & (t >= 0)
    pred_null = mask & (predicted < 0)
    true_ghost = mask & (truth < 0)
    occl_pred, occl_true = p < 0, t < 0
    return LabelingScore(
        instances=int(p.size), correct=int(correct.sum()), erroneous=int(erroneous.sum()),
        false_marker=int(false_marker.sum()), false_occlusion=int(false_occlusion.sum()),
        frames=int(p.shape[0]), frames_all_correct=int(correct.all(axis=1).sum()),
        ghosts=int(true_ghost.sum()),
        ghost_precision=_ratio((pred_null & true_ghost).sum(), pred_null.sum()),
        ghost_recall=_ratio((pred_null & true_ghost).sum(), true_ghost.sum()),
        occlusions=int(occl_true.sum()),
        occlusion_precision=_ratio((occl_pred & occl_true).sum(), occl_pred.sum()),
        occlusion_recall=_ratio((occl_pred & occl_true).sum(), occl_true.sum()),
    )


def _ratio(num: int, den: int) -> float:
    return float(num) / float(den) if den else float("nan")


def data_set_stats(present: np.ndarray) -> dict:
    """What METHODS.md asks to report beside the figures, from a bool ``(F, M)`` "marker observed" array."""
    runs = mask_runs(present)
    gaps = mask_runs(~present)
    # A gap is missing time between two observed runs of the same label, not a never-seen label.
    inner = [(c, a, b) for c, a, b in zip(*gaps) if a > 0 and b < present.shape[0]]
    gap_len = np.array([b - a for _, a, b in inner]) if inner else np.zeros(0)
    return {"frames": int(present.shape[0]), "instances": int(present.size), "gaps": int(len(inner)),
            "mean_gap_frames": float(gap_len.mean()) if len(gap_len) else 0.0,
            "tracklets": int(len(runs[0])),
            "mean_tracklet_frames": float(np.mean(runs[2] - runs[1])) if len(runs[0]) else 0.0}


def segments_right(labeling, truth: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """bool ``(S,)``: whether every sample of each segment of a Labeling carries its true label.

    ``truth`` int ``(F, P)`` per sample: the label index, or a negative value for a ghost (which
    a null decision gets right); ``valid`` bool ``(F, P)``.
    """
    t = np.where(truth < 0, -1, truth)
    ids = labeling.segment_ids()
    wrong = np.bincount(ids[valid], weights=labeling.per_sample()[valid] != t[valid], minlength=len(labeling))
    return wrong == 0


def clustered_se(hits: np.ndarray, counts: np.ndarray) -> float:
    """Standard error (percentage points) of a pooled share ``sum(hits) / sum(counts)`` with the
    takes as the units: errors cluster within a take (one missed swap spoils a hundred frames),
    so counting frames or instances as independent would understate it. Ratio estimator over
    ``(T,)`` per-take ``hits`` and ``counts``; NaN with fewer than two takes."""
    hits, counts = np.asarray(hits, dtype=float), np.asarray(counts, dtype=float)
    n, total = len(hits), counts.sum()
    if n < 2 or total <= 0:
        return float("nan")
    residual = hits - hits.sum() / total * counts
    return float(100.0 * np.sqrt(n / (n - 1) * np.sum(residual ** 2)) / total)
