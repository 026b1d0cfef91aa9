"""Solving the hand: a labeled take to a calibrated hand fitted in every frame (one per side)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from .cache import RunCache
from .errors import MocapInputError
from .hand.calibrate import Calibration, calibrate
from .hand.ik import GATE, MIN_MARKERS, Fit, HandSolver
from .hand.skeleton import ImplausibleHand
from .hands import HandNaming, split_hands
from .labeling import layout_markers
from .layout import Layout
from .take import Take


@dataclass
class HandSolve:
    """A hand solved over a labeled take.

    Attributes:
        calibration: the performer's hand and markers it was solved with.
        fit: poses ``(F, 26)``, fitted markers and residuals per frame.
        layout: the marker layout.
        rate: frames per second; first_frame: the take's first frame number.
        seconds: wall time of each stage.
        hand_solver: the solver the fit came from; None: the calibration's (:meth:`solver`).
    """

    calibration: Calibration | None
    fit: Fit
    layout: Layout
    rate: float
    first_frame: int
    seconds: dict
    hand_solver: HandSolver | None = None

    def solver(self) -> HandSolver:
        """The calibrated hand and its markers, as solved."""
        if self.hand_solver is None:
            self.hand_solver = self.calibration.solver(self.layout)
        return self.hand_solver

    def report(self) -> dict:
        """Per-frame and overall marker RMS in millimetres, per-marker RMS, calibration, timings."""
        fit = self.fit
        rms = fit.rms * 1000
        gate = np.isfinite(rms) & (rms > GATE * 1000)
        per_marker = _per_marker_rms(fit) * 1000
        return {
            "layout": self.layout.name,
            "frames": len(rms),
            "solved_frames": int(fit.solved.sum()),
            "marker_rms_mm": round(fit.overall_rms() * 1000, 4),
            "frames_over_gate": int(gate.sum()),
            "gate_mm": GATE * 1000,
            "per_marker_rms_mm": {n: (round(float(v), 4) if np.isfinite(v) else None)
                                  for n, v in zip(self.layout.names, per_marker)},
            "per_frame_rms_mm": [round(float(v), 3) if np.isfinite(v) else None for v in rms],
            "calibration": self.calibration.to_dict(),
            "seconds": self.seconds,
        }


def _per_marker_rms(fit: Fit) -> np.ndarray:
    """``(M,)`` RMS residual of each marker over the solved frames that saw it, metres; NaN for a marker
    no solved frame saw. Sums and counts, not nanmean: a marker missing from the whole take (or from
    every solved frame) would make numpy warn "Mean of empty slice" on the console."""
    seen = fit.solved[:, None] & np.isfinite(fit.residuals)
    count = seen.sum(axis=0)
    total = np.where(seen, fit.residuals, 0.0) ** 2
    out = np.full(count.shape, np.nan)
    np.divide(total.sum(axis=0), count, out=out, where=count > 0)
    return np.sqrt(out)


class CalibrationKey:
    """The inputs of one calibration as a dictionary key: the layout, the labeled frames it is
    solved on (by value: equal when the positions are, NaN equal to NaN), the side asked for (None:
    detected), the flat-hand reference frames and the pinch contacts. :func:`calibrate` is
    deterministic, so equal keys give equal calibrations: a performer's hand, per side, from the
    same labeled data is calibrated once per :class:`~.cache.RunCache` (a Blender session, one batch
    run) and reused by every later solve of that data (a re-solve after a look, the other outputs).
    """

    __slots__ = ("layout", "observed", "side", "reference", "contacts", "_hash")

    def __init__(self, layout: Layout, observed: np.ndarray, side: str | None = None,
                 reference: Sequence[int] | None = None, contacts: Sequence[tuple[int, str]] = ()) -> None:
        obs = np.asarray(observed, dtype=float)
        # One byte pattern per value, so that equal keys hash equally: every NaN alike, -0.0 as 0.0.
        self.observed = np.where(np.isnan(obs), np.nan, obs + 0.0)
        self.layout, self.side = layout, side
        self.reference = None if reference is None else tuple(int(f) for f in reference)
        self.contacts = tuple((int(f), str(d)) for f, d in contacts)
        self._hash = hash((layout, side, self.reference, self.contacts, self.observed.shape,
                           self.observed.tobytes()))

    def __hash__(self) -> int:
        return self._hash

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, CalibrationKey):
            return NotImplemented
        return (self._hash == other._hash and self.layout == other.layout and self.side == other.side
                and self.reference == other.reference and self.contacts == other.contacts
                and self.observed.shape == other.observed.shape
                and np.array_equal(self.observed, other.observed, equal_nan=True))


def calibrate_once(cache: RunCache | None, observed: np.ndarray, layout: Layout, side: str | None = None,
                   reference: Sequence[int] | None = None, contacts: Sequence[tuple[int, str]] = (),
                   progress: Callable[[float], None] | None = None) -> tuple[Calibration, bool]:
    """:func:`calibrate` the performer's hand on ``observed (F, M, 3)``, or reuse the calibration
    ``cache`` holds for the same inputs (:class:`CalibrationKey`). Returns the calibration (a copy:
    the caller may change it) and whether it was reused. Without a cache it always calibrates."""
    def make() -> Calibration:
        return calibrate(observed, layout, side=side, contacts=contacts,
                         reference=None if reference is None else np.asarray(reference), progress=progress)

    if cache is None:
        return make(), False
    key = CalibrationKey(layout, observed, side, reference, contacts)
    made = []
    found = cache.remember("calibration", key, lambda: made.append(1) or make())
    return replace(found, offsets=found.offsets.copy(), names=list(found.names), frames=list(found.frames),
                   contacts={k: list(v) for k, v in found.contacts.items()}), not made


#: The share of a solve's time its calibration takes (measured on the demo and glove takes: 75-80 %,
#: before and after issue 48 made both parts 4-6 times faster).
CALIBRATE_SHARE = 0.75


def solve_take(take: Take, layout: Layout, calibration: Calibration | None = None,
               calibrate_seconds: float | None = None, reference: Sequence[int] | None = None,
               contacts: Sequence[tuple[int, str]] = (), side: str | None = None,
               smooth_hz: float = 10.0, progress: Callable[[str, float], None] | None = None,
               cache: RunCache | None = None) -> HandSolve:
    """Fit the hand to a labeled take: calibrate (unless given a calibration), then solve every frame.

    Args:
        take: a labeled take whose point names include every marker of ``layout``.
        layout: the marker layout.
        calibration: a performer's calibration to reuse; None calibrates on this take.
        calibrate_seconds: calibrate on the take's first seconds only (default: all of it).
        reference: frames (0-based) in which the hand is flat (see :func:`calibrate`).
        contacts: pinch frames ``(frame, finger)`` for the calibration (see :func:`calibrate`).
        side: ``left``/``right``; detected from the markers when None.
        smooth_hz: low-pass cut-off for the pose track (0: none).
        progress: called with a stage message and the share of the work done (0-1) as the solve
            goes (a calibration is about three quarters of it: 2.5 s of 3.1 s on the 1,200-frame
            demo take); it may raise to stop the solve (a cancelled :class:`~.jobs.Job` does).
        cache: the caller's run cache (a Blender session, a batch run): a calibration on the same
            labeled frames with the same options is made once in it and reused
            (:func:`calibrate_once`); None calibrates every time.
    """
    say = progress or (lambda _msg, _share: None)
    observed = layout_markers(take, layout)
    if not (np.isfinite(observed).all(axis=-1).sum(axis=1) >= MIN_MARKERS).any():
        raise MocapInputError(take.source, f"no frame shows {MIN_MARKERS} or more of the layout's markers")
    seconds = {}
    start = time.perf_counter()
    if calibration is None:
        say("calibrating the hand", 0.0)
        stop = len(observed) if calibrate_seconds is None else max(1, int(round(calibrate_seconds * take.rate)))
        bad = [f for f, _ in contacts if not 0 <= f < stop]
        if bad:
            raise MocapInputError(take.source, f"pinch frames {bad[:5]} lie outside the calibration frames "
                                               f"0-{stop - 1}")
        calibration, _ = calibrate_once(cache, observed[:stop], layout, side=side, reference=reference,
                                        contacts=contacts,
                                        progress=lambda done: say(f"calibrating the hand ({100 * done:.0f} %)",
                                                                  CALIBRATE_SHARE * done))
    else:
        calibration.check(layout, "calibration")
        if side is not None and side != calibration.side:
            raise MocapInputError("calibration", f"is for a {calibration.side} hand, not a {side} one")
    seconds["calibrate"] = round(time.perf_counter() - start, 4)
    start = time.perf_counter()
    share0 = CALIBRATE_SHARE if seconds["calibrate"] > 0.05 else 0.0  # where the frames' share starts
    say("solving frames", share0)
    solver = calibration.solver(layout)
    fit = solver.solve(
        observed, rate=take.rate, smooth_hz=smooth_hz,
        progress=lambda done: say(f"solving frames ({100 * done:.0f} %)", share0 + (1 - share0) * done))
    seconds["solve"] = round(time.perf_counter() - start, 4)
    return HandSolve(calibration, fit, layout, float(take.rate), int(take.first_frame), seconds, solver)


def solve_hands(take: Take, layout: Layout, naming: HandNaming | None = None,
                calibrations: dict[str, Calibration] | None = None,
                progress: Callable[[str, float], None] | None = None, **options) -> list[tuple[str, HandSolve]]:
    """Solve every hand of a labeled take: ``[(side, HandSolve)]``, side ``""`` for a take labeled
    with plain names (one hand), else ``"left"`` / ``"right"`` read off the names
    (:func:`.hands.split_hands`); each hand calibrated on its own (size, side, marker offsets)
    unless ``calibrations[side]`` is given (a calibration of the other side is not used).
    ``progress(message, share)`` hears each hand's stages (each hand about the same work);
    ``options`` go to :func:`solve_take` (``cache=`` a :class:`~.cache.RunCache` reuses each
    hand's calibration when the same labeled data is solved again)."""
    hands = split_hands(take, layout, naming)
    out = []
    for i, (side, one) in enumerate(hands):
        given = (calibrations or {}).get(side)
        if given is not None and side and given.side != side:
            given = None  # a calibration of the other hand: this one is calibrated on the take
        kwargs = dict(options)
        if side and kwargs.get("side") is None:
            kwargs["side"] = side
        if progress is not None:
            def per_hand(message: str, share: float, i: int = i, side: str = side) -> None:
                progress(f"{side} hand: {message}" if side else message, (i + share) / len(hands))

            kwargs["progress"] = per_hand
        try:
            out.append((side, solve_take(one, layout, calibration=given, **kwargs)))
        except MocapInputError as exc:
            raise MocapInputError(take.source, f"{side} hand: {exc.problem}" if side else exc.problem) from exc
        except ImplausibleHand as exc:  # the calibration ran off to a size no hand has: wrong labels
            hand = f"the {side} hand's" if side else "its"
            raise MocapInputError(take.source, f"{hand} labels fit no plausible hand (the calibration reached {exc}): "
                                               f"check that hand's labels and corrections") from exc
    return out


def as_rig(solves: list[tuple[str, HandSolve]] | None) -> HandSolve | list[tuple[str, HandSolve]] | None:
    """Solves as the scene writers take them: one :class:`HandSolve` for a plain one-hand take
    (side ``""``), else the ``[(side, HandSolve)]`` list; None for none."""
    if not solves:
        return None
    return solves[0][1] if [side for side, _ in solves] == [""] else solves


def as_solves(rig: HandSolve | list[tuple[str, HandSolve]] | None) -> list[tuple[str, HandSolve]]:
    """The inverse of :func:`as_rig`: always ``[(side, HandSolve)]`` (empty for None)."""
    if rig is None:
        return []
    return rig if isinstance(rig, list) else [("", rig)]
