"""``gmm`` (Alexanderson, O'Sullivan and Beskow 2016): per-marker Gaussian mixtures in the hand frame.

``fit`` learns, from one labeled take of the subject, (a) the rigid triangle of three back-of-hand
markers that defines the hand frame and (b) a mixture of Gaussians per marker of its position in
that frame. Per frame, the triangle is found among the unlabeled points by its side lengths (as a
capture system's rigid-body tracker would), the other points are moved into the hand frame, and
each point's log-likelihood under each marker's mixture is its score. numpy/scipy only.
"""

from __future__ import annotations

import itertools

import numpy as np

from ..layout import Layout
from ..temporal.murty import nbest_labelings
from .assign import assign
from .base import Labeler

#: Regularisation added to every covariance of a performer's fit (metres): 1 mm standard deviation.
PERFORMER_SPREAD = 0.001
#: The same for the layout's synthetic range of motion, which stands in for a performer nobody
#: measured: their hand's proportions and marker places differ from the model's by about this much
#: (han2018 sparse sets: the fitted 1 mm left most fingertips outside every Gaussian).
ROM_SPREAD = 0.02
#: Poses of the average hand the range-of-motion fit is made on (drawn as the training frames are).
ROM_POSES = 5000


def hand_frame(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Origin ``(..., 3)`` and rotation ``(..., 3, 3)`` (columns x, y, z) of the frame of triangle a, b, c."""
    x = b - a
    x = x / np.linalg.norm(x, axis=-1, keepdims=True)
    z = np.cross(b - a, c - a)
    z = z / np.linalg.norm(z, axis=-1, keepdims=True)
    y = np.cross(z, x)
    return (a + b + c) / 3.0, np.stack([x, y, z], axis=-1)


def fit_gmm(x: np.ndarray, components: int, rng: np.random.Generator, iters: int = 60,
            spread: float = PERFORMER_SPREAD) -> tuple:
    """Expectation-maximisation of a full-covariance mixture on ``(n, 3)`` samples; ``spread`` (metres)
    is added to every component's standard deviation along each axis, as a variance.

    Returns weights ``(C,)``, means ``(C, 3)``, covariances ``(C, 3, 3)``.
    """
    n = len(x)
    c = max(1, min(components, n))
    means = x[rng.choice(n, size=c, replace=False)]
    cov = np.repeat((np.cov(x.T) + spread ** 2 * np.eye(3))[None], c, axis=0) if n > 1 else \
        np.repeat(np.eye(3)[None] * 1e-4, c, axis=0)
    weights = np.full(c, 1.0 / c)
    for _ in range(iters):
        log_r = _component_log_pdf(x, *_prepared(weights, means, cov))
        log_r -= np.logaddexp.reduce(log_r, axis=1, keepdims=True)
        r = np.exp(log_r)
        nk = r.sum(axis=0) + 1e-9
        weights = nk / n
        means = (r.T @ x) / nk[:, None]
        d = x[:, None, :] - means[None]
        cov = np.einsum("nc,nci,ncj->cij", r, d, d) / nk[:, None, None] + spread ** 2 * np.eye(3)
    return weights, means, cov


def _prepared(weights: np.ndarray, means: np.ndarray, cov: np.ndarray) -> tuple:
    """A mixture as :func:`_component_log_pdf` takes it: log weights plus the normalising constant,
    means, inverse covariances (computed once, not per frame)."""
    _, logdet = np.linalg.slogdet(cov)
    return np.log(weights) - 0.5 * (logdet + 3 * np.log(2 * np.pi)), means, np.linalg.inv(cov)


def _component_log_pdf(x: np.ndarray, log_norm: np.ndarray, means: np.ndarray, inv: np.ndarray) -> np.ndarray:
    """``log w_c + log N(x; mu_c, Sigma_c)`` for samples ``(..., 3)`` -> ``(..., C)``."""
    d = x[..., None, :] - means
    maha = np.einsum("...ci,cij,...cj->...c", d, inv, d)
    return log_norm - 0.5 * maha


class GmmLabeler(Labeler):
    """Alexanderson's spatial labeler. Call :meth:`fit` with a labeled take first.

    Args:
        layout: the marker layout.
        components: Gaussians per marker (the paper found 3 enough).
        rigid: names of the three back-of-hand markers; default: the three markers of the
            layout's palm that stay most rigid in the fitting take.
        theta_quantile, theta_margin: each marker's null threshold is this quantile of its own
            fitting samples' log-likelihoods, lowered by the margin (nats) because takes leave
            the fitted range (Alexanderson's theta_min, made independent of units).
        tolerance: metres; the triangle found in a frame may differ this much (summed over
            its three sides) from the fitted one, else the frame has no hand frame and all its
            points score null.
        candidates: triangles tried per frame (the best-matching shapes): dense layouts have
            several triangles of about the right size, so the one whose hand frame gives the
            other points the highest likelihood wins.
        spread: metres of standard deviation added to every Gaussian (a floor): the paper's tight
            fit for the performer's own take; wider where the fitting take is not theirs.
    """

    name = "gmm"

    def __init__(self, layout: Layout, components: int = 3, rigid: list[str] | None = None,
                 theta_quantile: float = 0.005, theta_margin: float = 8.0, tolerance: float = 0.012,
                 candidates: int = 6, seed: int = 0, spread: float = PERFORMER_SPREAD):
        self.layout = layout
        self.components = components
        self.rigid_names = rigid
        self.theta_quantile, self.theta_margin = theta_quantile, theta_margin
        self.tolerance, self.candidates = tolerance, candidates
        self.seed = seed
        self.spread = spread
        self.mixtures: list[tuple] = []

    def fit(self, markers: np.ndarray) -> GmmLabeler:
        """Learn from labeled positions ``(F, M, 3)`` in layout order (metres, NaN where missing)."""
        markers = np.asarray(markers, dtype=np.float64)
        rng = np.random.default_rng(self.seed)
        self.rigid = self._choose_rigid(markers)
        tri = markers[:, self.rigid]
        ok = np.isfinite(tri).all(axis=(1, 2))
        if ok.sum() < 10:
            raise ValueError("the fitting take has fewer than 10 frames with all three rigid markers")
        sides = np.linalg.norm(tri[ok] - np.roll(tri[ok], -1, axis=1), axis=2)
        self.sides = np.median(sides, axis=0)  # a-b, b-c, c-a
        origin, rot = hand_frame(tri[ok, 0], tri[ok, 1], tri[ok, 2])
        local = np.einsum("fmi,fij->fmj", markers[ok] - origin[:, None], rot)
        self.mixtures, self.theta = [], np.zeros(len(self.layout))
        for j in range(len(self.layout)):
            x = local[:, j][np.isfinite(local[:, j]).all(axis=1)]
            if len(x) < self.components:
                raise ValueError(f"marker {self.layout.names[j]} has too few samples to fit")
            mix = _prepared(*fit_gmm(x, self.components, rng, spread=self.spread))
            self.mixtures.append(mix)
            ll = np.logaddexp.reduce(_component_log_pdf(x, *mix), axis=1)
            self.theta[j] = np.quantile(ll, self.theta_quantile) - self.theta_margin
        return self

    def _choose_rigid(self, markers: np.ndarray) -> list[int]:
        names = self.layout.names
        if self.rigid_names is not None:
            return [names.index(n) for n in self.rigid_names]
        palm = [i for i, m in enumerate(self.layout.markers) if m.bone == "palm"]
        best, best_score = None, np.inf
        for tri in itertools.combinations(palm, 3):
            p = markers[:, tri]
            sides = np.linalg.norm(p - np.roll(p, -1, axis=1), axis=2)
            sides = sides[np.isfinite(sides).all(axis=1)]
            if len(sides) < 10:
                continue
            a, b, c = np.median(sides, axis=0)
            s = (a + b + c) / 2
            area = np.sqrt(max(s * (s - a) * (s - b) * (s - c), 0.0))
            score = np.std(sides, axis=0).sum() / max(area, 1e-6)  # rigid and well spread
            if score < best_score:
                best, best_score = list(tri), score
        if best is None:
            raise ValueError("the layout has no three palm markers seen together in the fitting take")
        return best

    def find_triangles(self, points: np.ndarray, mask: np.ndarray, candidates: int) -> tuple[np.ndarray, np.ndarray]:
        """The ``candidates`` ordered triples of observations ``(F, C, 3)`` that best match the rigid
        triangle's side lengths, and their errors ``(F, C)`` (metres, summed over the sides)."""
        frames, k, _ = points.shape
        d = np.linalg.norm(points[:, :, None] - points[:, None], axis=3)
        d = np.where(mask[:, :, None] & mask[:, None, :], d, np.inf)
        d[:, np.arange(k), np.arange(k)] = np.inf
        ab, bc, ca = self.sides
        err = (np.abs(d[:, :, :, None] - ab) + np.abs(d[:, None, :, :] - bc)
               + np.abs(np.swapaxes(d, 1, 2)[:, :, None, :] - ca))  # (F, i, j, k)
        flat = err.reshape(frames, -1)
        c = min(candidates, flat.shape[1])
        best = np.argpartition(flat, c - 1, axis=1)[:, :c]
        i, j, kk = np.unravel_index(best, (k, k, k))
        return np.stack([i, j, kk], axis=2), np.take_along_axis(flat, best, axis=1)

    def _block(self, p: np.ndarray, tri: np.ndarray) -> np.ndarray:
        """Scores ``(f, K, M)`` of every observation in the hand frame of the triangles ``(f, 3)``."""
        rows = np.arange(len(p))
        origin, rot = hand_frame(*(p[rows, tri[:, n]] for n in range(3)))
        local = np.einsum("fki,fij->fkj", p - origin[:, None], rot)
        ll = np.stack([np.logaddexp.reduce(_component_log_pdf(local, *mix), axis=2) for mix in self.mixtures], axis=2)
        block = np.clip(ll - self.theta, -50.0, None)  # null (0) wins below each marker's threshold
        # The triangle's own points are labeled by the rigid-body match.
        block[rows[:, None], tri] = -50.0
        block[rows[:, None], tri, np.array(self.rigid)[None, :]] = 50.0
        return block

    def scores(self, points: np.ndarray, mask: np.ndarray) -> np.ndarray:
        if not self.mixtures:
            raise RuntimeError("GmmLabeler.fit() must be called first")
        frames, k, _ = points.shape
        m = len(self.layout)
        out = np.full((frames, k, m + 1), -50.0, dtype=np.float32)
        out[:, :, m] = 0.0
        for s in range(0, frames, 128):  # (F, K, K, K) triangle search: bounded memory
            sl = slice(s, s + 128)
            p, msk = points[sl].astype(np.float64), mask[sl]
            tris, errs = self.find_triangles(p, msk, self.candidates)
            # Dense marker sets have several triangles of about the right shape: keep the one
            # whose hand frame explains the other points best.
            best_block, best_fit = None, np.full(len(p), -np.inf)
            for c in range(tris.shape[1]):
                block = np.where(msk[..., None], self._block(p, tris[:, c]), -50.0)
                fit = np.clip(block.max(axis=1), 0.0, None).sum(axis=1)
                fit = np.where(errs[:, c] <= self.tolerance, fit, -np.inf)
                better = fit > best_fit
                best_block = block if best_block is None else np.where(better[:, None, None], block, best_block)
                best_fit = np.maximum(fit, best_fit)
            found = np.isfinite(best_fit)
            out[sl, :, :m] = np.where(found[:, None, None], best_block, -50.0)
        return out

    def nbest(self, points: np.ndarray, mask: np.ndarray, n_best: int = 5) -> list[list[tuple[float, np.ndarray]]]:
        """Per frame, the ``n_best`` labelings (Murty) as ``(score, labels of the valid observations)``."""
        sc = self.scores(points, mask)
        return [nbest_labelings(sc[f][mask[f]], n_best) for f in range(len(points))]


#: Hand sizes (relative to the range of motion's average hand) and sides tried for a take labeled
#: by a range-of-motion ``gmm``: its Gaussians sit in metres in the back-of-hand frame, so a hand
#: 10 % smaller than the fitted one leaves its markers outside them (two synthetic takes of
#: 0.165 and 0.171 m hands: 2.6 and 0.0 % right unscaled).
ROM_SCALES = (0.88, 0.94, 1.0, 1.06, 1.12)


def range_of_motion_gmm(layout: Layout) -> GmmLabeler:
    """A right-hand ``gmm`` labeler fitted on ``layout``'s markers on the model's average hand in
    :data:`ROM_POSES` poses drawn over the joints' ranges (canonical poses, synergies, uniform
    samples), with Gaussians :data:`ROM_SPREAD` wide (a fit takes seconds: callers keep it in their
    :class:`..cache.RunCache`). Independent poses cover the ranges a short random motion leaves
    out (a fist, one finger bent)."""
    from ..synth.generate import pose_samples

    return GmmLabeler(layout, spread=ROM_SPREAD).fit(pose_samples(layout, ROM_POSES, side="right"))


class ScaledLabeler(Labeler):
    """Another labeler's scores of the take brought to the hand it was fitted on: positions divided
    by ``scale`` and, for a left hand, mirrored in x (the model's hands are exact mirrors, so one
    right-hand fit serves both sides)."""

    def __init__(self, inner: Labeler, scale: float = 1.0, mirror: bool = False) -> None:
        self.inner, self.layout, self.name = inner, inner.layout, inner.name
        self.factor = np.array([-1.0 if mirror else 1.0, 1.0, 1.0]) / scale

    def scores(self, points: np.ndarray, mask: np.ndarray) -> np.ndarray:
        return self.inner.scores((points * self.factor).astype(points.dtype), mask)


def fitted_to_take(labeler: Labeler, batch, sample: int = 100) -> Labeler:
    """``labeler`` (fitted on the average right hand) scaled and mirrored as best fits up to
    ``sample`` frames spread over the take (a :class:`.base.FrameBatch`), judged by the total score
    of each frame's best assignment: hand size and side are not known before labeling. (The count
    of labeled points picked the wrong side of a left-hand take: 7.9 % right against 62.2 %
    mirrored.)"""
    rows = np.unique(np.linspace(0, len(batch.mask) - 1, min(sample, len(batch.mask))).astype(int))
    points, mask = batch.points[rows], batch.mask[rows]
    best, best_total = labeler, -np.inf
    for mirror in (False, True):
        for scale in ROM_SCALES:
            candidate = ScaledLabeler(labeler, scale, mirror)
            scores = candidate.scores(points, mask)
            labels, _ = assign(scores, mask)
            col = np.where(labels >= 0, labels, scores.shape[2] - 1)
            total = np.take_along_axis(scores, col[..., None], axis=2)[..., 0][mask].sum()
            if total > best_total:
                best, best_total = candidate, total
    return best
