"""IK validation of a labeling: the hand fitted to what was labeled judges the labels.

A labeling is plausible when one hand of the performer's shape can produce it. After the first
decision, the hand is calibrated on the confident labels and solved on all of them (robustly: a
sample far off the first fit is left out of the second); then

* every point of every frame is scored by its distance to the fitted hand's markers, and these
  scores join the labeler's for a second vote, so that a point the hand puts on another marker
  can change label, and one far from every marker leans to null;
* a segment whose samples sit, in the median, further than the gate from the fitted marker of
  their label is downgraded: its confidence drops below the reviewer's "sure" line.
"""

from __future__ import annotations

import numpy as np

from .errors import MocapInputError
from .hand.calibrate import Calibration, calibrate
from .hand.ik import GATE, MIN_MARKERS, Fit
from .labeling import Labeling, labeled_take
from .layout import Layout
from .take import Take

#: Confidence a segment keeps at most when its fit residual exceeds the gate.
DOWNGRADED = 0.5


def fit_labeling(take: Take, layout: Layout, labeling: Labeling, calibration: Calibration | None = None,
                 gate: float = GATE, sure: float = 0.95) -> tuple[Calibration, Fit]:
    """Calibrate (unless given) on the confident labels, then solve the hand on all labels, robustly.

    Returns the calibration and the :class:`Fit` of the second, outlier-free solve.
    """
    observed = labeled_take(take, labeling).positions[:, :len(layout)].astype(float)
    if not (np.isfinite(observed[..., 0]).sum(axis=1) >= MIN_MARKERS).any():
        # A take with no hand (a body capture) gets here; say so rather than fail inside the solver.
        raise MocapInputError(take.source, f"IK validation: no frame has {MIN_MARKERS} or more {layout.name} markers "
                                           f"labeled to fit the hand to: no hand found (is this a {layout.name} take?)")
    if calibration is None:
        conf = np.full(observed.shape[:2], -1.0)
        per, pconf = labeling.per_sample(), labeling.per_sample_confidence()
        f, s = np.nonzero(per >= 0)
        conf[f, per[f, s]] = pconf[f, s]
        confident = np.where((conf >= sure)[..., None], observed, np.nan)
        if (np.isfinite(confident[..., 0]).sum(axis=1) >= max(MIN_MARKERS, int(0.7 * len(layout)))).sum() < 8:
            confident = observed  # too few sure frames: use everything
        try:
            calibration = calibrate(confident, layout, frames=15, iterations=24, rounds=2)
        except ValueError as exc:  # labels scattered over a body: no hand's size fits them
            raise MocapInputError(take.source, f"IK validation: the labeled markers make no {layout.name} hand "
                                               f"({exc}): no hand found (is this a {layout.name} take?)") from None
    solver = calibration.solver(layout)
    first = solver.solve(observed, rate=take.rate)
    outliers = np.nan_to_num(first.residuals, nan=0.0) > 2 * gate
    return calibration, solver.solve(np.where(outliers[..., None], np.nan, observed), rate=take.rate)


def fit_scores(points: np.ndarray, mask: np.ndarray, predicted: np.ndarray, gate: float = GATE,
               spread: float = 0.0) -> np.ndarray:
    """Log-likelihood of every observation under the fitted hand, to add to a labeler's scores.

    Args:
        points: ``(F, K, 3)`` observations, metres; mask: ``(F, K)`` which are real.
        predicted: ``(F, M, 3)`` the fitted hand's markers (NaN rows where unsolved).
        gate: the residual at which a label and null are equally likely, metres.
        spread: the fit's own RMS, metres: a hand that fits the take loosely speaks more softly.

    Returns:
        ``(F, K, M + 1)``: ``-d^2 / (2 sigma^2)`` with ``sigma = max(gate / 2, 2 spread)`` for each
        label, the value at ``d = max(gate, 4 spread)`` for null, and 0 where the frame has no fit.
    """
    sigma2 = max(gate / 2, 2 * spread) ** 2
    gate = max(gate, 4 * spread)
    d2 = ((points[:, :, None, :] - predicted[:, None, :, :]) ** 2).sum(axis=-1)
    out = np.empty(points.shape[:2] + (predicted.shape[1] + 1,), dtype=np.float32)
    out[..., :-1] = np.maximum(-d2 / (2 * sigma2), -50.0)
    out[..., -1] = -gate ** 2 / (2 * sigma2)
    out[~np.isfinite(out)] = 0.0  # markers the fit cannot place say nothing
    out[~mask] = 0.0
    return out


def segment_residuals(take: Take, labeling: Labeling, fit: Fit) -> np.ndarray:
    """``(S,)`` median distance of each labeled segment's samples to its label's fitted marker,
    metres (NaN for null segments and where the fit has no frame)."""
    out = np.full(len(labeling.slot), np.nan)
    for i in np.flatnonzero(labeling.label >= 0):
        a, b, slot, lab = labeling.start[i], labeling.stop[i], labeling.slot[i], labeling.label[i]
        d = np.linalg.norm(take.positions[a:b, slot].astype(float) - fit.markers[a:b, lab], axis=-1)
        if np.isfinite(d).any():
            out[i] = np.nanmedian(d)
    return out


def downgrade(labeling: Labeling, residuals: np.ndarray, gate: float = GATE) -> int:
    """Cap the confidence of unlocked segments fitted worse than ``gate``; returns how many."""
    bad = (residuals > gate) & ~labeling.locked
    labeling.confidence[bad] = np.minimum(labeling.confidence[bad], DOWNGRADED)
    return int(bad.sum())
