"""The checks every front end applies to a labeling: is there a hand at all (the no-hand rule),
does another layout fit clearly better, did the vote's bounded work cut a decision short."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from .labelers import labeler_method
from .labeling import Labeling, labeled_take
from .layout import Layout
from .take import Take
from .temporal.voting import FRACTIONAL_PAIRS, MILP_NODES


@dataclass(frozen=True)
class LayoutDoubt:
    """Another layout fits the take clearly better: ``better`` labels ``better_share`` of its labeled
    samples confidently where ``layout`` labels ``share``. ``str()`` is the one-line warning."""

    layout: str
    share: float
    better: str
    better_share: float

    def __str__(self) -> str:
        return (f"only {100 * self.share:.1f} % of labeled samples are confident with layout {self.layout!r}, "
                f"and {100 * self.better_share:.1f} % with {self.better!r}: is this a {self.better} take?")


#: A frame holds a hand when at least half of the layout's markers are labeled, all within HAND_REACH
#: (metres) of their median, and those labels are either believed (:data:`BELIEVED`) or most of what
#: the frame shows (:data:`ALONE`); a hand is "found" where at least HAND_FRAMES of the frames hold one.
#: A hand is about 0.2 m long; a body capture labeled as a hand spreads its "labels" over half a metre
#: or more.
HAND_FRAMES, HAND_REACH = 0.3, 0.25
#: A labeled marker is believed if its segment's mean per-frame probability (its calibrated
#: confidence for methods whose probabilities run low) is at least this: a full-body capture labeled
#: with a hand layout gets labels, but ones its labeler does not believe (``set``: median 0.26 on
#: ezc3d's Vicon.c3d; 0.98 and up on clean hands). Under heavy occlusion (a quarter of the samples
#: missing in long gaps, ghosts that stay) a hand's labels are believed no more than a body's (median
#: 0.35 on the worst han2018 takes of ``benchmarks/occlusion.py``), hence :data:`ALONE`.
BELIEVED = 0.5
#: Labels not believed still make a hand's frame where they are at least this share of the frame's
#: points that no other hand holds: a take of a hand (its markers, ghosts, a few distractors) shows
#: little else, a body capture shows two to five times more points than a hand layout has markers
#: and its labeler leaves most of them null. Not where another layout fits clearly better
#: (:class:`LayoutDoubt`): a han19 hand labeled with glove13 is mostly labeled too.
ALONE = 0.5


@dataclass(frozen=True)
class HandCheck:
    """Whether a labeled take holds a hand: ``share`` of its frames look like one (see
    :data:`HAND_FRAMES`); ``better`` names a layout that fits clearly better, if one does.
    ``points``, ``labeled`` and ``believed`` describe the median frame (points shown, labels,
    labels believed), for the message. ``str()`` of a failed check is the one-line reason, for
    errors in the CLI, batch and Blender."""

    share: float
    layout: str
    better: str | None = None
    points: int = 0
    labeled: int = 0
    believed: int = 0

    @property
    def found(self) -> bool:
        return self.share >= HAND_FRAMES

    def __str__(self) -> str:
        return self.describe()

    def describe(self, use: str = "--layout {}") -> str:
        """The one line; ``use`` says how to pick the better layout where one fits (the command
        line's flag by default; Blender names its panel field)."""
        if self.found:
            return f"a hand in {100 * self.share:.0f} % of frames"
        hint = (f"'{self.better}' fits better: use {use.format(self.better)}" if self.better else
                f"is this a {self.layout} take?")
        how = "believed" if self.better else "believed or most of the frame's points"
        return (f"no hand found: only {100 * self.share:.0f} % of frames have half of the {self.layout} markers "
                f"labeled within {HAND_REACH:g} m of each other, {how} (the median frame shows "
                f"{self.points} points, {self.labeled} labeled, {self.believed} believed; {hint})")


def _believed(labeling: Labeling, m: int) -> np.ndarray:
    """bool ``(F, M)``: where each label sits on a segment whose mean probability (calibrated
    confidence for methods whose probabilities are low where right,
    :attr:`.labelers.LabelerMethod.low_probability`) reaches :data:`BELIEVED`; every label of a
    method whose probabilities say nothing of that (:attr:`~.labelers.LabelerMethod.sure_of_itself`)."""
    seg = labeling.segment_ids()  # (F, P)
    frame, slot = np.nonzero(seg >= 0)
    s = seg[frame, slot]
    name = labeling.info.get("method")
    method = labeler_method(name) if name is not None else None
    low = method is not None and method.low_probability
    belief = labeling.confidence if low else labeling.evidence[:, 0]
    keep = labeling.label[s] >= 0
    if method is None or method.sure_of_itself:
        keep &= belief[s] >= BELIEVED
    out = np.zeros((labeling.n_frames, m), dtype=bool)
    out[frame[keep], labeling.label[s[keep]]] = True
    return out


def _hand_frames(markers: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per frame of ``markers`` ``(F, M, 3)`` (NaN = none): how many, and whether half of the M
    are there, all within :data:`HAND_REACH` of their median."""
    count = np.isfinite(markers[..., 0]).sum(axis=1)
    # np.nanmedian's exact value, from one sort (NaN sorts last): numpy's own takes a masked-array
    # path over so short an axis, several times slower on long takes.
    ordered = np.sort(markers, axis=1)
    n = np.isfinite(markers).sum(axis=1, keepdims=True)  # (F, 1, 3)
    last = markers.shape[1] - 1
    low = np.take_along_axis(ordered, np.clip((n - 1) // 2, 0, last), axis=1)
    high = np.take_along_axis(ordered, np.clip(n // 2, 0, last), axis=1)
    centre = np.where(n > 0, (low + high) / 2, np.nan)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # frames with no labeled marker
        reach = np.nanmax(np.linalg.norm(markers - centre, axis=2), axis=1)
    return count, (count >= markers.shape[1] / 2) & (reach <= HAND_REACH)


def hand_share(markers: np.ndarray, believed: np.ndarray | None = None, points: np.ndarray | None = None) -> float:
    """Share of frames whose labeled markers ``(F, M, 3)`` (metres, NaN = not labeled) look like one
    hand: at least half of the M labeled, all within :data:`HAND_REACH` of their median, and
    believed (``believed`` ``(F, M)`` bool, see :data:`BELIEVED`; None: all are) or, where
    ``points`` ``(F,)`` gives the points each frame offers the hand, at least :data:`ALONE` of them."""
    if not len(markers):
        return 0.0
    held = markers if believed is None else np.where(believed[..., None], markers, np.nan)
    ok = _hand_frames(held)[1]
    if points is not None:
        count, hand = _hand_frames(markers)
        ok |= hand & (count >= ALONE * np.asarray(points))
    return float(ok.mean())


def check_hand(take: Take, layout: Layout, labeling: Labeling, doubt: LayoutDoubt | None = None,
               labeled: Take | None = None, points: np.ndarray | None = None) -> HandCheck:
    """The no-hand rule the CLI, batch and Blender share: a labeling of ``take`` in which under
    :data:`HAND_FRAMES` of the frames hold half of ``layout``'s markers within :data:`HAND_REACH`
    of each other, believed or most of the frame's points (:data:`ALONE`; believed only where
    ``doubt``, from :func:`layout_doubt`, names a better layout), found no hand (a body capture, a
    prop, the wrong layout), however many labels it gave. ``labeled``: ``labeled_take(take,
    labeling)`` where the caller has it already; ``points`` ``(F,)``: the points each frame offers
    this hand (default: all it shows; :func:`hand_checks` leaves out the other hand's)."""
    m = len(layout)
    markers = (labeled if labeled is not None else labeled_take(take, labeling)).positions[:, :m]
    believed = _believed(labeling, m)
    if points is None:
        points = take.valid.sum(axis=1)
    share = hand_share(markers, believed, None if doubt else points)
    labels = np.isfinite(markers[..., 0])
    shown = points > 0
    median = [int(np.median(x[shown])) if shown.any() else 0
              for x in (points, labels.sum(axis=1), (labels & believed).sum(axis=1))]
    return HandCheck(share, layout.name, doubt.better if doubt else None, *median)


def hand_checks(take: Take, layout: Layout, labeling: Labeling,
                doubt: LayoutDoubt | None = None) -> list[tuple[str, HandCheck]]:
    """:func:`check_hand` per hand: ``[("", check)]`` for one hand, ``[("left", ...), ("right", ...)]``
    for a two-hand labeling (each hand's labels on their own, the other hand's points left out of
    the points its frames offer)."""
    hands = labeling.info.get("hands", {})
    if hands.get("count", 1) < 2:
        return [("", check_hand(take, layout, labeling, doubt))]
    m = len(layout)
    per = labeling.per_sample()
    shown = take.valid.sum(axis=1)
    out = []
    for h, side in enumerate(hands["sides"]):
        other = ((per >= 0) & (per // m != h)).sum(axis=1)
        out.append((side, check_hand(take, layout, labeling.label_range(h * m, (h + 1) * m), doubt,
                                     points=shown - other)))
    return out


def work_limit_warning(labeling: Labeling) -> str | None:
    """A one-line warning when the vote's exclusive assignment reached its work bound, else None."""
    stopped = labeling.info.get("work_limited", 0)
    if not stopped:
        return None
    return (f"the vote's exclusive assignment reached its work bound {stopped} time(s) ({MILP_NODES} search nodes, "
            f"or more than {FRACTIONAL_PAIRS} undecided pairs in its relaxation): the labels are the best found "
            f"within it, never worse than a greedy labeling (takes of hands stay far inside it; is this a hand, "
            f"and of this layout?)")


def occlusion_note(labeling: Labeling) -> str | None:
    """One line where the vote's occlusion prior acted (the take's trajectories break more often
    than its knee: heavy occlusion), else None."""
    knee, slope = labeling.info.get("occlusion_prior", (0.0, 0.0))
    rate = labeling.info.get("break_rate", 0.0)
    if slope <= 0 or rate <= knee:
        return None
    return (f"heavy occlusion: the take's trajectories break {rate:.2f} times a second (above {knee:g}; takes with "
            f"few occlusions: about 0.25), so short ones kept their labels on less evidence: review its uncertain "
            f"segments")

