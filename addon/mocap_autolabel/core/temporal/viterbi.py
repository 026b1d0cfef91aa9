"""N-best hypotheses per frame + Kalman filters + Viterbi (Alexanderson et al., MIG 2016).

Each frame keeps the N best labelings of its scores (Murty). Every hypothesis carries one
constant-acceleration Kalman filter per marker, inherited from its best predecessor. The
transition score from hypothesis n at t-1 to m at t is the sum over markers of the
log-likelihood of m's observations under n's predicted positions (innovation covariance).
Viterbi picks the best path. A missing marker is extrapolated by prediction for at most
``max_predict`` frames; after that its filter restarts, and its first ``warmup`` frames carry
no temporal score. Works on the scores of any labeler.
"""

from __future__ import annotations

import numpy as np

from ..labelers.null import NULL
from .murty import nbest_labelings


def _motion(dt: float, jerk: float) -> tuple[np.ndarray, np.ndarray]:
    """Transition ``A`` and process noise ``Q`` (3 x 3, per axis) of a constant-acceleration model
    driven by white jerk of spectral density ``jerk`` (m^2/s^5)."""
    a = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    q = jerk * np.array([[dt ** 5 / 20, dt ** 4 / 8, dt ** 3 / 6],
                         [dt ** 4 / 8, dt ** 3 / 3, dt ** 2 / 2],
                         [dt ** 3 / 6, dt ** 2 / 2, dt]])
    return a, q


def viterbi_labels(scores: np.ndarray, mask: np.ndarray, points: np.ndarray, rate: float, n_best: int = 5,
                   max_predict: int = 10, warmup: int = 2, jerk: float = 1e6, noise: float = 0.002,
                   start_sd: tuple[float, float] = (0.5, 20.0)) -> np.ndarray:
    """Labels ``(F, K)`` (int16, :data:`NULL` for null and padding) on the best Viterbi path.

    Args:
        scores: ``(F, K, M + 1)`` log-domain per-frame scores of any labeler.
        mask: bool ``(F, K)``.
        points: ``(F, K, 3)`` observations, metres.
        rate: frames per second.
        n_best: hypotheses per frame (Murty).
        max_predict: frames a missing marker is extrapolated before its filter restarts.
        warmup: frames after a (re)start without temporal score.
        jerk: process noise, white-jerk spectral density in m^2/s^5.
        noise: measurement noise SD, metres.
        start_sd: initial SD of velocity (m/s) and acceleration (m/s^2) of a new filter.
    """
    frames, k, m1 = scores.shape
    m = m1 - 1
    a, q = _motion(1.0 / rate, jerk)
    r = noise * noise
    p0 = np.diag([r, start_sd[0] ** 2, start_sd[1] ** 2])

    # Per hypothesis: state x (M, 3 derivatives, 3 axes), covariance P (M, 3, 3) shared by the
    # axes, age (frames since (re)start, -1 = no filter) and frames since last seen.
    hyp_labels: list[np.ndarray] = []  # per frame: (n, K) labels
    back: list[np.ndarray] = []  # per frame: (n,) best predecessor
    x = np.zeros((1, m, 3, 3))
    cov = np.broadcast_to(p0, (1, m, 3, 3)).copy()
    age = np.full((1, m), -1)
    unseen = np.zeros((1, m), dtype=np.int64)
    value = np.zeros(1)
    for f in range(frames):
        rows = np.flatnonzero(mask[f])
        if len(rows):
            hyps = nbest_labelings(scores[f, rows], n_best)
        else:
            hyps = [(0.0, np.zeros(0, dtype=np.int64))]
        n = len(hyps)
        frame_score = np.array([h[0] for h in hyps])
        labels = np.full((n, k), NULL, dtype=np.int64)
        obs = np.full((n, m, 3), np.nan)
        for i, (_, lab) in enumerate(hyps):
            labels[i, rows] = lab
            named = lab >= 0
            obs[i, lab[named]] = points[f, rows[named]]
        seen = ~np.isnan(obs[..., 0])  # (n, M)

        # Predict every previous hypothesis' filters.
        xp = np.einsum("ij,hmjc->hmic", a, x)
        pp = a @ cov @ a.T + q  # (h, M, 3, 3)
        s = pp[..., 0, 0] + r  # (h, M) innovation variance per axis
        live = (age >= warmup) & (unseen <= max_predict)  # filters whose prediction is scored
        # Transition scores (h, n): innovations of each current hypothesis under each previous one.
        innov = obs[None, :, :, :] - xp[:, None, :, 0, :]  # (h, n, M, 3)
        ll = -0.5 * ((innov ** 2).sum(-1) / s[:, None] + 3.0 * np.log(2 * np.pi * s[:, None]))
        ll = np.where(seen[None] & live[:, None], ll, 0.0)
        total = value[:, None] + ll.sum(axis=2)  # (h, n)
        best = np.argmax(total, axis=0)
        value = total[best, np.arange(n)] + frame_score
        value -= value.max()  # keep numbers small; Viterbi needs only differences
        back.append(best)
        hyp_labels.append(labels)

        # Update: each current hypothesis inherits its predecessor's filters.
        xn, pn = xp[best].copy(), pp[best].copy()
        agen, unseenn = age[best].copy(), unseen[best].copy()
        gain = pn[..., :, 0] / (pn[..., 0, 0] + r)[..., None]  # (n, M, 3)
        fresh = seen & ((agen < 0) | (unseenn > max_predict))
        upd = seen & ~fresh
        resid = obs - xn[..., 0, :]  # (n, M, 3)
        xu = xn + gain[..., :, None] * resid[..., None, :]
        pu = pn - gain[..., :, None] * pn[..., 0, None, :]
        xn = np.where(upd[..., None, None], xu, xn)
        pn = np.where(upd[..., None, None], pu, pn)
        start_x = np.zeros_like(xn)
        start_x[..., 0, :] = np.nan_to_num(obs)
        xn = np.where(fresh[..., None, None], start_x, xn)
        pn = np.where(fresh[..., None, None], p0, pn)
        agen = np.where(fresh, 0, np.where(upd, agen + 1, agen))
        unseenn = np.where(seen, 0, unseenn + 1)
        agen = np.where(unseenn > max_predict, -1, agen)
        x, cov, age, unseen = xn, pn, agen, unseenn

    out = np.full((frames, k), NULL, dtype=np.int16)
    i = int(np.argmax(value))
    for f in range(frames - 1, -1, -1):
        out[f] = hyp_labels[f][i]
        i = int(back[f][i])
    return out
