"""Cleanup of labeled markers: spikes and jumps, a zero-lag low-pass filter, short fragments, and
a per-gap preview of the fill.

**Spikes** (:func:`find_spikes`): a spike is a short run of samples (1 to :data:`SPIKE_FRAMES`
frames) that leaves the marker's course and comes back, as a ghost or a neighbour briefly taken
for the marker does. Every such span of a marker's samples is tested as a hypothesis: it is
bridged by up to :data:`BRIDGE` samples on each side (a least-squares quadratic through them; a
line through one side's where the other has fewer than :data:`MIN_SIDE`), and it departs when each
of its samples, and their mean, is further from the bridge than two things together explain:

- the marker noise: a few standard deviations of the residual, which the bridge's weights give
  from the per-axis noise (estimated per marker from the take itself, :func:`marker_noise`);
- the motion: the most that any course whose acceleration stays within ``max_accel`` (and speed
  within ``max_speed``) can depart from its own bridge, a bound that holds however the
  acceleration turns (the integral of the bridge's Peano kernel, :func:`_motion_bounds`).

A departing span is a spike when its bridge fits its own samples within the same allowances
(else the motion there is too fast to judge, or another spike spoils the bridge, and nothing is
claimed); of spans that claim the same samples the best fit wins (:func:`_accept`). Spikes close
together spoil each other's bridges: the departing spans left are bridged again (up to
:data:`PEEL_ROUNDS` times, reaching up to ``BRIDGE + 2 * max_frames`` frames away) over the
samples of the spikes found so far and of the most departing span of each neighbourhood (the
likeliest spike there, :func:`_most_departing`), until no more are found. Bridges
never reach across a gap: a marker that comes back after one may be another marker, and the
frames between are unknown; so a gap never makes a spike, and a span with too few samples on both
sides is not tested. The samples left between a spike and the end of its run (fewer than
:data:`MIN_SIDE`: never bridged on that side) are flagged with it where together they are no
longer than a spike.

**Jumps**: a step between two consecutive samples faster than ``max_speed`` is flagged whatever
the bridges say: the samples between two such steps up to :data:`SPIKE_FRAMES` frames apart,
the short side of one near the end of a run, else the two samples of the step (either may be
wrong).

**Low-pass** (:func:`lowpass`): Butterworth (scipy.signal) run forwards and backwards
(``sosfiltfilt``: no lag), over each run of valid samples on its own: never across a gap.

**Short fragments** (:func:`short_fragments`): samples in runs shorter than ``min_frames``.

**Fill preview** (:class:`FillPreview`): per gap of each marker, the method ``auto`` picks (as
:func:`.fill.fill_markers` does), the markers the fill is computed from, its samples and expected
error; and any other method for one gap on request.

Units: metres, seconds; arrays ``(F, M, 3)`` for F frames of M markers, NaN where missing.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from .fill import MAX_GAP, GapFills, NoFill, fill_method, find_gaps
from .hand.ik import HandSolver
from .tracklets import mask_runs

#: Longest spike, frames.
SPIKE_FRAMES = 3
#: Samples on each side of a span that bridge it.
BRIDGE = 4
#: Most rounds that bridge the suspects left after the first over the most departing of them.
PEEL_ROUNDS = 6
#: Fewest samples on a side of a span that its bridge uses (a fit bends to meet fewer, offset or
#: not); a span with fewer on both sides is not tested.
MIN_SIDE = 3
#: m/s²: the acceleration a marker's course is taken to keep within across a span and its bridge.
#: The bound it gives holds for any course within it however its acceleration turns (the worst
#: case, not a typical one), and grows with the square of the frame time; so it sits well below
#: the peaks of fast finger motion (a flick passes 100 m/s²), which is spared by the bridge's own
#: fit instead (no span is claimed where the bridge's samples do not follow it). Chosen on
#: synthetic takes with injected spikes (``benchmarks/cleanup.py``): at 100-120 Hz its bound plus
#: the noise allowance stays under the smallest spike sought (10 mm held for 3 frames), while the
#: clean samples of the synthetic takes, fast flicks and the real glove recording pass (bar the
#: recording's own one-frame glitches).
MAX_ACCEL = 20.0
#: m/s: a step between consecutive samples faster than this is a jump. Finger joints turn at
#: 60-300 deg/s in everyday tasks (:mod:`.synth.motion`); even 2,000 deg/s moves a fingertip 9 cm
#: from its knuckle at about 3 m/s.
MAX_SPEED = 5.0
#: Standard deviations of its residual beyond which a span's mean departs from the bridge (the
#: norm of three axes' noise passes 4 of them once in a thousand), that each of its samples must
#: depart by (a weaker test: the mean carries the evidence of a spike of several frames), and that
#: the bridge's own samples may stray from it.
NOISE_Z, NOISE_Z_EACH, NOISE_Z_BRIDGE = 4.0, 2.5, 4.0
#: Metres: the least per-axis noise a marker is given (recordings that were smoothed before
#: export have almost none).
NOISE_FLOOR = 1e-4
#: Metres: the noise taken for a marker with too few samples to estimate its own, where no other
#: marker has any.
DEFAULT_NOISE = 5e-4
#: Fewest bridged single samples a marker's noise estimate needs.
MIN_NOISE_SAMPLES = 20
#: Median of the chi distribution with three degrees of freedom (the norm of a standard normal 3-vector).
_CHI3_MEDIAN = 1.5381722


# --- bridges ----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Bridge:
    """A span of ``span`` samples (times ``0 .. span - 1``) bridged by samples at ``offsets``.

    Attributes:
        offsets: int ``(n,)`` the bridge's sample times, relative to the span's first sample.
        inside: ``(span, n)`` the bridge at the span's samples, as weights on the bridge's samples.
        hat: ``(n, n)`` the bridge at its own samples (the least-squares hat matrix).
        noise_inside, noise_mean, noise_bridge: ``(span,)``, scalar, ``(n,)``: standard deviation of
            the residual of each inside sample, of their mean, and of each bridge sample, per unit
            of per-axis marker noise.
        accel_inside, accel_mean, accel_bridge: the same residuals' largest value per unit of
            acceleration (frames²): the integral of the absolute Peano kernel.
        speed_inside, speed_mean, speed_bridge: the same per unit of speed (frames).
    """

    offsets: np.ndarray
    inside: np.ndarray
    hat: np.ndarray
    noise_inside: np.ndarray
    noise_mean: float
    noise_bridge: np.ndarray
    accel_inside: np.ndarray
    accel_mean: float
    accel_bridge: np.ndarray
    speed_inside: np.ndarray
    speed_mean: float
    speed_bridge: np.ndarray


def _motion_bounds(times: np.ndarray, functionals: np.ndarray, order: int, per_frame: int = 32) -> np.ndarray:
    """``(k,)``: the largest value of each functional ``f -> functionals[i] @ f(times)`` over
    courses ``f`` whose ``order``-th derivative (1: speed, 2: acceleration) is at most 1 per frame
    power, for functionals that vanish on polynomials of degree ``order - 1``: the integral of the
    absolute Peano kernel ``K(t) = sum_j c_j (times_j - t)_+^(order-1) / (order-1)!``.

    The kernel is piecewise polynomial between the (integer) times: sampled ``per_frame`` times a
    frame and integrated by the trapezoid rule (exact for the piecewise constant and linear kernels
    here but where one changes sign inside a frame).
    """
    lo, hi = float(times.min()), float(times.max())
    t = np.linspace(lo, hi, int(round((hi - lo) * per_frame)) + 1)
    d = times[:, None] - t[None, :]
    basis = (d > 0).astype(float) if order == 1 else np.clip(d, 0.0, None)
    kernel = np.abs(functionals @ basis)
    return ((kernel[:, 1:] + kernel[:, :-1]) * 0.5 * np.diff(t)).sum(axis=1)


@functools.lru_cache(maxsize=4096)
def _bridge(offsets: tuple[int, ...], span: int) -> _Bridge:
    """The bridge of a span of ``span`` samples by the samples at ``offsets`` (sorted, none inside):
    a quadratic where both sides have samples, else a line."""
    t = np.asarray(offsets, dtype=float)
    degree = 2 if t[0] < 0 < t[-1] else 1
    centre = 0.5 * (t[0] + t[-1])
    design = np.vander(t - centre, degree + 1)
    fit = np.linalg.pinv(design)  # (degree + 1, n)
    inside = np.vander(np.arange(span) - centre, degree + 1) @ fit
    hat = design @ fit
    n = len(t)
    # the residuals as functionals on the samples at [offsets..., 0 .. span - 1]
    times = np.concatenate([t, np.arange(span, dtype=float)])
    of_inside = np.concatenate([-inside, np.eye(span)], axis=1)
    of_mean = of_inside.mean(axis=0, keepdims=True)
    of_bridge = np.concatenate([np.eye(n) - hat, np.zeros((n, span))], axis=1)
    functionals = np.concatenate([of_inside, of_mean, of_bridge])
    accel = _motion_bounds(times, functionals, 2)
    speed = _motion_bounds(times, functionals, 1)
    mean_weights = inside.mean(axis=0)
    return _Bridge(
        offsets=np.asarray(offsets, dtype=np.int64), inside=inside, hat=hat,
        noise_inside=np.sqrt(1.0 + (inside ** 2).sum(axis=1)),
        noise_mean=float(np.sqrt(1.0 / span + mean_weights @ mean_weights)),
        noise_bridge=np.sqrt(np.clip(1.0 - np.diag(hat), 1e-12, None)),
        accel_inside=accel[:span], accel_mean=float(accel[span]), accel_bridge=accel[span + 1:],
        speed_inside=speed[:span], speed_mean=float(speed[span]), speed_bridge=speed[span + 1:])


def _run_ends(valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """int ``(F, M)`` each: the first and the last frame of each valid sample's run (-1 elsewhere)."""
    n_f, n_m = valid.shape
    idx = np.broadcast_to(np.arange(n_f)[:, None], valid.shape)
    previous = np.zeros_like(valid)
    previous[1:] = valid[:-1]
    following = np.zeros_like(valid)
    following[:-1] = valid[1:]
    first = np.maximum.accumulate(np.where(valid & ~previous, idx, -1), axis=0)
    last = np.minimum.accumulate(np.where(valid & ~following, idx, n_f)[::-1], axis=0)[::-1]
    return np.where(valid, first, -1), np.where(valid, last, -1)


def _neighbours(good: np.ndarray, first: np.ndarray, last: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """int ``(F, M)`` each: the nearest ``good`` sample strictly before and after each frame within
    its run (``first``, ``last``: :func:`_run_ends`), -1 where there is none."""
    n_f = good.shape[0]
    idx = np.broadcast_to(np.arange(n_f)[:, None], good.shape)
    upto = np.maximum.accumulate(np.where(good, idx, -1), axis=0)
    before = np.full(good.shape, -1)
    before[1:] = upto[:-1]
    before[before < first] = -1
    from_ = np.minimum.accumulate(np.where(good, idx, n_f)[::-1], axis=0)[::-1]
    after = np.full(good.shape, -1)
    after[:-1] = from_[1:]
    after[(after > last) | (after >= n_f) | (last < 0)] = -1
    return before, after


def _bridge_samples(before: np.ndarray, after: np.ndarray, start: np.ndarray, span: int, column: np.ndarray,
                    reach: int) -> np.ndarray:
    """int ``(N, 2 * BRIDGE)``: the frames of up to :data:`BRIDGE` good samples before each span
    ``[start, start + span)`` of marker ``column`` and after it (in time order), within ``reach``
    frames of the span, a side with fewer than :data:`MIN_SIDE` left out (-1 for none);
    ``before``, ``after``: :func:`_neighbours`."""
    out = np.full((len(start), 2 * BRIDGE), -1)
    cur = start.copy()
    for k in range(BRIDGE):
        cur = np.where(cur >= 0, before[np.maximum(cur, 0), column], -1)
        cur[cur < start - reach] = -1
        out[:, BRIDGE - 1 - k] = cur
    cur = start + span - 1
    for k in range(BRIDGE):
        cur = np.where(cur >= 0, after[np.maximum(cur, 0), column], -1)
        cur[(cur > start + span - 1 + reach)] = -1
        out[:, BRIDGE + k] = cur
    # a side of fewer samples is left out: a fit bends to meet them whatever they are
    few = (out[:, :BRIDGE] >= 0).sum(axis=1) < MIN_SIDE
    out[few, :BRIDGE] = -1
    few = (out[:, BRIDGE:] >= 0).sum(axis=1) < MIN_SIDE
    out[few, BRIDGE:] = -1
    return out


@dataclass
class _Tests:
    """The tests of spans ``[start, start + span)`` of marker ``column`` ``(N,)`` each.

    Attributes:
        departs: bool ``(N,)``: every sample and their mean depart from the bridge beyond the allowance.
        stray: ``(N,)``: the most a bridge sample strays from the bridge, over its allowance (the
            bridge fits its samples at 1 or less; computed where ``departs``, inf elsewhere).
        excess: ``(N,)``: the samples' mean distance from the bridge over its allowance (0 where
            the span has no bridge).
        frames: int ``(N, 2 * BRIDGE)``: the bridge's samples (:func:`_bridge_samples`).
    """

    departs: np.ndarray
    stray: np.ndarray
    excess: np.ndarray
    frames: np.ndarray


def _test_spans(x: np.ndarray, start: np.ndarray, column: np.ndarray, span: int, before: np.ndarray,
                after: np.ndarray, noise: np.ndarray, accel: float, speed: float, reach: int) -> _Tests:
    """Test spans of ``span`` samples of ``x (F, M, 3)`` (zeros where missing) starting at
    ``start (N,)`` in marker ``column (N,)`` against their bridges; ``noise (M,)`` per-axis metres,
    ``accel`` metres per frame², ``speed`` metres per frame."""
    n = len(start)
    departs = np.zeros(n, dtype=bool)
    stray_ratio = np.full(n, np.inf)
    excess = np.zeros(n)
    frames = _bridge_samples(before, after, start, span, column, reach)
    if not n:
        return _Tests(departs, stray_ratio, excess, frames)
    has = frames >= 0
    # a pattern key: which offsets are present (bit per offset before and after the span)
    rel = np.concatenate([start[:, None] - frames[:, :BRIDGE] - 1,
                          frames[:, BRIDGE:] - (start[:, None] + span) + reach], axis=1)
    key = (has.astype(np.int64) << np.where(has, rel, 0)).sum(axis=1)
    order = np.argsort(key, kind="stable")
    keys, first = np.unique(key[order], return_index=True)
    bounds = np.append(first, n)
    inside_frames = start[:, None] + np.arange(span)
    for g in range(len(keys)):
        rows = order[bounds[g]:bounds[g + 1]]
        at = frames[rows[0]]
        offsets = tuple(int(f) - int(start[rows[0]]) for f in at[at >= 0])
        if len(offsets) < MIN_SIDE:
            continue
        b = _bridge(offsets, span)
        cols = column[rows]
        anchors = x[start[rows, None] + b.offsets, cols[:, None]]  # (R, n, 3)
        samples = x[inside_frames[rows], cols[:, None]]  # (R, span, 3)
        residual = samples - np.tensordot(anchors, b.inside, axes=([1], [1])).transpose(0, 2, 1)
        sd = noise[cols][:, None]
        ok, excess[rows] = _departure(residual, sd[:, 0], b, accel, speed)
        departs[rows] = ok
        if ok.any():
            sel = np.flatnonzero(ok)
            a = anchors[sel]
            stray = np.linalg.norm(a - np.tensordot(a, b.hat, axes=([1], [1])).transpose(0, 2, 1), axis=2)
            allow = NOISE_Z_BRIDGE * sd[sel] * b.noise_bridge + np.minimum(b.accel_bridge * accel,
                                                                          b.speed_bridge * speed)
            stray_ratio[rows[sel]] = (stray / allow).max(axis=1)
    return _Tests(departs, stray_ratio, excess, frames)


def _departure(residual: np.ndarray, noise: np.ndarray, b: _Bridge, accel: float,
               speed: float) -> tuple[np.ndarray, np.ndarray]:
    """Spans' residuals from bridge ``b`` ``(..., span, 3)`` (metres) against the allowance: bool
    ``(...)`` whether they depart (each sample and their mean beyond it), and ``(...)`` their mean's
    distance over its allowance; ``noise (...)`` per-axis metres, ``accel`` metres per frame²,
    ``speed`` metres per frame."""
    each = NOISE_Z_EACH * noise[..., None] * b.noise_inside + np.minimum(b.accel_inside * accel, b.speed_inside * speed)
    mean = NOISE_Z * noise * b.noise_mean + min(b.accel_mean * accel, b.speed_mean * speed)
    excess = np.linalg.norm(residual.mean(axis=-2), axis=-1) / np.maximum(mean, 1e-12)
    return (np.linalg.norm(residual, axis=-1) > each).all(axis=-1) & (excess > 1.0), excess


def _full_departs(x: np.ndarray, span: int, noise: np.ndarray, accel: float, speed: float) -> np.ndarray:
    """bool ``(F, M)``: for each first frame, whether the span of ``span`` samples there departs from
    its bridge of :data:`BRIDGE` samples on each side (:func:`_departure`), computed on whole
    arrays (``x (F, M, 3)``, zeros where missing: the caller keeps the spans whose samples are all
    there); False where the bridge would leave the take."""
    n_f = len(x)
    out = np.zeros(x.shape[:2], dtype=bool)
    n = n_f - span - 2 * BRIDGE + 1
    if n <= 0:
        return out
    offsets = tuple(range(-BRIDGE, 0)) + tuple(range(span, span + BRIDGE))
    b = _bridge(offsets, span)
    at = [x[BRIDGE + o:BRIDGE + o + n] for o in offsets]
    residual = np.stack([x[BRIDGE + k:BRIDGE + k + n] - sum(w * a for w, a in zip(b.inside[k], at))
                         for k in range(span)], axis=2)  # (n, M, span, 3)
    out[BRIDGE:BRIDGE + n] = _departure(residual, noise[None, :], b, accel, speed)[0]
    return out


def marker_noise(positions: np.ndarray) -> np.ndarray:
    """Per-axis noise of each marker, metres ``(M,)``, from ``positions (F, M, 3)`` (metres, NaN
    where missing): the median departure of single samples from their bridges of :data:`BRIDGE`
    samples each side, over the noise that a bridge's own samples add; at least
    :data:`NOISE_FLOOR`. A marker with fewer than :data:`MIN_NOISE_SAMPLES` such samples gets the
    median of the others' (:data:`DEFAULT_NOISE` where none has enough). Robust: spikes and fast
    motion in under half of the samples leave it as it is.
    """
    x = np.asarray(positions, dtype=float)
    n_f, n_m, _ = x.shape
    offsets = tuple(range(-BRIDGE, 0)) + tuple(range(1, BRIDGE + 1))
    b = _bridge(offsets, 1)
    sd = np.full(n_m, np.nan)
    if n_f > 2 * BRIDGE:
        mid = slice(BRIDGE, n_f - BRIDGE)
        pred = sum(w * x[BRIDGE + o:n_f - BRIDGE + o] for w, o in zip(b.inside[0], offsets))
        r = np.linalg.norm(x[mid] - pred, axis=2)  # NaN wherever a sample is missing
        counts = np.isfinite(r).sum(axis=0)
        enough = counts >= MIN_NOISE_SAMPLES
        if enough.any():
            sd[enough] = np.nanmedian(r[:, enough], axis=0) / (b.noise_inside[0] * _CHI3_MEDIAN)
    fallback = float(np.nanmedian(sd)) if np.isfinite(sd).any() else DEFAULT_NOISE
    return np.maximum(np.where(np.isfinite(sd), sd, fallback), NOISE_FLOOR)


def _jumps(x: np.ndarray, valid: np.ndarray, first: np.ndarray, last: np.ndarray, speed: float,
           max_frames: int, known: np.ndarray) -> np.ndarray:
    """bool ``(F, M)``: the samples at steps faster than ``speed`` metres per frame (see the module)
    that no sample of ``known`` (bool ``(F, M)``, the spikes found) explains: steps into or out of them
    are left out."""
    out = np.zeros(valid.shape, dtype=bool)
    if len(x) < 2:
        return out
    step = np.linalg.norm(x[1:] - x[:-1], axis=2)
    fast = (step > speed) & valid[1:] & valid[:-1] & ~known[1:] & ~known[:-1]  # [k]: the step from frame k to k + 1
    for m in np.flatnonzero(fast.any(axis=0)):
        ks = np.flatnonzero(fast[:, m]).tolist()
        i = 0
        while i < len(ks):
            k = ks[i]
            if i + 1 < len(ks) and ks[i + 1] - k <= max_frames:  # out and back: the samples between
                out[k + 1:ks[i + 1] + 1, m] = True
                i += 2
                continue
            if k + 1 - first[k, m] <= max_frames:  # the short side at a run's start
                out[first[k, m]:k + 1, m] = True
            elif last[k + 1, m] - k <= max_frames:  # ... or at its end
                out[k + 1:last[k + 1, m] + 1, m] = True
            else:
                out[k:k + 2, m] = True
            i += 1
    return out


def find_spikes(positions: np.ndarray, rate: float, *, max_accel: float = MAX_ACCEL, max_speed: float = MAX_SPEED,
                max_frames: int = SPIKE_FRAMES, noise: float | np.ndarray | None = None) -> np.ndarray:
    """Samples that leave a marker's course for a few frames and come back, or jump, faster than a
    finger can: suspects for review (see the module for the tests).

    Args:
        positions: ``(F, M, 3)`` metres, NaN where missing.
        rate: frames per second.
        max_accel: m/s²: the acceleration a marker's course is taken to keep within around a spike
            (:data:`MAX_ACCEL`); lower finds smaller spikes, higher spares faster motion.
        max_speed: m/s: a step between consecutive samples faster than this is a jump.
        max_frames: the longest spike, frames (1 to :data:`BRIDGE`).
        noise: per-axis marker noise, metres: one for all markers or ``(M,)``; None estimates it
            per marker (:func:`marker_noise`).

    Returns:
        bool ``(F, M)``: the suspect samples (never a missing one).

    Raises:
        ValueError: a bad shape, rate or limit.
    """
    x = np.asarray(positions, dtype=float)
    if x.ndim != 3 or x.shape[2] != 3:
        raise ValueError(f"positions must be (frames, markers, 3), got {x.shape}")
    if not rate > 0:
        raise ValueError(f"rate must be positive, got {rate}")
    if not (max_accel > 0 and max_speed > 0):
        raise ValueError(f"max_accel and max_speed must be positive, got {max_accel} and {max_speed}")
    if not 1 <= max_frames <= BRIDGE:
        raise ValueError(f"max_frames must be 1 to {BRIDGE}, got {max_frames}")
    n_f, n_m, _ = x.shape
    valid = np.isfinite(x).all(axis=2)
    if noise is None:
        sd = marker_noise(x)
    else:
        sd = np.broadcast_to(np.asarray(noise, dtype=float), (n_m,))
        if not (sd >= 0).all():
            raise ValueError(f"noise must be 0 or more metres, got {noise}")
    accel, speed = max_accel / rate ** 2, max_speed / rate
    x0 = np.where(valid[..., None], x, 0.0)
    first, last = _run_ends(valid)
    taken = np.zeros((2, n_f, n_m), dtype=bool)  # the accepted spans' samples, and their bridges' samples
    # round 1: every span, bridged by its nearest samples
    before, after = _neighbours(valid, first, last)
    suspects = []
    for span in range(1, min(max_frames, n_f) + 1):
        ok = valid[:n_f - span + 1] & (last[:n_f - span + 1] >= np.arange(n_f - span + 1)[:, None] + span - 1)
        # spans with a whole bridge each side are tested on whole arrays first, those that depart again here
        whole = ok & _whole(first, last, span)
        start, column = np.nonzero((ok & ~whole) | (whole & _full_departs(x0, span, sd, accel, speed)[:n_f - span + 1]))
        suspects.append(_Suspects.of(span, start, column, _test_spans(x0, start, column, span, before, after, sd,
                                                                      accel, speed, BRIDGE)))
    found: list[tuple[int, int, int]] = []
    left = _accept(suspects, taken, found)
    # then the suspects left (spikes close together spoil each other's bridges): bridged over the
    # samples of the spans accepted so far and of the most departing suspect of each neighbourhood
    pool = [(one.span, one.start, one.column) for one in left]
    doubt = taken[0].copy()
    for _ in range(PEEL_ROUNDS):
        before, after = _neighbours(valid & ~doubt, first, last)
        tested = [_Suspects.of(span, start, column, _test_spans(x0, start, column, span, before, after, sd, accel,
                                                                 speed, BRIDGE + 2 * max_frames))
                  for span, start, column in pool]
        accepted = len(found)
        rest = _accept(tested, taken, found)
        grown = _most_departing(rest, n_f, n_m, max_frames) & ~doubt
        if len(found) == accepted and not grown.any():
            break
        doubt |= taken[0] | grown
        pool = [(span, start[~taken[0][start, column]], column[~taken[0][start, column]])
                for span, start, column in pool]
    spike = taken[0]
    # the samples between a spike and its run's end: too few to be bridged on their side
    for a, b, m in found:
        head, tail = first[a, m], last[a, m] + 1
        if 0 < a - head < MIN_SIDE and b - head <= max_frames:
            spike[head:a, m] = True
        if 0 < tail - b < MIN_SIDE and tail - a <= max_frames:
            spike[b:tail, m] = True
    return (spike | _jumps(x0, valid, first, last, speed, max_frames, spike)) & valid


def _whole(first: np.ndarray, last: np.ndarray, span: int) -> np.ndarray:
    """bool ``(F - span + 1, M)``: spans of ``span`` samples from each frame with :data:`BRIDGE`
    samples of their run on each side (``first``, ``last``: :func:`_run_ends`)."""
    frames = np.arange(len(first) - span + 1)[:, None]
    head, tail = first[:len(first) - span + 1], last[:len(first) - span + 1]
    return (head >= 0) & (head <= frames - BRIDGE) & (tail >= frames + span - 1 + BRIDGE)


@dataclass
class _Suspects:
    """Spans of ``span`` samples that depart from their bridges: first frames ``start (N,)``,
    markers ``column (N,)``, their bridges' fit ``stray (N,)``, their departure ``excess (N,)`` and
    their bridges' samples ``frames (N, 2 * BRIDGE)`` (:class:`_Tests`)."""

    span: int
    start: np.ndarray
    column: np.ndarray
    stray: np.ndarray
    excess: np.ndarray
    frames: np.ndarray

    @classmethod
    def of(cls, span: int, start: np.ndarray, column: np.ndarray, tests: _Tests) -> _Suspects:
        d = tests.departs
        return cls(span, start[d], column[d], tests.stray[d], tests.excess[d], tests.frames[d])

    def subset(self, keep: np.ndarray) -> _Suspects:
        return _Suspects(self.span, self.start[keep], self.column[keep], self.stray[keep], self.excess[keep],
                         self.frames[keep])


def _most_departing(suspects: list[_Suspects], n_f: int, n_m: int, max_frames: int) -> np.ndarray:
    """bool ``(F, M)``: the samples of the ``suspects`` that depart most (``excess``) within
    ``BRIDGE + max_frames`` frames of their first frame, per marker."""
    from scipy.ndimage import maximum_filter1d

    best = np.zeros((n_f, n_m))
    for one in suspects:
        np.maximum.at(best, (one.start, one.column), one.excess)
    peak = maximum_filter1d(best, size=2 * (BRIDGE + max_frames) + 1, axis=0, mode="constant")
    out = np.zeros((n_f, n_m), dtype=bool)
    for one in suspects:
        top = (one.excess > 0) & (one.excess >= peak[one.start, one.column])
        for k in range(one.span):
            out[one.start[top] + k, one.column[top]] = True
    return out


def _accept(suspects: list[_Suspects], taken: np.ndarray, found: list[tuple[int, int, int]]) -> list[_Suspects]:
    """Accept the ``suspects`` whose bridges fit (``stray`` at most 1), best fit first (then the
    shorter), where they clash with none accepted before (a span holds no sample of an accepted
    one's bridge, its bridge none of an accepted span); marks them in ``taken`` ``(2, F, M)``
    (spans' samples, bridges' samples) and adds them to ``found`` (``(start, stop, column)``).
    Returns those not accepted."""
    if not suspects:
        return []
    spans = np.concatenate([np.full(len(one.start), one.span) for one in suspects])
    start = np.concatenate([one.start for one in suspects])
    column = np.concatenate([one.column for one in suspects])
    stray = np.concatenate([one.stray for one in suspects])
    frames = np.concatenate([one.frames for one in suspects])
    accepted = np.zeros(len(start), dtype=bool)
    for i in np.lexsort((spans, stray)):
        if not stray[i] <= 1.0:
            break
        a, b, m = start[i], start[i] + spans[i], column[i]
        f = frames[i][frames[i] >= 0]
        if taken[1, a:b, m].any() or taken[0, f, m].any():
            continue
        taken[0, a:b, m] = True
        taken[1, f, m] = True
        accepted[i] = True
        found.append((a, b, m))
    out, at = [], 0
    for one in suspects:
        out.append(one.subset(~accepted[at:at + len(one.start)]))
        at += len(one.start)
    return out


# --- low-pass filter -------------------------------------------------------------------------------

#: The default order of the Butterworth filter (run twice: a zero-lag filter of twice the order,
#: the usual fourth-order filter of motion capture).
FILTER_ORDER = 2


def lowpass(positions: np.ndarray, rate: float, *, cutoff_hz: float, order: int = FILTER_ORDER) -> np.ndarray:
    """A zero-lag low-pass Butterworth filter over each run of valid samples of each marker.

    The filter (``scipy.signal.butter``, second-order sections) runs forwards and backwards
    (``sosfiltfilt``): no phase shift, the magnitude response squared, so that a sine at the
    cut-off keeps half its amplitude (-6 dB) whatever the order. Runs are filtered on their own,
    never across a gap (gaps stay gaps); each run is padded at its ends by scipy's odd extension
    (its default length, or the run's length less one in a shorter run); a run of one sample is
    left as it is.

    Args:
        positions: ``(F, M, 3)`` metres, NaN where missing.
        rate: frames per second.
        cutoff_hz: the cut-off, Hz: above 0, below half the rate (Nyquist).
        order: the Butterworth filter's order (each pass).

    Returns:
        ``(F, M, 3)`` float64 metres, NaN where ``positions`` has a missing sample.

    Raises:
        ValueError: a cut-off at or beyond 0 or Nyquist, a bad order, rate or shape.
    """
    x = np.array(positions, dtype=float)
    if x.ndim != 3 or x.shape[2] != 3:
        raise ValueError(f"positions must be (frames, markers, 3), got {x.shape}")
    if not rate > 0:
        raise ValueError(f"rate must be positive, got {rate}")
    if not 0 < cutoff_hz < rate / 2:
        raise ValueError(f"cutoff_hz must be above 0 and below the Nyquist frequency ({rate / 2:g} Hz at "
                         f"{rate:g} fps), got {cutoff_hz}")
    if int(order) != order or order < 1:
        raise ValueError(f"order must be a positive integer, got {order}")
    from scipy.signal import butter, sosfiltfilt  # here: scipy.signal takes a while to import

    sos = butter(int(order), cutoff_hz / (rate / 2), output="sos")
    pad = 3 * (2 * len(sos) + 1 - min((sos[:, 2] == 0).sum(), (sos[:, 5] == 0).sum()))  # sosfiltfilt's default
    valid = np.isfinite(x).all(axis=2)
    x[~valid] = np.nan
    column, start, stop = mask_runs(valid)
    for m, a, b in zip(column, start, stop):
        if b - a > 1:
            x[a:b, m] = sosfiltfilt(sos, x[a:b, m], axis=0, padlen=min(pad, b - a - 1))
    return x


# --- short fragments -------------------------------------------------------------------------------

def short_fragments(valid: np.ndarray, *, min_frames: int) -> np.ndarray:
    """bool ``(F, M)``: the samples in runs of valid samples shorter than ``min_frames`` (to delete).

    Args:
        valid: bool ``(F, M)``: where each marker has a sample.
        min_frames: the shortest run kept (1 keeps every run).

    Raises:
        ValueError: ``min_frames`` below 1, or ``valid`` not 2-D.
    """
    valid = np.asarray(valid, dtype=bool)
    if valid.ndim != 2:
        raise ValueError(f"valid must be (frames, markers), got {valid.shape}")
    if int(min_frames) != min_frames or min_frames < 1:
        raise ValueError(f"min_frames must be a positive integer, got {min_frames}")
    column, start, stop = mask_runs(valid)
    short = stop - start < min_frames
    edges = np.zeros((valid.shape[0] + 1, valid.shape[1]), dtype=np.int32)
    np.add.at(edges, (start[short], column[short]), 1)
    np.add.at(edges, (stop[short], column[short]), -1)
    return np.cumsum(edges[:-1], axis=0) > 0


# --- fill preview ----------------------------------------------------------------------------------

@dataclass
class GapPreview:
    """One gap of one marker and a fill of it.

    Attributes:
        marker: the marker's column.
        name: its name.
        start, stop: frames ``[start, stop)``, 0-based.
        asked: the method asked for (``auto`` or one model).
        method: the model that fills it (``auto``'s pick, or the one asked); None when none can.
        donors: int ``(k,)``: the other markers the fill is computed from (:meth:`.fill.GapFills.donors`).
        positions: ``(stop - start, 3)`` metres, the filled samples; None when open.
        error: ``(stop - start,)`` metres, each sample's expected error; None when open.
        reason: why it is open ("" when filled).
        tried: per model tried, its mean expected error (metres) or why it cannot fill the gap.
    """

    marker: int
    name: str
    start: int
    stop: int
    asked: str
    method: str | None = None
    donors: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    positions: np.ndarray | None = None
    error: np.ndarray | None = None
    reason: str = ""
    tried: dict[str, float | str] = field(default_factory=dict)

    @property
    def filled(self) -> bool:
        return self.method is not None


class FillPreview:
    """Every gap of one hand's labeled markers with the fill ``auto`` picks, and another method
    for any gap on request; the caller holds it (its models are solved once).

    ``auto`` picks per gap what :func:`.fill.fill_markers` picks: the model of least mean expected
    error among those it tries, the first of them on a tie.

    Args:
        markers: ``(F, M, 3)`` metres, NaN where missing.
        rate: frames per second.
        max_gap: seconds; longer gaps are left open (whatever the method).
        solver, poses: the calibrated hand and its solve's poses ``(F, 26)``, for ``hand``.
        partners: per marker, int columns of its rigid partners, for ``rigid``
            (:func:`.fill.layout_partners`).
        names: marker names (default ``"0"``, ``"1"``...).

    Attributes:
        gaps: one :class:`GapPreview` per gap, in :func:`.fill.find_gaps` order (by marker, then frame).
    """

    def __init__(self, markers: np.ndarray, rate: float, *, max_gap: float = MAX_GAP, solver: HandSolver | None = None,
                 poses: np.ndarray | None = None, partners: list[np.ndarray] | None = None,
                 names: list[str] | None = None) -> None:
        if not max_gap > 0:
            raise ValueError(f"max_gap must be positive seconds, got {max_gap}")
        self.fills = GapFills(markers, rate, solver=solver, poses=poses, partners=partners)
        self.max_gap = max_gap
        self.names = names or [str(i) for i in range(self.fills.markers.shape[1])]
        found = find_gaps(self.fills.valid)
        self.fills.prepare([(m, a, b) for m, a, b in found if not self.fills.open_reason(a, b, max_gap)])
        self.gaps = [self._preview(m, a, b, "auto") for m, a, b in found]

    def choose(self, gap: int, method: str) -> GapPreview:
        """Fill gap number ``gap`` (an index of :attr:`gaps`) by ``method`` (one of
        :data:`.fill.METHODS`, ``auto`` included) instead; it replaces that gap's preview, and is
        returned (open, with the reason, where the method cannot fill it).

        Raises:
            ValueError: an unknown method; IndexError: no such gap.
        """
        fill_method(method)
        old = self.gaps[gap]
        self.gaps[gap] = self._preview(old.marker, old.start, old.stop, method)
        return self.gaps[gap]

    def apply(self) -> tuple[np.ndarray, np.ndarray]:
        """The markers with every gap's previewed fill: ``(F, M, 3)`` metres, and bool ``(F, M)``
        the filled samples."""
        out = self.fills.markers.copy()
        filled = np.zeros(self.fills.valid.shape, dtype=bool)
        for g in self.gaps:
            if g.filled:
                out[g.start:g.stop, g.marker] = g.positions
                filled[g.start:g.stop, g.marker] = True
        return out, filled

    def _preview(self, marker: int, start: int, stop: int, method: str) -> GapPreview:
        out = GapPreview(marker, self.names[marker], start, stop, method)
        out.reason = self.fills.open_reason(start, stop, self.max_gap)
        if out.reason:
            return out
        tries = fill_method(method).tries
        best = None
        for model in tries:
            try:
                fill, error = self.fills.fill(model, marker, start, stop)
            except NoFill as exc:
                out.tried[model] = str(exc)
                continue
            out.tried[model] = float(error.mean())
            if best is None or error.mean() < best[2].mean():
                best = (model, fill, error)
        if best is None:
            why = [f"{k}: {v}" if len(tries) > 1 else v for k, v in out.tried.items()]
            out.reason = "; ".join(dict.fromkeys(why))
            return out
        out.method, out.positions, out.error = best
        out.donors = self.fills.donors(out.method, marker, start, stop)
        return out

