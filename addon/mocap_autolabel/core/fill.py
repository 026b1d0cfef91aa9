"""Gap filling of labeled markers: from the solved hand, rigid partners, PCA and splines.

Each gap of a labeled marker (a run of frames where it is missing, with samples on both sides) is
filled by one of

- ``spline``: a cubic spline (not-a-knot) through up to :data:`SPLINE_SUPPORT` samples on each
  side; it reproduces a cubic exactly and suits short gaps.
- ``rigid``: the pattern / rigid-body fill of Vicon and QTM: the marker carried in the frame of
  the markers that move rigidly with it (the layout's rigid partners and the palm markers), its
  place in that frame taken from the frames near the gap where all are seen (Kabsch, numpy SVD).
- ``hand``: the calibrated, solved hand's marker (:func:`.pipeline.solve_take`), the hand solved
  again in the gap without the marker, with a prior on its joint angles learned from the take
  near the gap (:class:`HandFill`): the angles the hidden marker leaves unseen follow the others.
- ``pca``: the PCA reconstruction of Gløersen & Federolf (PLoS ONE 2016): principal components of
  the hand's frames where every marker is seen; in a gap frame the missing coordinates are read
  off the components fitted to the seen ones (least squares).
- ``pose``: the marker read off the pose of the hand's other markers: a linear model of it from
  them, both in the hand's own frame (the Kabsch fit of those markers), learned from the frames
  within :data:`POSE_WINDOW` seconds of the gap. Unlike ``pca`` (global coordinates, where a
  hand's turn is not linear) it needs no frame with every marker seen, and it learns the
  marker's relation to the others as it is around the gap.
- ``auto`` (the default): per gap, the available method with the lowest expected error.

The model methods (rigid, hand, pca, pose) do not meet the samples at the gap's ends by themselves: the
model's offset from the observed samples at both ends (position and velocity) is blended across
the gap (:func:`_end_correction`), so that a fill meets the observed samples with no jump in
position or velocity. A gap at the start or end of the take, longer than ``max_gap`` seconds, or
one that the chosen method cannot fill (the hand unsolved in its frames, partners unseen), is left
open, and the result says why.

Every fill comes with a per-sample estimate of its error (metres) measured on the take itself: the
same method over gaps of the same length hidden in the marker's own samples near the gap
(:data:`TESTS` of them within :data:`NEAR` seconds, each predicted as if hidden too).
``auto`` compares these estimates.

Units: metres; arrays ``(F, M, 3)`` for F frames of M markers, NaN where a sample is missing.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np
from scipy.interpolate import CubicSpline

from .errors import MocapInputError
from .hand.ik import HandSolver
from .hand.skeleton import POSE_LIMITS
from .labeling import layout_markers
from .layout import Layout
from .rotations import kabsch
from .solve import HandSolve, solve_hands, solve_take
from .take import Take
from .tracklets import mask_runs


class FillMethod:
    """A fill method of the registry: capabilities as class attributes.

    Attributes:
        name: the method's name (``--fill-method``, the panel).
        uses_hand: fills from the solved hand: the hand is solved before the fill.
        needs_hand: fills from nothing else (no hand solve, no fill).
        tries: the models it tries per gap, best expected error first (``auto`` tries several).
    """

    name: ClassVar[str]
    uses_hand: ClassVar[bool] = False
    needs_hand: ClassVar[bool] = False
    tries: ClassVar[tuple[str, ...]]


class AutoFill(FillMethod):
    """Per gap, the model of least expected error among the hand, the pose and the spline."""

    name = "auto"
    uses_hand = True
    tries = ("hand", "pose", "spline")


class SplineMethod(FillMethod):
    name, tries = "spline", ("spline",)


class RigidMethod(FillMethod):
    name, tries = "rigid", ("rigid",)


class HandMethod(FillMethod):
    name, uses_hand, needs_hand, tries = "hand", True, True, ("hand",)


class PCAMethod(FillMethod):
    name, tries = "pca", ("pca",)


class PoseMethod(FillMethod):
    name, tries = "pose", ("pose",)


#: The fill methods by name; the first is the default.
FILL_METHODS: dict[str, type[FillMethod]] = {m.name: m for m in (AutoFill, SplineMethod, RigidMethod, HandMethod,
                                                                 PCAMethod, PoseMethod)}
METHODS = tuple(FILL_METHODS)


def fill_method(name: str) -> type[FillMethod]:
    """The registry's class for ``name``; a ValueError naming the choices for an unknown one."""
    try:
        return FILL_METHODS[name]
    except KeyError:
        raise ValueError(f"unknown fill method {name!r}; choose one of {', '.join(FILL_METHODS)}") from None


class NoFill(Exception):
    """A model cannot fill a gap; ``str()`` says why."""


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
#: Test windows of the take's own samples that an error estimate is measured on.
TESTS = 8
#: Most frames inside a test window whose error is measured (spread evenly, the ends included;
#: the error between them interpolated: it changes smoothly across a gap).
TEST_POINTS = 16
#: Order in which ``auto`` prefers methods of equal expected error.
PREFERENCE = AutoFill.tries
#: Seconds each side of a gap whose frames a pose fill learns from (on the real glove recording,
#: median error of 0.25-2 s gaps: 0.53 mm learning from 1 s, 0.40 mm from 5 s, 0.37 mm from 10 s).
POSE_WINDOW = 5.0
#: Most frames a pose fill learns from, spread evenly over the window (real glove recording, median
#: error of 0.25-2 s gaps: 0.43 mm from 120, 0.41 mm from 160, 0.42 mm from 240).
POSE_FRAMES = 160
#: Fewest frames a pose fill learns from.
MIN_LEARN = 18
#: Share of the variance of the other markers' coordinates (in the hand's frame) a pose fill keeps.
POSE_ENERGY = 0.9999
#: Metres: the marker distance that weighs as much as one standard deviation of the joint angles'
#: prior in a hand fill (real glove recording, 12 rounds, median error of 0.25-2 s gaps: 0.64 mm
#: at 1.5 mm, 0.63 at 2, 0.65 at 3, 0.69 at 4; steps at the gaps' ends of 0.5 mm or more beyond
#: the marker's own: 2, 1, 0 and 1 of 156).
PRIOR_SIGMA = 0.003
#: Radians: the least spread of a joint angle in that prior, so that an angle that did not move
#: near the gap is held, not frozen (glove: the same 0.65 mm from 0.0003 to 0.01 rad).
PRIOR_FLOOR = 0.001
#: Gauss-Newton steps of a hand fill from the take's solve (glove, 0.25-2 s gaps: 1.10 mm after
#: one, 0.65 mm after two or three).
HAND_ITERATIONS = 2
#: A hand fill's test windows and the frames measured in each (fewer than the other models': each
#: frame is a solve).
HAND_TESTS, HAND_TEST_POINTS = 3, 5
#: Most rows (a frame with one marker hidden) a hand fill solves side by side: about 30 kB each;
#: 512 fill the 10,000-frame take 20 % faster than 2,048 (the arrays stay in the cache).
HAND_BATCH = 512


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


class _Model:
    """A way to predict marker ``m`` in given frames (NaN where it cannot)."""

    #: Test windows its error estimate is measured on, and frames measured in each.
    tests, test_points = TESTS, TEST_POINTS

    #: Its course is smoothed before it fills (:func:`_smooth`): a model that carries the noise and
    #: spikes of many markers' samples into each frame.
    smooth = False

    def available(self, m: int) -> np.ndarray:
        """bool ``(F,)``: frames where the model can predict marker ``m`` (kept per marker)."""
        known = self.__dict__.setdefault("_known", {})
        if m not in known:
            known[m] = self._available(m)
        return known[m]

    def _available(self, m: int) -> np.ndarray:
        raise NotImplementedError

    def predict(self, m: int, frames: np.ndarray, start: int, stop: int, held_out: bool = False) -> np.ndarray:
        """``(len(frames), 3)`` metres: marker ``m`` in ``frames``, for the gap ``[start, stop)``;
        ``held_out``: ``frames`` are test windows, to be predicted as if hidden too (a model that
        learns from the frames near the gap leaves them out)."""
        raise NotImplementedError


class HandFill(_Model):
    """The calibrated hand solved again without marker ``m``, its joint angles held to their own
    course near the gap.

    A hidden marker leaves some of the hand's joint angles unseen (a fingertip's: its finger's
    distal flexion), and the solve's frame-by-frame fit keeps them where they were (on the real
    glove recording that alone misses a hidden tip by 5-11 mm, median, in gaps of 0.25 s and
    longer). Here each frame is fitted again (:meth:`_fit`) to the other markers under a
    Gaussian prior on the 20 joint angles: their mean and covariance over the frames within
    :data:`POSE_WINDOW` seconds of the gap where ``m`` is seen (at most :data:`POSE_FRAMES` of
    them, less the test windows when those are asked for). The angles the other markers pin stay
    where they pin them; the unseen ones follow the others as they did near the gap (a finger
    flexes with its neighbours): the conditional mean of the prior. :data:`PRIOR_SIGMA` weighs
    the prior against the marker distances.

    Args:
        solver: the calibrated hand and its markers.
        poses: ``(F, 26)`` the solve's poses (NaN rows where unsolved).
        markers: ``(F, M, 3)`` the observed markers, metres (NaN where missing).
        rate: frames per second.
    """

    smooth = True
    tests, test_points = HAND_TESTS, HAND_TEST_POINTS

    def __init__(self, solver: HandSolver, poses: np.ndarray, markers: np.ndarray, rate: float) -> None:
        self.solver, self.poses, self.x, self.rate = solver, np.asarray(poses, dtype=float), markers, rate
        self.valid = np.isfinite(markers[..., 0])
        self.solved = np.isfinite(self.poses[:, 0])

    def _available(self, m: int) -> np.ndarray:
        return self.solved & (self.valid.sum(axis=1) - self.valid[:, m] >= MIN_PARTNERS)

    def _prior(self, m: int, start: int, stop: int, leave_out: np.ndarray | None) -> tuple | None:
        """The joint angles' mean ``(20,)`` and precision ``(20, 20)`` near the gap, or None."""
        w = int(POSE_WINDOW * self.rate)
        lo, hi = max(0, start - w), min(len(self.x), stop + w)
        ok = self.valid[lo:hi, m] & self.solved[lo:hi]
        if leave_out is not None:
            ok[leave_out[(leave_out >= lo) & (leave_out < hi)] - lo] = False
        near = _evenly(lo + np.flatnonzero(ok), POSE_FRAMES)  # the gap's frames are not seen
        if len(near) < MIN_LEARN:
            return None
        angles = self.poses[near, 6:]
        mean = angles.mean(axis=0)
        cov = (angles - mean).T @ (angles - mean) / (len(near) - 1) + PRIOR_FLOOR ** 2 * np.eye(angles.shape[1])
        return mean, PRIOR_SIGMA ** 2 * np.linalg.inv(cov)

    def prepare(self, gaps: list[tuple[int, int, int]]) -> None:
        """Solve, in one batch, the frames that the fills of ``gaps`` ``(m, start, stop)`` and their
        error estimates will ask for (a solve of a few frames at a time is mostly overhead)."""
        asks = []
        for m, start, stop in gaps:
            if self.available(m)[start:stop].all():
                around, _, _, windows = _plan(self, m, self.valid[:, m], start, stop, self.rate)
                asks.append((m, start, stop, around, False))
                if len(windows):
                    asks.append((m, start, stop, np.unique(windows), True))
        self.__dict__.setdefault("_solved", {}).update(self._solve(asks))

    def _solve(self, asks: list[tuple[int, int, int, np.ndarray, bool]]) -> dict:
        """For each ask ``(m, start, stop, frames, held_out)``: ``frames`` and marker ``m`` in them
        ``(len(frames), 3)``, fitted without it (NaN where unsolved or without a prior)."""
        out, owners, means, precisions, rows = {}, [], [], [], []
        for m, start, stop, frames, held_out in asks:
            key = (m, start, stop, held_out)
            out[key] = frames, np.full((len(frames), 3), np.nan)
            prior = self._prior(m, start, stop, frames if held_out else None)
            if prior is not None:
                at = np.flatnonzero(self.solved[frames])  # row: frame, marker, ask, place in the ask
                rows.append(np.stack([frames[at], np.full(len(at), m), np.full(len(at), len(owners)), at], axis=1))
                owners.append(key)
                means.append(prior[0])
                precisions.append(prior[1])
        if not owners:
            return out
        rows = np.concatenate(rows)
        rows = rows[np.argsort(rows[:, 0], kind="stable")]  # a chunk's rows share frames: one Jacobian each
        means, precisions = np.stack(means), np.stack(precisions)
        fitted = np.concatenate([self._fit(part[:, 0], part[:, 1], means[part[:, 2]], precisions[part[:, 2]])
                                 for part in np.array_split(rows, -(-len(rows) // HAND_BATCH))])
        for row, at in zip(rows, fitted):
            out[owners[row[2]]][1][row[3]] = at
        return out

    def _fit(self, frames: np.ndarray, hidden: np.ndarray, mean: np.ndarray, precision: np.ndarray) -> np.ndarray:
        """Marker ``hidden[i]`` ``(R, 3)`` of the hand fitted in frame ``frames[i]`` to the other
        markers seen there, under the joint-angle prior ``mean[i] (20,)``, ``precision[i] (20, 20)``.

        :data:`HAND_ITERATIONS` Gauss-Newton steps from the take's solve, on its Jacobian there:
        the solve is near the fit already, so the Jacobian hardly changes, and one per frame serves
        every marker hidden in it (the Jacobian is most of a step's time). The last step moves the
        marker along the Jacobian too.
        """
        solver, n = self.solver, len(frames)
        unique, which = np.unique(frames, return_inverse=True)
        which = which.ravel()
        poses = self.poses[unique]
        fitted, jac = solver.jacobian(poses)  # (U, M, 3), (U, M, 3, 26)
        seen = self.valid[unique]
        observed = np.nan_to_num(self.x[unique])
        jac_seen = (jac * seen[..., None, None]).reshape(len(unique), -1, jac.shape[-1])
        normal_all = np.swapaxes(jac_seen, 1, 2) @ jac_seen
        off = (fitted - observed) * seen[..., None]  # (U, M, 3)
        grad_all = (np.swapaxes(jac_seen, 1, 2) @ off.reshape(len(unique), -1, 1))[..., 0]
        rows = np.arange(n)
        mine = jac[which, hidden] * seen[which, hidden][:, None, None]  # (R, 3, 26): the hidden marker's part
        normal = normal_all[which] - np.swapaxes(mine, 1, 2) @ mine
        normal[:, 6:, 6:] += precision
        normal += 1e-9 * np.eye(normal.shape[-1])
        try:
            lower = np.linalg.cholesky(normal)  # one factor for both steps (5x faster than numpy's solve)
            solve = functools.partial(_cholesky_solve, lower)
        except np.linalg.LinAlgError:  # a frame whose other markers pin too little, in round-off
            solve = functools.partial(_matvec, np.linalg.pinv(normal, hermitian=True))
        grad = grad_all[which] - (np.swapaxes(mine, 1, 2) @ off[which, hidden][..., None])[..., 0]
        current, at, step = poses[which], fitted[which, hidden], np.zeros((n, poses.shape[1]))
        use = seen[which]
        use[rows, hidden] = False
        lo, hi = POSE_LIMITS
        for it in range(HAND_ITERATIONS):
            if it:
                current = solver.step(current, step)
                current[:, 6:] = np.clip(current[:, 6:], lo[6:], hi[6:])
                markers = solver.markers(current)
                at = markers[rows, hidden]
                residual = ((markers - observed[which]) * use[..., None]).reshape(n, -1, 1)
                grad = (np.swapaxes(jac_seen[which], 1, 2) @ residual)[..., 0]
            grad[:, 6:] += np.einsum("fi,fij->fj", current[:, 6:] - mean, precision)
            step = -solve(grad)
        return at + (jac[which, hidden] @ step[..., None])[..., 0]

    def predict(self, m: int, frames: np.ndarray, start: int, stop: int, held_out: bool = False) -> np.ndarray:
        key = (m, start, stop, held_out)
        got = self.__dict__.get("_solved", {}).get(key)
        if got is None or not np.array_equal(got[0], frames):
            got = self._solve([(m, start, stop, frames, held_out)])[key]
        return got[1]


def _matvec(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a (R, n, n) @ b (R, n)`` per row: ``(R, n)``."""
    return (a @ b[..., None])[..., 0]


def _cholesky_solve(lower: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``x (R, n)`` with ``lower @ lower^T @ x = b`` for ``lower (R, n, n)`` lower triangular
    (batched forward and back substitution: numpy has none)."""
    n = b.shape[1]
    y = np.empty_like(b)
    for i in range(n):
        y[:, i] = (b[:, i] - np.einsum("rj,rj->r", lower[:, i, :i], y[:, :i])) / lower[:, i, i]
    x = np.empty_like(b)
    for i in range(n - 1, -1, -1):
        x[:, i] = (y[:, i] - np.einsum("rj,rj->r", lower[:, i + 1:, i], x[:, i + 1:])) / lower[:, i, i]
    return x


class RigidFill(_Model):
    """The pattern / rigid-body fill: marker ``m`` carried by the Kabsch fit of its ``partners``.

    Its place in the partners' frame is the mean over the frames near the gap (within
    :data:`NEAR` seconds, or the gap's length) where it and every partner are seen; where there
    are fewer than :data:`MIN_REFERENCE` of them, over the nearest such frames of the take.
    """

    def __init__(self, markers: np.ndarray, partners: list[np.ndarray], rate: float) -> None:
        self.x, self.partners, self.rate = markers, partners, rate
        self.valid = np.isfinite(markers[..., 0])

    def _available(self, m: int) -> np.ndarray:
        if len(self.partners[m]) < MIN_PARTNERS:
            return np.zeros(len(self.x), dtype=bool)
        return self.valid[:, self.partners[m]].sum(axis=1) >= MIN_PARTNERS

    def predict(self, m: int, frames: np.ndarray, start: int, stop: int, held_out: bool = False) -> np.ndarray:
        out = np.full((len(frames), 3), np.nan)
        p = self.partners[m]
        every = np.flatnonzero(self.valid[:, m] & self.valid[:, p].all(axis=1))
        if not len(every):
            return out
        span = max(int(NEAR * self.rate), 2 * (stop - start))
        distance = np.maximum(start - 1 - every, every - stop)
        ref = every[distance <= span]
        if len(ref) < MIN_REFERENCE:
            ref = every[np.argsort(distance, kind="stable")[:2 * span]]
        ref = _evenly(ref, MAX_REFERENCE)
        shape = self.x[ref[0], p]
        rot, t = kabsch(shape, self.x[ref][:, p], np.ones((len(ref), len(p))))
        template = np.einsum("fji,fj->fi", rot, self.x[ref, m] - t).mean(axis=0)  # R^T (x - t)
        seen = self.valid[frames][:, p]
        rot, t = kabsch(shape, np.nan_to_num(self.x[frames][:, p]), seen.astype(float))
        out = np.einsum("fij,j->fi", rot, template) + t
        out[seen.sum(axis=1) < MIN_PARTNERS] = np.nan
        return out


class PCAFill(_Model):
    """Gløersen & Federolf's PCA reconstruction over one hand's markers ``(F, M, 3)`` (metres).

    The components are those of the frames where every marker is seen (centred; enough of them to
    hold :data:`PCA_ENERGY` of the variance). A frame is fitted to them on the coordinates of the
    other markers seen there by least squares (one solve per pattern of seen markers), and marker
    ``m`` read off the fit.
    """

    def __init__(self, markers: np.ndarray, energy: float = PCA_ENERGY) -> None:
        f, m, _ = markers.shape
        self.x = markers.reshape(f, 3 * m)
        self.seen = np.isfinite(self.x)
        self.markers_seen = self.seen[:, 0::3]
        complete = self.seen.all(axis=1)
        self.ok = complete.sum() >= 2
        if self.ok:
            self.mean = self.x[complete].mean(axis=0)
            _, s, vt = np.linalg.svd(self.x[complete] - self.mean, full_matrices=False)
            share = np.cumsum(s ** 2) / max(float(np.sum(s ** 2)), 1e-30)
            k = int(np.searchsorted(share, energy) + 1)
            self.basis = vt[:k].T  # (3M, k)

    def _available(self, m: int) -> np.ndarray:
        if not self.ok:
            return np.zeros(len(self.x), dtype=bool)
        return (self.markers_seen.sum(axis=1) - self.markers_seen[:, m]) * 3 > self.basis.shape[1]

    def predict(self, m: int, frames: np.ndarray, start: int, stop: int, held_out: bool = False) -> np.ndarray:
        out = np.full((len(frames), 3), np.nan)
        if not self.ok or not len(frames):
            return out
        seen = self.markers_seen[frames].copy()
        seen[:, m] = False
        keys, which = np.unique(seen @ (1 << np.arange(seen.shape[1], dtype=np.int64)), return_inverse=True)
        maps = np.stack([self._map(m, int(key)) for key in keys])  # (U, 3, 3M)
        centred = np.nan_to_num(self.x[frames] - self.mean)
        out = np.einsum("fij,fj->fi", maps[which.ravel()], centred) + self.mean[3 * m:3 * m + 3]
        out[~np.isfinite(maps[which.ravel(), 0, 0])] = np.nan
        return out

    def _map(self, m: int, key: int) -> np.ndarray:
        """``(3, 3M)``: marker ``m`` (centred) from the centred coordinates of the markers in the
        bit mask ``key`` (zero columns for the others); NaN when they are too few (kept per pair)."""
        maps = self.__dict__.setdefault("_maps", {})
        if (m, key) not in maps:
            n_m = self.markers_seen.shape[1]
            use = np.repeat((key >> np.arange(n_m)) & 1 == 1, 3)
            k = self.basis.shape[1]
            out = np.zeros((3, 3 * n_m))
            if use.sum() <= k:
                out[:] = np.nan
            else:
                b = self.basis[use]
                out[:, use] = self.basis[3 * m:3 * m + 3] @ np.linalg.solve(b.T @ b + 1e-12 * np.eye(k), b.T)
            maps[m, key] = out
        return maps[m, key]


class PoseFill(_Model):
    """Marker ``m`` read off the pose of the hand's other markers ``(F, M, 3)`` (metres).

    The predictors are the other markers seen in every frame of the gap (and in most frames near
    it). In each frame they and ``m`` are carried into the hand's own frame: the Kabsch fit of the
    predictors onto their mean shape. There ``m`` is a linear function of the predictors'
    coordinates (their principal components holding :data:`POSE_ENERGY` of the variance, least
    squares), learned from the frames within :data:`POSE_WINDOW` seconds of the gap where all are
    seen (less the test windows, when those are asked for: they are predicted out of sample, as
    the gap is).
    """

    smooth = True

    def __init__(self, markers: np.ndarray, rate: float) -> None:
        self.x, self.rate = markers, rate
        self.valid = np.isfinite(markers[..., 0])

    def _available(self, m: int) -> np.ndarray:
        return self.valid.sum(axis=1) - self.valid[:, m] >= MIN_PARTNERS

    def _in_hand(self, shape: np.ndarray, frames: np.ndarray, cols: np.ndarray):
        """The hand's frame in ``frames`` (rotations ``(n, 3, 3)``, translations ``(n, 3)``), from
        ``cols`` fitted to ``shape (len(cols), 3)``, and the ``cols`` in it ``(n, len(cols), 3)``."""
        seen = self.valid[frames][:, cols]
        at = np.nan_to_num(self.x[frames][:, cols])
        rot, t = kabsch(shape, at, seen.astype(float))
        return rot, t, (at - t[:, None]) @ rot  # R^T (x - t)

    def _learned(self, m: int, start: int, stop: int) -> tuple | None:
        """For the gap ``[start, stop)`` of marker ``m``: the predictors' columns, their mean shape,
        the frames learned from, and there the predictors ``(n, 3 * len(cols))`` and ``m`` ``(n, 3)``
        in the hand's frame; None when too few (kept for the gap's two predictions)."""
        if self.__dict__.get("_key") == (m, start, stop):
            return self._gap
        valid, w = self.valid, int(POSE_WINDOW * self.rate)
        near = np.r_[max(0, start - w):start, stop:min(len(valid), stop + w)]
        near = near[valid[near, m]]
        gap_seen = valid[start:stop].all(axis=0)
        gap_seen[m] = False
        cols = np.flatnonzero(gap_seen & (valid[near].mean(axis=0) > 0.5)) if len(near) else []
        gap = None
        if len(cols) >= MIN_PARTNERS:
            # neighbouring frames teach little more than one of them
            learn = _evenly(near[valid[near][:, cols].all(axis=1)], POSE_FRAMES)
            if len(learn) >= MIN_LEARN:
                shape = self.x[learn][:, cols].mean(axis=0)
                rot, t, local = self._in_hand(shape, learn, cols)
                target = ((self.x[learn, m] - t)[:, None] @ rot)[:, 0]
                gap = cols, shape, learn, local.reshape(len(learn), -1), target
        self._key, self._gap = (m, start, stop), gap
        return gap

    def predict(self, m: int, frames: np.ndarray, start: int, stop: int, held_out: bool = False) -> np.ndarray:
        out = np.full((len(frames), 3), np.nan)
        gap = self._learned(m, start, stop)
        if gap is None:
            return out
        cols, shape, learn, features, target = gap
        if held_out:
            keep = ~np.isin(learn, frames)
            if keep.sum() < MIN_LEARN:
                return out
            features, target = features[keep], target[keep]
        mean_f, mean_y = features.mean(axis=0), target.mean(axis=0)
        centred = features - mean_f
        # least squares on the principal components (normal equations: 3 * len(cols) <= 3M unknowns)
        val, vec = np.linalg.eigh(centred.T @ centred)
        val, vec = val[::-1], vec[:, ::-1]
        share = np.cumsum(val) / max(float(val.sum()), 1e-30)
        k = min(int(np.searchsorted(share, POSE_ENERGY) + 1), len(features) // 4, int(np.sum(val > 1e-18 * val[0])))
        coef = vec[:, :k] @ ((vec[:, :k].T @ (centred.T @ (target - mean_y))) / val[:k, None])  # (3 * len(cols), 3)
        rot, t, local = self._in_hand(shape, frames, cols)
        pred = (rot @ ((local.reshape(len(frames), -1) - mean_f) @ coef + mean_y)[..., None])[..., 0] + t
        ok = self.valid[frames][:, cols].all(axis=1)
        out[ok] = pred[ok]
        return out


# --- meeting the observed samples, and the error estimates -----------------------------------------

def _slope(frames: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Least-squares slope per frame of ``values (n, 3)`` over ``frames (n,)`` (0 for one sample)."""
    if len(frames) < 2:
        return np.zeros(3)
    t = frames - frames.mean()
    return (t @ (values - values.mean(axis=0))) / float(t @ t)


def _fade(tau: np.ndarray, width: float) -> np.ndarray:
    """``g(tau)`` for frames ``tau`` from a gap's end: g(0) = 0, g(1) = 1 (the first step into the gap
    takes the whole velocity offset), g = g' = 0 from ``width`` on (a cubic); at most about 4/27
    ``width``."""
    tau = np.minimum(tau, width)
    return (tau * (1 - tau / width) ** 2 / (1 - 1 / width) ** 2)[:, None]


def _carried_out(inner: np.ndarray, before: np.ndarray, after: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A model's values ``before``, ``after`` ``(k, 3)`` a gap that it fills with ``inner (n, 3)``,
    at an end where it has none next to the gap (its partners unseen there) carried straight out
    of the gap: the continuation of its first (last) two frames inside."""
    n, k = len(inner), len(before)
    before, after = before.copy(), after.copy()
    steps = np.arange(1, k + 1)[:, None]
    if not np.isfinite(before[-1]).all():
        step = inner[1] - inner[0] if n >= 2 else np.zeros(3)
        before[:] = inner[0] - steps[::-1] * step
    if not np.isfinite(after[0]).all():
        step = inner[-2] - inner[-1] if n >= 2 else np.zeros(3)
        after[:] = inner[-1] - steps * step
    return before, after


def _end_correction(x: np.ndarray, inner: np.ndarray, ends: tuple[np.ndarray, np.ndarray], before: np.ndarray,
                    after: np.ndarray, valid: np.ndarray, start: int, stop: int,
                    rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The correction ``(n, 3)`` that makes a model's ``inner (n, 3)`` fill of the gap ``[start,
    stop)`` of marker ``x (F, 3)`` meet it in position and velocity at both ends; and the model's
    offsets from the marker at the two ends ``(3,)`` each.

    ``ends``: the model at the last frame before the gap and the first after it; ``before``,
    ``after``: the model in the :data:`SLOPE_SAMPLES` frames before and after the gap
    ``(SLOPE_SAMPLES, 3)`` (NaN where it has none). The offsets from the marker at the two ends are
    blended with a smoothstep (no velocity added); each end's velocity offset (a line through up
    to :data:`SLOPE_SAMPLES` offsets) is added by :func:`_fade` within :data:`VELOCITY_BLEND`
    seconds.
    """
    n, k = stop - start, SLOPE_SAMPLES
    a, b = start - 1, stop
    da, db = x[a] - ends[0], x[b] - ends[1]
    ka, kb = _run_before(valid, start, k), _run_after(valid, stop, k)
    fa, fb = np.arange(start - ka, start), np.arange(stop, stop + kb)
    off_a, off_b = x[fa] - before[k - ka:], x[fb] - after[:kb]
    good_a, good_b = np.isfinite(off_a[:, 0]), np.isfinite(off_b[:, 0])
    sa, sb = _slope(fa[good_a], off_a[good_a]), _slope(fb[good_b], off_b[good_b])
    t = np.arange(start, stop)
    u = (t - a) / (n + 1)
    smooth = (3 * u ** 2 - 2 * u ** 3)[:, None]
    width = min(float(n + 1), max(3.0, VELOCITY_BLEND * rate))
    return da * (1 - smooth) + db * smooth + sa * _fade(t - a, width) - sb * _fade(b - t, width), da, db


#: Share of the change of a model's offset from one end of the gap to the other counted (halved)
#: into its expected error.
END_SHARE = 1.0
#: Fewest frames a rigid fill's template is taken from near the gap, and the most (spread evenly).
MIN_REFERENCE, MAX_REFERENCE = 5, 64


def _tests(ok: np.ndarray, start: int, stop: int, pad: int, span: int, most: int = TESTS) -> np.ndarray:
    """Up to ``most`` frames ``c``, spread near the gap ``[start, stop)`` (within ``span``
    frames), where ``ok[c - pad : c + n + pad]`` holds throughout (n = the gap's length)."""
    n = stop - start
    cs = np.concatenate([[0], np.cumsum(ok)])
    c = np.arange(max(pad, start - span), min(len(ok) - n - pad, stop + span) + 1)
    return _evenly(c[cs[c + n + pad] - cs[c - pad] == n + 2 * pad], most)


def _evenly(frames: np.ndarray, most: int) -> np.ndarray:
    """At most ``most`` of ``frames``, evenly spread, the first and last kept (the nearest to even
    steps: :func:`.hands._spread`'s twin rounds down, and its picks are the labeler's)."""
    if len(frames) <= most:
        return frames
    return frames[np.linspace(0, len(frames) - 1, most).round().astype(int)]


def _test_points(n: int, most: int = TEST_POINTS) -> np.ndarray:
    """Frames ``(k,)`` of a gap of ``n`` frames (0-based, ascending) where a test window's error is measured."""
    return np.unique(np.linspace(0, n - 1, min(n, most)).round().astype(int))


def _smoothstep(n: int) -> np.ndarray:
    """``(n,)``: the position blend of :func:`_end_correction` over a gap of ``n`` frames."""
    u = np.arange(1, n + 1) / (n + 1)
    return 3 * u ** 2 - 2 * u ** 3


def _shape(n: int) -> np.ndarray:
    """``(n,)``: how far into a gap of ``n`` frames each frame is, 0 at the ends to 1 in the middle."""
    u = np.arange(1, n + 1) / (n + 1)
    return np.sqrt(4 * u * (1 - u))


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
    lo, hi = max(h, start - span), min(len(valid) - h, stop + span)
    near = np.arange(lo, hi)
    near = near[valid[near] & valid[near - h] & valid[near + h]]
    accel = 0.0
    if len(near):
        accel = float(np.median(np.linalg.norm(x[near + h] - 2 * x[near] + x[near - h], axis=1))) * (rate / h) ** 2
    t = np.arange(start, stop)
    return NOISE + 0.5 * accel * (t - start + 1) * (stop - t) / rate ** 2


#: Frames of the median and of the Savitzky-Golay filter that smooth a per-frame model's course
#: (real glove recording, 0.25-2 s gaps: pose median error 0.51 -> 0.47 mm, steps at the gaps'
#: ends of 0.5 mm or more beyond the marker's own: 5 -> 2 of 156).
SPIKE_FRAMES, SMOOTH_FRAMES = 5, 7


def _smooth(track: np.ndarray, window: int) -> np.ndarray:
    """``track (n, 3)`` of consecutive frames with each run of finite samples of at least ``window``
    frames smoothed: a median over :data:`SPIKE_FRAMES` frames (a one-frame spike gone), then
    Savitzky-Golay over ``window`` frames (quadratic: a motion of constant acceleration passes)."""
    from scipy.ndimage import median_filter

    out = track.copy()
    fit, h = _quadratic_fit(window), window // 2
    _, starts, stops = mask_runs(np.isfinite(track[:, :1]))
    for a, b in zip(starts, stops):
        if b - a >= window:
            run = median_filter(track[a:b], size=(SPIKE_FRAMES, 1), mode="nearest")
            # scipy's savgol_filter(mode="interp"), whose ends' polynomial fits cost 20 times the rest
            out[a + h:b - h] = np.lib.stride_tricks.sliding_window_view(run, window, axis=0) @ fit[h]
            out[a:a + h] = fit[:h] @ run[:window]
            out[b - h:b] = fit[window - h:] @ run[-window:]
    return out


@functools.cache
def _quadratic_fit(window: int) -> np.ndarray:
    """``(window, window)``: a quadratic's least-squares fit through ``window`` consecutive samples,
    at each of them."""
    v = np.vander(np.arange(window, dtype=float), 3)
    return v @ np.linalg.pinv(v)


def _plan(model: _Model, m: int, valid: np.ndarray, start: int, stop: int,
          rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The frames a model's fill of the gap ``[start, stop)`` of marker ``m`` (seen where ``valid
    (F,)``) asks it for: ``around``, the gap and :data:`SLOPE_SAMPLES` frames each side; and its
    test windows: their first frames inside ``c``, the points measured in each ``inside`` (0-based
    in the gap), and ``windows``, every window's frames in order (the one before its gap, the
    points, the one after it)."""
    n, k = stop - start, SLOPE_SAMPLES
    around = np.clip(np.arange(start - k, stop + k), 0, len(valid) - 1)
    c = _tests(valid & model.available(m), start, stop, 1, max(int(NEAR * rate), 2 * n), model.tests)
    inside = _test_points(n, model.test_points)
    return around, c, inside, (c[:, None] + np.concatenate([[-1], inside, [n]])).ravel()


def _model_fill(model: _Model, m: int, x: np.ndarray, valid: np.ndarray, start: int, stop: int,
                rate: float) -> tuple[np.ndarray, np.ndarray]:
    """A model's fill ``(n, 3)`` of the gap and its expected error ``(n,)``; :class:`NoFill` says
    why it has none.

    The expected error per sample: how far the model's offset from the marker strays from its
    blend between the ends over gaps of the same length hidden near this one (RMS; a rigid or PCA
    model predicts the marker there as in a gap). Added in quadrature (shaped by :func:`_shape`):
    half of :data:`END_SHARE` of the change of its offset from one end of this gap to the other.
    """
    n = stop - start
    ok = model.available(m)
    if not ok[start:stop].all():
        raise NoFill("no model in every frame of the gap")
    around, c, inside, windows = _plan(model, m, valid, start, stop, rate)
    k = SLOPE_SAMPLES
    pred = model.predict(m, around, start, stop)
    tried = np.zeros((0, 3))
    if len(c):
        frames, back = np.unique(windows, return_inverse=True)
        tried = model.predict(m, frames, start, stop, held_out=True)[back.ravel()]
    if model.smooth:
        pred = _smooth(pred, SMOOTH_FRAMES)
    inner = pred[k:k + n]
    if not np.isfinite(inner).all():
        raise NoFill("no model in every frame of the gap")
    before, after = pred[:k], pred[k + n:2 * k + n]
    before, after = _carried_out(inner, before, after)
    corr, da, db = _end_correction(x, inner, (before[-1], after[0]), before, after, valid, start, stop, rate)
    spread = np.zeros(n)
    if len(c):
        offset = (x[windows] - tried).reshape(len(c), len(inside) + 2, 3)
        good = np.isfinite(offset).all(axis=(1, 2))
        if good.any():
            s = _smoothstep(n)[inside][None, :, None]
            off = offset[good]
            err = np.linalg.norm(off[:, 1:-1] - (off[:, :1] * (1 - s) + off[:, -1:] * s), axis=2)
            spread = np.interp(np.arange(n), inside, np.sqrt(np.mean(err ** 2, axis=0)))
    # its offset is its own in the test windows too; a change across the gap is a doubt
    missed = END_SHARE * 0.5 * np.linalg.norm(db - da) * _shape(n)
    return inner + corr, NOISE + np.sqrt(spread ** 2 + missed ** 2)


# --- the fill ---------------------------------------------------------------------------------------

def fill_markers(markers: np.ndarray, rate: float, method: str = "auto", max_gap: float = MAX_GAP,
                 solver: HandSolver | None = None, poses: np.ndarray | None = None,
                 partners: list[np.ndarray] | None = None, names: list[str] | None = None) -> Filled:
    """Fill the gaps of one hand's labeled markers.

    Args:
        markers: ``(F, M, 3)`` metres, NaN where missing.
        rate: frames per second.
        method: one of :data:`METHODS`.
        max_gap: seconds; longer gaps are left open.
        solver, poses: the calibrated hand and its solve's poses ``(F, 26)`` (NaN rows where
            unsolved), for ``hand`` (:class:`HandFill`).
        partners: per marker, int columns of the markers that move rigidly with it, for ``rigid``.
        names: marker names for the gaps (default ``"0"``, ``"1"``...).

    Returns:
        :class:`Filled`; observed samples are copied unchanged.
    """
    wanted = fill_method(method).tries
    markers = np.asarray(markers, dtype=float)
    n_f, n_m, _ = markers.shape
    names = names or [str(i) for i in range(n_m)]
    valid = np.isfinite(markers[..., 0])
    out = markers.copy()
    filled = np.zeros((n_f, n_m), dtype=bool)
    error = np.full((n_f, n_m), np.nan)
    models: dict[str, _Model | str] = {
        "hand": HandFill(solver, poses, markers, rate) if solver is not None and poses is not None else "no hand solve",
        "rigid": RigidFill(markers, partners, rate) if partners is not None else "no rigid partners given",
    }
    found = find_gaps(valid)
    hand = models["hand"]
    if "hand" in wanted and isinstance(hand, HandFill):
        hand.prepare([(m, a, b) for m, a, b in found if not _left_open(a, b, n_f, rate, max_gap)])
    gaps = []
    for m, start, stop in found:
        gap = Gap(m, names[m], start, stop)
        gaps.append(gap)
        gap.reason = _left_open(start, stop, n_f, rate, max_gap)
        if gap.reason:
            continue
        best, why = None, []
        for name in wanted:
            try:
                got = _fill_with(name, models, markers, m, valid, start, stop, rate, partners)
            except NoFill as exc:
                why.append(f"{name}: {exc}" if len(wanted) > 1 else str(exc))
                continue
            if best is None or got[1].mean() < best[2].mean():
                best = (name, *got)
        if best is None:
            gap.reason = "; ".join(dict.fromkeys(why))
            continue
        gap.method, fill, err = best
        out[start:stop, m] = fill
        filled[start:stop, m] = True
        error[start:stop, m] = err
        gap.error, gap.max_error = float(err.mean()), float(err.max())
    return Filled(out, filled, error, gaps)


def _fill_with(name: str, models: dict, markers: np.ndarray, m: int, valid: np.ndarray, start: int, stop: int,
               rate: float, partners) -> tuple[np.ndarray, np.ndarray]:
    """Gap ``[start, stop)`` of marker ``m`` filled by model ``name`` and its expected error;
    :class:`NoFill` where the model cannot fill it (``models`` holds the take's models, or why
    there is none, made when a gap first asks)."""
    x = markers[:, m]
    if name == "spline":
        return spline_fill(x, valid[:, m], start, stop), spline_error(x, valid[:, m], start, stop, rate)
    if name not in models:
        models[name] = PCAFill(markers) if name == "pca" else PoseFill(markers, rate)
    model = models[name]
    if isinstance(model, str):
        raise NoFill(model)
    if name == "rigid" and len(partners[m]) < MIN_PARTNERS:
        raise NoFill(f"fewer than {MIN_PARTNERS} rigid partners")
    return _model_fill(model, m, x, valid[:, m], start, stop, rate)


def _left_open(start: int, stop: int, frames: int, rate: float, max_gap: float) -> str:
    """Why the gap ``[start, stop)`` of a take of ``frames`` frames is left open whatever the
    method ("" when a method may fill it)."""
    if start == 0 or stop == frames:
        return ("never seen" if start == 0 and stop == frames else
                "at the start of the take" if start == 0 else "at the end of the take")
    if stop - start > int(np.floor(max_gap * rate + 1e-9)):
        return f"longer than max_gap ({(stop - start) / rate:.2f} s > {max_gap:g} s)"
    return ""


class GapFills:
    """One hand's markers and the models that fill their gaps, asked one gap and one model at a
    time: the fills, expected errors and reasons of :func:`fill_markers` (the same models and
    code), for a preview that shows them gap by gap (:class:`.cleanup.FillPreview`).

    Args:
        markers: ``(F, M, 3)`` metres, NaN where missing.
        rate: frames per second.
        solver, poses: the calibrated hand and its solve's poses ``(F, 26)``, for ``hand``.
        partners: per marker, int columns of the markers that move rigidly with it, for ``rigid``.
    """

    def __init__(self, markers: np.ndarray, rate: float, *, solver: HandSolver | None = None,
                 poses: np.ndarray | None = None, partners: list[np.ndarray] | None = None) -> None:
        self.markers = np.asarray(markers, dtype=float)
        self.rate, self.partners = rate, partners
        self.valid = np.isfinite(self.markers[..., 0])
        self.models: dict[str, _Model | str] = {
            "hand": HandFill(solver, poses, self.markers, rate) if solver is not None and poses is not None
            else "no hand solve",
            "rigid": RigidFill(self.markers, partners, rate) if partners is not None else "no rigid partners given",
        }

    def open_reason(self, start: int, stop: int, max_gap: float) -> str:
        """Why the gap ``[start, stop)`` is left open whatever the method ("" when one may fill it)."""
        return _left_open(start, stop, len(self.markers), self.rate, max_gap)

    def prepare(self, gaps: list[tuple[int, int, int]]) -> None:
        """Solve in one batch what hand fills of ``gaps`` ``(marker, start, stop)`` will ask for (as
        :func:`fill_markers` does before its gaps; optional: a fill solves what it lacks)."""
        hand = self.models["hand"]
        if isinstance(hand, HandFill):
            hand.prepare(gaps)

    def fill(self, model: str, marker: int, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """The gap ``[start, stop)`` of ``marker`` filled by ``model`` (a name of ``auto``'s kind:
        ``spline``, ``rigid``, ``hand``, ``pca``, ``pose``): ``(n, 3)`` metres and the expected
        error ``(n,)`` metres. Raises :class:`NoFill` (why) where it cannot."""
        return _fill_with(model, self.models, self.markers, marker, self.valid, start, stop, self.rate,
                          self.partners)

    def donors(self, model: str, marker: int, start: int, stop: int) -> np.ndarray:
        """int ``(k,)``: the other markers ``model``'s fill of the gap ``[start, stop)`` of ``marker``
        is computed from: none for ``spline`` (the marker's own samples), the rigid partners seen in
        the gap for ``rigid``, the pose's predictors for ``pose``, every other marker seen in the gap
        for ``hand`` and ``pca``."""
        seen = self.valid[start:stop].any(axis=0)
        seen[marker] = False
        if model == "spline":
            return np.zeros(0, dtype=np.int64)
        if model == "rigid":
            mine = np.asarray(self.partners[marker] if self.partners is not None else [], dtype=np.int64)
            return mine[seen[mine]]
        if model == "pose":
            pose = self.models.get("pose")
            if not isinstance(pose, PoseFill):
                pose = self.models["pose"] = PoseFill(self.markers, self.rate)
            learned = pose._learned(marker, start, stop)
            return np.zeros(0, dtype=np.int64) if learned is None else np.asarray(learned[0], dtype=np.int64)
        return np.flatnonzero(seen)


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
        solves: ``[(side, HandSolve)]`` the fill used (solved here where none was given), or None.
    """

    take: Take
    gaps: list[Gap]
    method: str
    max_gap: float
    seconds: dict
    solves: list | None = None

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
              solves: list | None = None, naming=None, calibrate: bool = True, **solve_options) -> TakeFill:
    """Fill the gaps of every labeled hand of ``take`` (one hand with plain layout names, or two
    named by side, :func:`.hands.hands_in_names`); other points are left as they are.

    Args:
        take: a labeled take (metres).
        layout: its marker layout.
        method: one of :data:`METHODS`.
        max_gap: seconds; longer gaps are left open.
        solves: ``[(side, HandSolve)]`` as :func:`.solve.solve_hands` gives for this take; None
            solves here when the method may use the hand (``hand``, ``auto``); ``[]``: no hand.
        naming: how two hands' names carry their side (:class:`.hands.HandNaming`).
        calibrate: a hand with no calibration in ``solve_options["calibrations"]`` is calibrated
            on the take; False: without a calibration for every hand the fill goes without the
            hand (``hand`` refuses).
        solve_options: passed to :func:`.solve.solve_hands` when solving here.

    Raises:
        MocapInputError: the take is not labeled with ``layout``; or a bad ``method`` / ``max_gap``.
    """
    from .hands import hands_in_names, split_hands

    if method not in FILL_METHODS:
        raise MocapInputError(take.source, f"unknown fill method {method!r} (one of {', '.join(FILL_METHODS)})")
    if not max_gap > 0:
        raise MocapInputError(take.source, f"max_gap must be positive seconds, got {max_gap}")
    split_hands(take, layout, naming)  # a take that is not labeled with the layout: one clear error
    found = hands_in_names(take.names, layout, naming)
    seconds = {}
    if solves is None and fill_method(method).uses_hand:  # the one place of "solve the hand before the fill"
        calibrations = solve_options.get("calibrations") or {}
        if calibrate or set(found) <= set(calibrations):
            t0 = time.perf_counter()
            solves = solve_hands(take, layout, naming, **solve_options)
            seconds["solve"] = round(time.perf_counter() - t0, 4)
        elif fill_method(method).needs_hand:
            raise MocapInputError(take.source, "has no solved hand to fill from: Solve Hand first (or use another "
                                               "method)")
    by_side = dict(solves or [])
    t0 = time.perf_counter()
    partners = layout_partners(layout)
    positions = take.positions.copy()
    was = np.zeros(take.valid.shape, dtype=bool) if take.filled is None else take.filled.copy()
    gaps = []
    for side, cols in found.items():
        one = by_side.get(side)
        hand = {} if one is None else {"solver": one.solver(), "poses": one.fit.poses}
        result = fill_markers(take.positions[:, cols], take.rate, method, max_gap, partners=partners,
                              names=[take.names[c] for c in cols], **hand)
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
    return TakeFill(out, gaps, method, max_gap, seconds, solves)


# --- a kept hand solve brought up to date for the fill --------------------------------------------

#: Seconds solved again on either side of the frames whose markers changed since a kept solve. The
#: new poses are spliced in at a cut in the inner half of each margin, at the frame where the new and
#: the kept solve agree best (two solves of the same markers may settle differently for a while where
#: the fit is loose: on the real glove recording, a marker hidden for 0.3-0.6 s in four places, up to
#: 6 mm apart at a fixed cut, at most 0.03 mm at the chosen one, within 0.1 mm RMS of a whole solve
#: inside); the outer half lets the new solve's cold start and low-pass filter settle.
SOLVE_PAD_S = 0.5
#: Fewest frames of that margin.
MIN_SOLVE_PAD = 16
#: Where the frames solved again would exceed this share of the take, it is solved whole (with the
#: kept calibration).
RESOLVE_SHARE = 0.5


def frame_digests(observed: np.ndarray) -> np.ndarray:
    """int32 ``(F,)``: a digest of each frame's markers ``observed (F, M, 3)`` (every missing sample
    alike), so that a kept solve tells the frames it was solved from apart from changed ones (a
    label moved, a correction, another trajectory)."""
    import hashlib

    x = np.ascontiguousarray(observed, dtype=np.float64).reshape(len(observed), -1)
    x = np.where(np.isnan(x), np.nan, x)  # one bit pattern for every missing sample
    raw = b"".join(hashlib.blake2b(row.tobytes(), digest_size=4).digest() for row in x)
    return np.frombuffer(raw, dtype="<i4").astype(np.int32)


def solve_digests(take: Take, layout: Layout, naming=None) -> dict[str, np.ndarray]:
    """Per side (``""`` for a take with plain names), :func:`frame_digests` of the markers a solve of the
    labeled ``take`` sees: what a solved rig keeps, so that Fill Gaps reuses the solve while the labels
    give the same markers. ``naming``: the take's :class:`..hands.HandNaming` (None: any built-in)."""
    from .hands import split_hands
    from .labeling import layout_markers

    return {side: frame_digests(layout_markers(one, layout)) for side, one in split_hands(take, layout, naming)}


def digests_fingerprint(digests: np.ndarray) -> str:
    """A short hex fingerprint of a whole take's :func:`frame_digests`."""
    import hashlib

    return hashlib.blake2b(np.asarray(digests, dtype="<i4").tobytes(), digest_size=8).hexdigest()


@dataclass
class KeptSolve:
    """A hand solve kept with a take (a scene keeps it on the solved rig).

    Attributes:
        calibration: the performer's calibration it was solved with.
        poses: ``(F, 26)`` its poses, NaN rows where unsolved; None: not kept (solved again whole).
        digests: :func:`frame_digests` of the markers it was solved from; None: unknown (solved
            again whole).
        smooth_hz: the low-pass cut-off it was solved with.
    """

    calibration: object
    poses: np.ndarray | None = None
    digests: np.ndarray | None = None
    smooth_hz: float = 10.0


def _changed_windows(changed: np.ndarray, pad: int) -> list[tuple[int, int, int, int]]:
    """``[(window start, first changed, last changed + 1, window stop)]``: the runs of ``changed (F,)``,
    those closer than two margins merged, each in a window of ``2 * pad`` frames more on either side
    (clipped to the take)."""
    n = len(changed)
    _, starts, stops = mask_runs(np.asarray(changed, dtype=bool)[:, None])
    runs: list[list[int]] = []
    for a, b in zip(starts.tolist(), stops.tolist()):
        if runs and a - runs[-1][1] < 4 * pad:
            runs[-1][1] = b
        else:
            runs.append([a, b])
    return [(max(0, a - 2 * pad), a, b, min(n, b + 2 * pad)) for a, b in runs]


def _best_cut(old: np.ndarray, new: np.ndarray, lo: int, hi: int, default: int) -> int:
    """Of frames ``[lo, hi)``, the one where the markers ``old`` and ``new`` ``(F, M, 3)`` of two solves
    are closest (the largest marker distance; a frame solved in one only is worst, in neither best);
    ``default`` where the range is empty."""
    if hi <= lo:
        return default
    idx = np.arange(lo, hi)
    gap = np.linalg.norm(old[idx] - new[idx], axis=-1)
    one_only = np.isnan(old[idx, :, 0]) != np.isnan(new[idx, :, 0])
    gap = np.where(one_only, np.inf, np.nan_to_num(gap, nan=0.0)).max(axis=1)
    return int(idx[np.argmin(gap)])


def update_solve(kept: KeptSolve, take: Take, layout: Layout,
                 progress: Callable[[str, float], None] | None = None) -> tuple[HandSolve, np.ndarray, dict]:
    """The hand of a one-hand labeled ``take`` (one hand of :func:`.hands.split_hands`) solved as
    ``kept`` was, without solving again what did not change.

    Frames whose markers are the ones the kept solve saw (:func:`frame_digests`) keep its poses.
    Around the frames that changed, :data:`SOLVE_PAD_S` seconds twice over on either side, the hand
    is solved again with the kept calibration, and the new poses replace the kept ones between a cut
    on either side of the change (see :data:`SOLVE_PAD_S`). Without kept poses or digests, with
    another frame count, or where the windows would cover more than :data:`RESOLVE_SHARE` of the
    take, it is solved whole with the kept calibration.

    Returns:
        ``(HandSolve, digests, facts)``: the solve, the digests of ``take``'s frames, and
        ``{"solved_frames", "stretches": [[start, stop]], "seconds"}``: how many frames were solved
        again and the 0-based frame ranges whose poses changed (none when no marker changed).
    """
    say = progress or (lambda _message, _share: None)
    t0 = time.perf_counter()
    observed = layout_markers(take, layout)
    digests = frame_digests(observed)
    n = len(observed)
    whole = (kept.poses is None or kept.digests is None or len(kept.poses) != n or len(kept.digests) != n)
    windows: list[tuple[int, int, int, int]] = []
    pad = max(MIN_SOLVE_PAD, int(round(SOLVE_PAD_S * take.rate)))
    if not whole:
        windows = _changed_windows(np.asarray(kept.digests) != digests, pad)
        whole = sum(d - a for a, _, _, d in windows) > RESOLVE_SHARE * n
    if whole:
        one = solve_take(take, layout, calibration=kept.calibration, smooth_hz=kept.smooth_hz, progress=say)
        facts = {"solved_frames": n, "stretches": [[0, n]], "seconds": round(time.perf_counter() - t0, 4)}
        return one, digests, facts
    solver = kept.calibration.solver(layout)
    poses = np.array(kept.poses, dtype=float)
    old = solver.evaluate(poses, observed).markers if windows else None
    total, done, stretches = max(1, sum(d - a for a, _, _, d in windows)), 0, []
    for wa, a, b, wb in windows:
        say("solving the changed frames", done / total)
        part = solver.solve(observed[wa:wb], rate=take.rate, smooth_hz=kept.smooth_hz,
                            progress=lambda share, d=done, w=wb - wa: say(
                                f"solving the changed frames ({100 * (d + share * w) / total:.0f} %)",
                                (d + share * w) / total))
        new = np.full_like(old, np.nan)
        new[wa:wb] = part.markers
        # The new poses from the unchanged frame before the change where both solves agree best to
        # the one after it, at least half a margin inside the window (a window that starts or ends
        # the take starts or ends it as the whole solve does: no margin needed there).
        cut_a = _best_cut(old, new, wa if wa == 0 else wa + pad // 2, a, a)
        cut_b = _best_cut(old, new, b, n if wb == n else wb - pad // 2, b - 1) + 1
        poses[cut_a:cut_b] = part.poses[cut_a - wa:cut_b - wa]
        stretches.append([cut_a, cut_b])
        done += wb - wa
    fit = solver.evaluate(poses, observed)
    seconds = round(time.perf_counter() - t0, 4)
    one = HandSolve(kept.calibration, fit, layout, float(take.rate), int(take.first_frame), {"solve": seconds}, solver)
    return one, digests, {"solved_frames": int(sum(d - a for a, _, _, d in windows)), "stretches": stretches,
                          "seconds": seconds}
