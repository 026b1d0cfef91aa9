"""Gap filling of labeled markers: from the solved hand, rigid partners, PCA and splines.

Each gap of a labeled marker (a run of frames where it is missing, with samples on both sides) is
filled by one of

- ``spline``: a cubic spline (not-a-knot) through up to :data:`SPLINE_SUPPORT` samples on each
  side; it reproduces a cubic exactly and suits short gaps.
- ``rigid``: the pattern / rigid-body fill of Vicon and QTM: the marker carried in the frame of
  the markers that move rigidly with it (the layout's rigid partners and the palm markers), its
  place in that frame taken from the frames near the gap where all are seen (Kabsch, numpy SVD).
- ``hand``: the calibrated, solved hand's marker (:func:`.pipeline.solve_take`).
- ``pca``: the PCA reconstruction of Gløersen & Federolf (PLoS ONE 2016): principal components of
  the hand's frames where every marker is seen; in a gap frame the missing coordinates are read
  off the components fitted to the seen ones (least squares).
- ``auto`` (the default): per gap, the available method with the lowest expected error.

The model methods (rigid, hand, pca) do not meet the samples at the gap's ends by themselves: the
model's offset from the observed samples at both ends (position and velocity) is blended across
the gap (:func:`_end_correction`), so that a fill meets the observed samples with no jump in
position or velocity. A gap at the start or end of the take, longer than ``max_gap`` seconds, or
one that the chosen method cannot fill (the hand unsolved in its frames, partners unseen), is left
open, and the result says why.

Every fill comes with a per-sample estimate of its error (metres) from what the take shows near
the gap: for a spline, the marker's acceleration there; for a model, how much the model's offset
from the marker varies there. ``auto`` compares these estimates.

Units: metres; arrays ``(F, M, 3)`` for F frames of M markers, NaN where a sample is missing.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.interpolate import CubicSpline

from .errors import MocapInputError
from .layout import Layout
from .take import Take

METHODS = ("auto", "spline", "rigid", "hand", "pca")
#: Seconds: longer gaps are left open unless told otherwise.
MAX_GAP = 1.0
#: Samples each side of a gap that its spline passes through.
SPLINE_SUPPORT = 4
#: Seconds: the velocity part of the end correction fades out within this time of each end (its
#: bump is at most 4/27 of this times the velocity offset).
VELOCITY_BLEND = 0.1
#: Observed samples each side whose offset from the model gives the velocity offset (a line fit).
SLOPE_SAMPLES = 5
#: Seconds each side of a gap over which the take's own behaviour sets the error estimates (and
#: the rigid template is measured).
NEAR = 1.0
#: Fewest seen rigid partners for a rigid fill (a rotation needs three points).
MIN_PARTNERS = 3
#: Share of the variance the PCA keeps.
PCA_ENERGY = 0.999
#: Metres: the least error an estimate gives (marker noise).
NOISE = 0.0005
#: Order in which ``auto`` prefers methods of equal expected error.
PREFERENCE = ("hand", "rigid", "pca", "spline")


@dataclass
class Gap:
    """One gap of one marker.

    Attributes:
        marker: the marker's column in the array (or point slot in the take).
        name: its name.
        start, stop: frames ``[start, stop)``, 0-based.
        method: the method that filled it, None when left open.
        error: expected error of the fill, metres, mean over its samples (None when open).
        max_error: the largest per-sample estimate, metres (None when open).
        reason: why it was left open ("" when filled).
    """

    marker: int
    name: str
    start: int
    stop: int
    method: str | None = None
    error: float | None = None
    max_error: float | None = None
    reason: str = ""

    @property
    def filled(self) -> bool:
        return self.method is not None

    def as_dict(self, rate: float, first_frame: int = 0) -> dict:
        """For reports: frames as the file numbers them (``first_frame`` + index), errors in mm."""
        out = {"marker": self.name, "first_frame": first_frame + self.start, "last_frame": first_frame + self.stop - 1,
               "frames": self.stop - self.start, "seconds": round((self.stop - self.start) / rate, 4)}
        if self.filled:
            out |= {"method": self.method, "expected_error_mm": round(1000 * self.error, 3),
                    "max_expected_error_mm": round(1000 * self.max_error, 3)}
        else:
            out |= {"method": None, "open": self.reason}
        return out


@dataclass
class Filled:
    """The result of :func:`fill_markers`.

    Attributes:
        positions: ``(F, M, 3)`` metres: the observed samples unchanged, the fills added.
        filled: bool ``(F, M)``: the samples that were filled.
        error: ``(F, M)`` metres: each fill's expected error (NaN elsewhere).
        gaps: every gap, filled or left open.
    """

    positions: np.ndarray
    filled: np.ndarray
    error: np.ndarray
    gaps: list[Gap] = field(default_factory=list)


def find_gaps(valid: np.ndarray) -> list[tuple[int, int, int]]:
    """Every run of missing samples: ``(column, start, stop)`` from bool ``valid (F, M)``."""
    out = []
    pad = np.zeros((1, valid.shape[1]), dtype=np.int8)
    edges = np.diff(np.concatenate([pad, (~valid).astype(np.int8), pad]), axis=0)
    for m in range(valid.shape[1]):
        starts = np.flatnonzero(edges[:, m] == 1)
        stops = np.flatnonzero(edges[:, m] == -1)
        out += [(m, int(a), int(b)) for a, b in zip(starts, stops)]
    return out


# --- the methods: each predicts a marker over frames, or says it cannot ---------------------------

def _run_before(valid: np.ndarray, start: int, most: int) -> int:
    """How many frames right before ``start`` are valid in a row (at most ``most``)."""
    n = 0
    while n < most and start - n - 1 >= 0 and valid[start - n - 1]:
        n += 1
    return n


def _run_after(valid: np.ndarray, stop: int, most: int) -> int:
    n = 0
    while n < most and stop + n < len(valid) and valid[stop + n]:
        n += 1
    return n


@functools.lru_cache(maxsize=4096)
def _spline_weights(before: int, after: int, n: int) -> np.ndarray:
    """``(n, before + after)``: the not-a-knot cubic spline through ``before`` samples ending right
    before a gap of ``n`` frames and ``after`` samples starting right after it, evaluated in the
    gap, as weights on those samples (a spline is linear in its data)."""
    t = np.concatenate([np.arange(-before, 0), np.arange(n, n + after)])
    w = CubicSpline(t, np.eye(before + after), axis=0, bc_type="not-a-knot")(np.arange(n))
    w.setflags(write=False)
    return w


def spline_fill(x: np.ndarray, valid: np.ndarray, start: int, stop: int) -> np.ndarray:
    """A cubic spline (not-a-knot, scipy's CubicSpline) through up to :data:`SPLINE_SUPPORT` samples
    each side of the gap ``[start, stop)`` of one marker ``x (F, 3)``: ``(stop - start, 3)`` metres."""
    a = _run_before(valid, start, SPLINE_SUPPORT)
    b = _run_after(valid, stop, SPLINE_SUPPORT)
    t = np.concatenate([np.arange(start - a, start), np.arange(stop, stop + b)])
    return _spline_weights(a, b, stop - start) @ x[t]


def _kabsch(model: np.ndarray, observed: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted rigid fit of ``model (K, 3)`` onto each of ``observed (F, K, 3)``: rotation matrices
    ``(F, 3, 3)`` and translations ``(F, 3)`` with ``observed ~ R model + t`` (weights ``(F, K)``)."""
    w = weights / np.maximum(weights.sum(axis=1, keepdims=True), 1e-12)
    obs = np.where(weights[..., None] > 0, observed, 0.0)
    mc = w @ model
    oc = np.einsum("fk,fki->fi", w, obs)
    cov = np.einsum("fk,fki,fkj->fij", w, obs - oc[:, None], model[None] - mc[:, None])
    u, _, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(u @ vt))
    u[:, :, 2] *= d[:, None]
    rot = u @ vt
    return rot, oc - np.einsum("fij,fj->fi", rot, mc)


def rigid_model(markers: np.ndarray, m: int, partners: np.ndarray, frames: np.ndarray,
                reference: np.ndarray) -> tuple[np.ndarray, float] | None:
    """Marker ``m`` carried rigidly by ``partners`` over ``frames``: ``(len(frames), 3)`` metres (NaN
    where fewer than :data:`MIN_PARTNERS` are seen), and the RMS error of that model in the
    ``reference`` frames (those where ``m`` and every partner are seen), or None when there are
    no such frames.

    Args:
        markers: ``(F, M, 3)`` metres, NaN where missing.
        partners: int ``(K,)`` columns of the partners (K >= :data:`MIN_PARTNERS`).
        frames, reference: int frame indices.
    """
    if len(reference) == 0 or len(partners) < MIN_PARTNERS:
        return None
    shape = markers[reference[0], partners]
    ones = np.ones((len(reference), len(partners)))
    rot, t = _kabsch(shape, markers[reference][:, partners], ones)
    local = np.einsum("fji,fj->fi", rot, markers[reference, m] - t)  # R^T (x - t)
    template = local.mean(axis=0)
    refit = np.einsum("fij,j->fi", rot, template) + t
    rms = float(np.sqrt(np.mean(np.sum((refit - markers[reference, m]) ** 2, axis=1))))
    seen = np.isfinite(markers[frames][:, partners, 0])
    rot, t = _kabsch(shape, np.nan_to_num(markers[frames][:, partners]), seen.astype(float))
    out = np.einsum("fij,j->fi", rot, template) + t
    out[seen.sum(axis=1) < MIN_PARTNERS] = np.nan
    return out, rms


class PCAModel:
    """Gløersen & Federolf's PCA reconstruction over one hand's markers ``(F, M, 3)`` (metres).

    The components are those of the frames where every marker is seen (centred; enough of them to
    hold :data:`PCA_ENERGY` of the variance). :meth:`predict` gives a marker in every frame from
    the other markers seen there: the frame is fitted to the components on their coordinates by
    least squares (one solve per pattern of seen markers), and the marker read off the fit.
    """

    def __init__(self, markers: np.ndarray, energy: float = PCA_ENERGY) -> None:
        f, m, _ = markers.shape
        self.x = markers.reshape(f, 3 * m)
        self.seen = np.isfinite(self.x)
        complete = self.seen.all(axis=1)
        self.ok = complete.sum() >= 2
        if self.ok:
            self.mean = self.x[complete].mean(axis=0)
            _, s, vt = np.linalg.svd(self.x[complete] - self.mean, full_matrices=False)
            share = np.cumsum(s ** 2) / max(float(np.sum(s ** 2)), 1e-30)
            self.k = int(np.searchsorted(share, energy) + 1)
            self.basis = vt[:self.k].T  # (3M, k)

    def predict(self, m: int) -> np.ndarray:
        """``(F, 3)`` metres: marker ``m`` from the others, NaN where none is seen (or no frame is complete)."""
        out = np.full((len(self.x), 3), np.nan)
        if not self.ok:
            return out
        cols = np.arange(3 * m, 3 * m + 3)
        seen = self.seen.copy()
        seen[:, cols] = False
        rows_any = np.flatnonzero(seen.any(axis=1))
        patterns, which = np.unique(seen[rows_any], axis=0, return_inverse=True)
        for p, pattern in enumerate(patterns):
            rows = rows_any[which.ravel() == p]
            basis = self.basis[:, :max(1, min(self.k, int(pattern.sum()) - 1))]
            coef, *_ = np.linalg.lstsq(basis[pattern], (self.x[rows][:, pattern] - self.mean[pattern]).T, rcond=None)
            out[rows] = (basis[cols] @ coef).T + self.mean[cols]
        return out


# --- meeting the observed samples, and the error estimates -----------------------------------------

def _slope(frames: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Least-squares slope per frame of ``values (n, 3)`` over ``frames (n,)`` (0 for one sample)."""
    if len(frames) < 2:
        return np.zeros(3)
    t = frames - frames.mean()
    return (t @ (values - values.mean(axis=0))) / float(t @ t)


def _end_correction(offset: np.ndarray, valid: np.ndarray, start: int, stop: int, rate: float) -> np.ndarray:
    """The correction ``(stop - start, 3)`` that makes a model meet a marker at both ends of the gap.

    ``offset (F, 3)`` is the observed marker minus the model (NaN where either is missing). The
    offsets at the last sample before the gap and the first after are blended with a smoothstep
    (position, no velocity added); each end's velocity offset (a line fitted to the offsets of up
    to :data:`SLOPE_SAMPLES` samples) is added by a cubic that fades out within
    :data:`VELOCITY_BLEND` seconds. So the fill's position and velocity both meet the marker's.
    """
    a, b = start - 1, stop
    n = b - a
    t = np.arange(start, stop)
    u = (t - a) / n
    smooth = (3 * u ** 2 - 2 * u ** 3)[:, None]
    out = offset[a] * (1 - smooth) + offset[b] * smooth
    width = min(float(n), max(2.0, VELOCITY_BLEND * rate))
    ka = _run_before(valid, start, SLOPE_SAMPLES)
    kb = _run_after(valid, stop, SLOPE_SAMPLES)
    fa, fb = np.arange(start - ka, start), np.arange(stop, stop + kb)
    good_a, good_b = np.isfinite(offset[fa, 0]), np.isfinite(offset[fb, 0])
    slope_a = _slope(fa[good_a], offset[fa[good_a]])
    slope_b = _slope(fb[good_b], offset[fb[good_b]])

    def fade(tau: np.ndarray) -> np.ndarray:  # g(0) = 0, g'(0) = 1, g = g' = 0 from width on
        tau = np.minimum(tau, width)
        return (tau * (1 - tau / width) ** 2)[:, None]

    return out + slope_a * fade(t - a) - slope_b * fade(b - t)


#: Test windows of the take's own samples that an error estimate is measured on.
TESTS = 8


def _tests(ok: np.ndarray, start: int, stop: int, pad: int, span: int) -> np.ndarray:
    """Up to :data:`TESTS` frames ``c``, spread near the gap ``[start, stop)`` (within ``span``
    frames), where ``ok[c - pad : c + n + pad]`` holds throughout (n = the gap's length)."""
    n = stop - start
    cs = np.concatenate([[0], np.cumsum(ok)])
    c = np.arange(max(pad, start - span), min(len(ok) - n - pad, stop + span) + 1)
    c = c[cs[c + n + pad] - cs[c - pad] == n + 2 * pad]
    if len(c) > TESTS:
        c = c[np.linspace(0, len(c) - 1, TESTS).round().astype(int)]
    return c


def _smoothstep(n: int) -> np.ndarray:
    """``(n,)``: the position blend of :func:`_end_correction` over a gap of ``n`` frames."""
    u = np.arange(1, n + 1) / (n + 1)
    return 3 * u ** 2 - 2 * u ** 3


def spline_error(x: np.ndarray, valid: np.ndarray, start: int, stop: int, rate: float) -> np.ndarray:
    """Expected error ``(stop - start,)`` metres of a spline fill, per sample: the RMS error of the
    same spline over gaps of the same length hidden in the marker's own samples near the gap; where
    there are none, half its median acceleration there times the product of the times to the gap's
    ends (the interpolation error of a smooth motion)."""
    n, k = stop - start, SPLINE_SUPPORT
    span = max(int(NEAR * rate), 2 * n)
    c = _tests(valid, start, stop, k, span)
    if len(c):
        support = np.concatenate([np.arange(-k, 0), np.arange(n, n + k)])
        pred = np.einsum("ns,csi->cni", _spline_weights(k, k, n), x[c[:, None] + support])
        err = np.linalg.norm(pred - x[c[:, None] + np.arange(n)], axis=2)
        return NOISE + np.sqrt(np.mean(err ** 2, axis=0))
    h = max(1, int(round(0.05 * rate)))
    near = _window(valid, start, stop, span)
    near = near[(near - h >= 0) & (near + h < len(valid))]
    near = near[valid[near - h] & valid[near + h]]
    accel = 0.0
    if len(near):
        accel = float(np.median(np.linalg.norm(x[near + h] - 2 * x[near] + x[near - h], axis=1))) * (rate / h) ** 2
    t = np.arange(start, stop)
    return NOISE + 0.5 * accel * (t - start + 1) * (stop - t) / rate ** 2


def model_error(offset: np.ndarray, start: int, stop: int, rate: float, floor: float = 0.0) -> np.ndarray:
    """Expected error ``(stop - start,)`` metres of a model fill, per sample: how far the model's
    offset from the marker (``offset (F, 3)``, NaN where either is missing) strays from its blend
    between the ends, over gaps of the same length near this one (RMS); where there are none,
    twice the offset's spread near the gap (or ``floor``) shaped by :func:`_shape`."""
    n = stop - start
    span = max(int(NEAR * rate), 2 * n)
    ok = np.isfinite(offset[:, 0])
    c = _tests(ok, start, stop, 1, span)
    if len(c):
        s = _smoothstep(n)[None, :, None]
        blend = offset[c - 1][:, None] * (1 - s) + offset[c + n][:, None] * s
        err = np.linalg.norm(offset[c[:, None] + np.arange(n)] - blend, axis=2)
        return NOISE + np.sqrt(np.mean(err ** 2, axis=0))
    near = _window(ok, start, stop, span)
    spread = 2 * float(np.sqrt(np.mean(np.sum((offset[near] - offset[near].mean(axis=0)) ** 2, axis=1)))) \
        if len(near) >= 2 else float("inf")
    return NOISE + max(spread, floor) * _shape(start, stop)


def _shape(start: int, stop: int) -> np.ndarray:
    """``(stop - start,)``: how far into the gap each frame is, 0 at the ends to 1 in the middle."""
    a, b = start - 1, stop
    u = (np.arange(start, stop) - a) / (b - a)
    return np.sqrt(4 * u * (1 - u))


def _window(valid: np.ndarray, start: int, stop: int, span: int) -> np.ndarray:
    """Observed frames within ``span`` frames of the gap ``[start, stop)``."""
    lo, hi = max(0, start - span), min(len(valid), stop + span)
    idx = np.arange(lo, hi)
    return idx[valid[idx]]


# --- the fill ---------------------------------------------------------------------------------------

def fill_markers(markers: np.ndarray, rate: float, method: str = "auto", max_gap: float = MAX_GAP,
                 solved: np.ndarray | None = None, partners: list[np.ndarray] | None = None,
                 names: list[str] | None = None) -> Filled:
    """Fill the gaps of one hand's labeled markers.

    Args:
        markers: ``(F, M, 3)`` metres, NaN where missing.
        rate: frames per second.
        method: one of :data:`METHODS`.
        max_gap: seconds; longer gaps are left open.
        solved: ``(F, M, 3)`` metres, the solved hand's markers (NaN where unsolved), for ``hand``.
        partners: per marker, int columns of the markers that move rigidly with it, for ``rigid``.
        names: marker names for the gaps (default ``"0"``, ``"1"``...).

    Returns:
        :class:`Filled`; observed samples are copied unchanged.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    markers = np.asarray(markers, dtype=float)
    n_f, n_m, _ = markers.shape
    names = names or [str(i) for i in range(n_m)]
    valid = np.isfinite(markers[..., 0])
    out = markers.copy()
    filled = np.zeros((n_f, n_m), dtype=bool)
    error = np.full((n_f, n_m), np.nan)
    longest = int(np.floor(max_gap * rate + 1e-9))
    wanted = PREFERENCE if method == "auto" else (method,)
    pca = PCAModel(markers) if "pca" in wanted else None
    all_frames = np.arange(n_f)
    models: dict[tuple[str, int], tuple[np.ndarray, float] | None] = {}
    gaps = []
    for m, start, stop in find_gaps(valid):
        gap = Gap(m, names[m], start, stop)
        gaps.append(gap)
        if start == 0 or stop == n_f:
            gap.reason = "at the start of the take" if start == 0 else "at the end of the take"
            if start == 0 and stop == n_f:
                gap.reason = "never seen"
            continue
        if stop - start > longest:
            gap.reason = f"longer than max_gap ({(stop - start) / rate:.2f} s > {max_gap:g} s)"
            continue
        x = markers[:, m]
        span = np.arange(start - 1, stop + 1)
        best = None
        why = []
        for name in wanted:
            if name == "spline":
                fill, err = spline_fill(x, valid[:, m], start, stop), spline_error(x, valid[:, m], start, stop, rate)
            else:
                if name == "hand" and solved is None:
                    why.append("no hand solve")
                    continue
                if name == "rigid" and (partners is None or len(partners[m]) < MIN_PARTNERS):
                    why.append("fewer than 3 rigid partners")
                    continue
                if (name, m) not in models:
                    if name == "hand":
                        models[name, m] = solved[:, m], 0.0
                    elif name == "pca":
                        models[name, m] = pca.predict(m), 0.0
                    else:
                        ref = np.flatnonzero(valid[:, m] & valid[:, partners[m]].all(axis=1))
                        models[name, m] = rigid_model(markers, m, partners[m], all_frames, ref)
                if models[name, m] is None:
                    why.append("the rigid partners are never seen with it")
                    continue
                model, floor = models[name, m]
                if not np.isfinite(model[span, 0]).all():
                    why.append(f"no {name} model in every frame of the gap")
                    continue
                offset = x - model
                fill = model[start:stop] + _end_correction(offset, valid[:, m], start, stop, rate)
                err = model_error(offset, start, stop, rate, floor)
            if best is None or err.mean() < best[2].mean():
                best = (name, fill, err)
        if best is None:
            gap.reason = "; ".join(dict.fromkeys(why))
            continue
        gap.method, fill, err = best
        out[start:stop, m] = fill
        filled[start:stop, m] = True
        error[start:stop, m] = err
        gap.error, gap.max_error = float(err.mean()), float(err.max())
    return Filled(out, filled, error, gaps)


def layout_partners(layout: Layout) -> list[np.ndarray]:
    """Per marker of ``layout``, the columns of the markers that move rigidly with it: its rigid
    partners (:func:`.temporal.partners.rigid_pairs`) and the palm markers."""
    from .temporal.partners import rigid_pairs

    rigid = rigid_pairs(layout)
    palm = [i for i, mk in enumerate(layout.markers) if mk.bone == "palm"]
    out = []
    for m in range(len(layout)):
        mine = set(rigid.pairs[rigid.pairs[:, 0] == m, 1].tolist()) | set(palm)
        mine.discard(m)
        out.append(np.array(sorted(mine), dtype=np.int64))
    return out


@dataclass
class TakeFill:
    """The result of :func:`fill_gaps`.

    Attributes:
        take: the take with its gaps filled; ``take.filled`` marks the fills (and any the input had).
        gaps: every gap of every hand's markers, filled or left open (``marker`` = point slot).
        method, max_gap: as asked.
        seconds: wall time of the solve (when done here) and of the fill.
    """

    take: Take
    gaps: list[Gap]
    method: str
    max_gap: float
    seconds: dict

    def report(self) -> dict:
        """A JSON-ready report: counts, every gap (marker, frames, method, expected error, or why open)."""
        take = self.take
        filled = [g for g in self.gaps if g.filled]
        methods = {}
        for g in filled:
            methods[g.method] = methods.get(g.method, 0) + 1
        return {
            "file": take.source, "method": self.method, "max_gap_s": self.max_gap, "rate": take.rate,
            "gaps": len(self.gaps), "filled": len(filled), "open": len(self.gaps) - len(filled),
            "filled_samples": int(sum(g.stop - g.start for g in filled)), "methods": methods,
            "seconds": self.seconds,
            "gap_list": [g.as_dict(take.rate, take.first_frame) for g in self.gaps],
        }


def fill_gaps(take: Take, layout: Layout, method: str = "auto", max_gap: float = MAX_GAP,
              solves: list | None = None, naming=None, **solve_options) -> TakeFill:
    """Fill the gaps of every labeled hand of ``take`` (one hand with plain layout names, or two
    named by side, :func:`.hands.hands_in_names`); other points are left as they are.

    Args:
        take: a labeled take (metres).
        layout: its marker layout.
        method: one of :data:`METHODS`.
        max_gap: seconds; longer gaps are left open.
        solves: ``[(side, HandSolve)]`` as :func:`.pipeline.solve_hands` gives for this take; None
            solves here when the method may use the hand (``hand``, ``auto``).
        naming: how two hands' names carry their side (:class:`.hands.HandNaming`).
        solve_options: passed to :func:`.pipeline.solve_hands` when solving here.

    Raises:
        MocapInputError: the take is not labeled with ``layout``; or a bad ``method`` / ``max_gap``.
    """
    from .hands import hands_in_names, split_hands

    if method not in METHODS:
        raise MocapInputError(take.source, f"unknown fill method {method!r} (one of {', '.join(METHODS)})")
    if not max_gap > 0:
        raise MocapInputError(take.source, f"max_gap must be positive seconds, got {max_gap}")
    split_hands(take, layout, naming)  # a take that is not labeled with the layout: one clear error
    found = hands_in_names(take.names, layout, naming)
    seconds = {}
    if solves is None and method in ("hand", "auto"):
        from .pipeline import solve_hands

        t0 = time.perf_counter()
        solves = solve_hands(take, layout, naming, **solve_options)
        seconds["solve"] = round(time.perf_counter() - t0, 4)
    by_side = dict(solves or [])
    t0 = time.perf_counter()
    partners = layout_partners(layout)
    positions = take.positions.copy()
    was = np.zeros(take.valid.shape, dtype=bool) if take.filled is None else take.filled.copy()
    gaps = []
    for side, cols in found.items():
        one = by_side.get(side)
        result = fill_markers(take.positions[:, cols], take.rate, method, max_gap,
                              solved=None if one is None else one.fit.markers, partners=partners,
                              names=[take.names[c] for c in cols])
        positions[:, cols] = result.positions
        was[:, cols] |= result.filled
        for g in result.gaps:
            g.marker = cols[g.marker]
        gaps += result.gaps
    seconds["fill"] = round(time.perf_counter() - t0, 4)
    residuals = take.residuals
    if residuals is not None:
        residuals = np.where(was & ~take.valid, 0.0, residuals).astype(residuals.dtype)
    out = replace(take, positions=positions.astype(take.positions.dtype), residuals=residuals, filled=was,
                  warnings=list(take.warnings))
    return TakeFill(out, gaps, method, max_gap, seconds)
