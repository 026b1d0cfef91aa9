"""The one per-take entry of every front end: :func:`process_take`.

The CLI, batch and the Blender operators turn their options into a :class:`.settings.LabelSettings`
and an :class:`Outputs`, call :func:`process_take`, and turn its :class:`TakeResult` into files,
scenes and messages. The rules every front end shares live here once: the layout picked from the
points' names, the doubt about the layout, the no-hand rule, and "solve the hand before a fill
that uses it".
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from .cache import RunCache
from .checks import HandCheck, LayoutDoubt, check_hand, hand_checks, occlusion_note, work_limit_warning
from .errors import MocapInputError
from .hands import HandNaming, add_warning
from .labelers import Labeler, labeler_method
from .labelers.onnx_labeler import shipped_model
from .labeling import Labeling, labeled_take, layout_markers
from .layout import DEFAULT_LAYOUT, Layout, builtin_layouts, layout_for_names, load_layout
from .pipeline import label_take
from .settings import Corrections, LabelSettings
from .stages.decide import CALIBRATED, TEMPORAL_MODES
from .stages.refine import CLEARLY_BETTER, DOUBTFUL_SHARE
from .stages.run import Progress, no_progress
from .take import Take, read_take

if TYPE_CHECKING:  # the solve and the fill are imported where they run: labeling alone needs neither
    from .hand.calibrate import Calibration
    from .solve import HandSolve

#: What the front ends (CLI, batch, Blender) use of the core's labeling and solving.
__all__ = ["TEMPORAL_MODES", "LayoutDoubt", "Outputs", "TakeResult", "choose_layout", "layout_doubt",
           "layout_from_names", "occlusion_note", "performer_inputs", "process_take",
           "work_limit_warning"]

#: The share of a labeling's work before its layout check (the check labels a short excerpt per layout).
LABEL_SHARE = 0.95
#: Frames of the take the other layouts are tried on (about half a second each).
CHECK_FRAMES = 2000


@dataclass(frozen=True)
class Outputs:
    """What a take's outputs need beyond its labels.

    Attributes:
        label: label the take; False: it is labeled already (its point names carry the labels).
        check_hand: the no-hand rule: a labeling in which no hand is found raises.
        check_layout: try the other built-in layouts where this one labels few samples confidently.
        pick_layout: where another layout fits clearly better, label with it instead (the layout was
            not the user's choice).
        solve: solve the hand(s) (a calibrated rig per side).
        fill: a fill method of :data:`.fill.FILL_METHODS`, or None for no fill.
        max_gap: seconds; longer gaps stay open.
        calibrations: per side (``""`` for one hand, ``left``, ``right``) a performer's calibration
            to solve with instead of calibrating on the take.
        calibrate: calibrate a hand that has no calibration; False: a fill goes without the hand
            unless every hand has one (Blender's Fill Gaps: Solve Hand calibrates, not the fill).
        solve_options: keywords of :func:`.solve.solve_take` (calibrate_seconds, reference,
            contacts, side, smooth_hz).
        confident: the confidence a segment needs to count as confident in the checks.
        layout_hint: how the front end's user picks another layout (``{}``: its name), for the
            no-hand rule's message.
        hands_hint: how the front end's user forces one hand and two, for the message of one hand
            forced on a take of two.
    """

    label: bool = True
    check_hand: bool = True
    check_layout: bool = True
    pick_layout: bool = False
    solve: bool = False
    fill: str | None = None
    max_gap: float | None = None  # None: the fill's own (:data:`.fill.MAX_GAP`)
    calibrations: dict[str, Calibration] | None = None
    calibrate: bool = True
    solve_options: dict = field(default_factory=dict)
    confident: float = 0.95
    layout_hint: str = "--layout {}"
    hands_hint: tuple[str, str] = ("--hands 1", "--hands 2")


@dataclass
class TakeResult:
    """What :func:`process_take` made of one take.

    Attributes:
        take: the raw take as read (metres).
        layout: the layout it was labeled with (the picked one, where it was picked).
        labeling: the labeling (None for a take labeled already).
        labeled: the labeled take (points named by label, ghosts unnamed after them).
        checks: the no-hand rule per hand, ``[(side, HandCheck)]``.
        doubt: another layout that fits clearly better, or None.
        picked: ``{"from", "to", "share", "better_share"}`` where the layout was picked, else None.
        solves: ``[(side, HandSolve)]``, side ``""`` for one hand.
        filled: the fill (:class:`.fill.TakeFill`), or None.
        warnings: one-line warnings for the user.
        seconds: wall time of each step.
    """

    take: Take
    layout: Layout
    labeling: Labeling | None
    labeled: Take
    checks: list[tuple[str, HandCheck]] = field(default_factory=list)
    doubt: LayoutDoubt | None = None
    picked: dict | None = None
    solves: list[tuple[str, HandSolve]] | None = None
    filled: object | None = None
    warnings: list[str] = field(default_factory=list)
    seconds: dict = field(default_factory=dict)

    @property
    def output_take(self) -> Take:
        """The take to write: filled where it was, else labeled."""
        return self.filled.take if self.filled is not None else self.labeled

    def rig(self) -> HandSolve | list[tuple[str, HandSolve]] | None:
        """The solve as the scene writers take it (:func:`.solve.as_rig`)."""
        from .solve import as_rig

        return as_rig(self.solves)


def layout_from_names(take: Take) -> str | None:
    """The built-in layout whose every marker the take's point names hold (:func:`.layout.layout_for_names`),
    or None; a take of unnamed points (``*N``, ``M001``...) names none (no layout file is read)."""
    return None if take.unlabeled.all() else layout_for_names(take.names)


def choose_layout(take: Take, requested: str | None) -> str:
    """The layout to label ``take`` with: the one asked for, else the one its points' names give
    (:func:`layout_from_names`), else :data:`.layout.DEFAULT_LAYOUT`."""
    return requested or layout_from_names(take) or DEFAULT_LAYOUT


#: A built-in layout is tried against a take only if it has at most this many times the points of the
#: take's median frame (plus two).
FEWER_POINTS = 1.5


#: The settings another layout is tried with (:func:`layout_doubt`): a quick reading, whose vote settles
#: its clashes by the rounded relaxation (on another layout's markers the integer programme of a clash can
#: take minutes, within its work bound).
QUICK_READING = LabelSettings(occlusion_prior=(0.0, 0.0), exact_pairs=0)


def layout_doubt(take: Take, layout: Layout, labeling: Labeling, confident: float = 0.95,
                 cache: RunCache | None = None) -> LayoutDoubt | None:
    """A :class:`.checks.LayoutDoubt` when another built-in layout fits ``take`` clearly better, else None.

    Nothing is tried while at least :data:`DOUBTFUL_SHARE` of the labeled samples are confident.
    Below it, every built-in layout with a shipped ``set`` model labels the take's first
    :data:`CHECK_FRAMES` frames (:data:`QUICK_READING`); one whose confident share is at least
    :data:`DOUBTFUL_SHARE` and :data:`CLEARLY_BETTER` above ``layout``'s (on the same frames) is named.
    Where ``labeling``'s confidences are not calibrated (a layout with no model of its own, labeled by
    ``set_any``, whose raw confidences seldom reach ``confident``), only layouts of more markers are
    tried: a dedicated model's calibrated confidences claimed sparse takes of 13 markers that were none
    of its layout's (glove13 on han2018 takes of tips and proximal phalanges and a hand cluster).
    """
    share = labeling.summary(confident)["confident_share"]
    if share >= DOUBTFUL_SHARE:
        return None
    excerpt = replace(take, positions=take.positions[:CHECK_FRAMES],
                      residuals=None if take.residuals is None else take.residuals[:CHECK_FRAMES], filled=None)
    shares = {}
    # A layout with far more markers than the take shows points is not the take's (and labeling
    # with it sets the vote a large, slow problem): a sparse set's take is not tried as han19.
    most = FEWER_POINTS * float(np.median(excerpt.valid.sum(axis=1))) + 2
    fewest = 0 if labeling.info.get("confidence") == CALIBRATED else len(layout) + 1
    for name in builtin_layouts():
        if (name != layout.name and os.path.isfile(shipped_model("set", name))
                and fewest <= len(load_layout(name)) <= most):
            try:
                # Without the occlusion prior: on another layout's markers a heavily occluded take's
                # label bonus makes nearly every label worth a segment, and the vote's programme
                # grows by an order of magnitude; which layout fits is asked of the evidence alone.
                other = label_take(excerpt, load_layout(name), QUICK_READING, cache=cache)
            except MocapInputError:  # e.g. no samples in the excerpt
                continue
            shares[name] = other.summary(confident)["confident_share"]
    best = max(shares, key=shares.get, default=None)
    if best is None or shares[best] < DOUBTFUL_SHARE:
        return None
    labeled = labeling.per_sample()[:CHECK_FRAMES] >= 0
    own = (labeled & (labeling.per_sample_confidence()[:CHECK_FRAMES] >= confident)).sum() / max(labeled.sum(), 1)
    if shares[best] - own < CLEARLY_BETTER:
        return None
    return LayoutDoubt(layout.name, float(share), best, float(shares[best]))


def _naming(labeling: Labeling | None, settings: LabelSettings) -> HandNaming | None:
    pattern = labeling.info.get("hands", {}).get("naming") if labeling is not None else settings.naming
    return HandNaming(pattern) if pattern else None


def _label(take: Take, layout: Layout, settings: LabelSettings, outputs: Outputs, corrections: Corrections,
           result_seconds: dict, progress: Progress, cache: RunCache,
           **inputs) -> tuple[Layout, Labeling, LayoutDoubt | None, dict | None]:
    """Label, and where asked check the layout (and pick a better one)."""
    t = time.perf_counter()
    checked = LABEL_SHARE if outputs.check_layout else 1.0  # the rest of the work: the layout check

    def labeling_progress(message: str, share: float) -> None:
        progress(message, checked * share)

    labeling = label_take(take, layout, settings, corrections=corrections, progress=labeling_progress, cache=cache,
                          **inputs)
    result_seconds["label"] = round(time.perf_counter() - t, 4)
    one = labeling.info.get("hands", {}).get("count", 1) == 1
    doubt, picked = None, None
    if outputs.check_layout and one:
        progress("checking the layout against the other built-in layouts", checked)
        doubt = layout_doubt(take, layout, labeling, outputs.confident, cache)
        if doubt and outputs.pick_layout and not (corrections.constraints or corrections.splits):
            # The take's shape says which layout it is: label with that one (the user chose none).
            progress(f"checking: the take fits {doubt.better} better, labeling with it", checked)
            better = load_layout(doubt.better)
            labeling = label_take(take, better, settings, progress=lambda message, _share: progress(message, checked),
                                  cache=cache)
            picked = {"from": layout.name, "to": doubt.better, "share": doubt.share,
                      "better_share": doubt.better_share}
            layout, doubt = better, None
    if doubt:
        labeling.info["layout_doubt"] = asdict(doubt)  # in the report, and in the review scene's panel
    progress("labeled and checked", 1.0)
    return layout, labeling, doubt, picked


def _two_hand_reading(take: Take, layout: Layout, settings: LabelSettings, outputs: Outputs, corrections: Corrections,
                      labeling: Labeling, doubt: LayoutDoubt | None, cache: RunCache, progress: Progress,
                      **inputs) -> tuple[Labeling, list[tuple[str, HandCheck]]] | str | None:
    """A take labeled as one hand in which no hand was found may hold two: one hand forced on it
    (``hand_count`` 1) spreads the layout over both, and under heavy occlusion two hands may label
    too few samples confidently to beat one (:func:`.stages.refine.one_hand_stage`). Where the
    no-hand rule finds a hand among two, the labeling and its checks: for one hand forced, the hand
    found in more frames, labeled on its own (the other hand's samples kept out), with a warning
    that names it; else the two hands, with a warning. A string: that hand, labeled on its own, is
    no hand (the reason). None: no hand among two either (or not tried: a method that labels one
    hand, IK validation, corrections of a take read as one hand)."""
    facts = labeling.info.get("hands", {})
    forced = str(settings.hand_count) == "1"
    if (facts.get("count", 1) != 1 or not labeler_method(settings.method).labels_two_hands
            or not (forced or ("two_hands_rejected" in facts and not settings.validate
                               and not corrections.constraints))):
        return None
    progress("no hand found as one hand: looking for two", LABEL_SHARE)
    two = label_take(take, layout, settings.but(hand_count=2, sides=None, validate=False),
                     corrections=corrections.but(constraints=(), splits=()), cache=cache, **inputs)
    if two.info["hands"]["count"] != 2:
        return None
    checks = hand_checks(take, layout, two, doubt)
    if not any(check.found for _, check in checks):
        return None
    if not forced:
        add_warning(two.info["hands"], "labeled as two hands: as one hand, no hand was found")
        return two, checks
    m = len(layout)
    best = max(range(2), key=lambda h: checks[h][1].share)
    per = two.per_sample()
    elsewhere = (per >= 0) & (per // m != best)  # the other hand's samples
    if corrections.exclude is not None:
        elsewhere |= corrections.exclude
    one = label_take(take, layout, settings, corrections=corrections.but(exclude=elsewhere), cache=cache, **inputs)
    check = check_hand(take, layout, one, doubt, points=(take.valid & ~elsewhere).sum(axis=1))
    one_hint, two_hint = outputs.hands_hint
    side = checks[best][0]
    if not check.found:
        return (f"two hands found; {one_hint} labels one of them, and finds no hand in the {side} one: "
                f"{check.describe(outputs.layout_hint)} ({two_hint} labels both)")
    add_warning(one.info["hands"], f"two hands found; {one_hint} labels one of them, the {side} hand here (a hand "
                                   f"in {100 * check.share:.0f} % of frames); {two_hint} labels both")
    return one, [("", check)]


def performer_inputs(labeled: str | None, layout: Layout, method: str) -> dict:
    """The keywords of :func:`process_take` that ``labeled``, the path of a labeled take of the performer, gives
    ``method``: ``fit`` ``(F, M, 3)`` for a labeler fitted per performer (``gmm``), ``start`` ``(M, 3)``, its
    first frame, for one that starts from a labeled frame (``nearest``); none for the others (``set``), whose
    take is then not read.

    Raises:
        MocapInputError: the take cannot be read, or lacks some of the layout's marker names.
    """
    chosen = labeler_method(method)
    if labeled is None or not (chosen.fits_performer or chosen.starts_from_frame):
        return {}
    positions = layout_markers(read_take(labeled), layout)
    return {"fit": positions} if chosen.fits_performer else {"start": positions[0]}


def process_take(take: Take, layout: Layout, settings: LabelSettings, outputs: Outputs = Outputs(), *,
                 corrections: Corrections | None = None, previous: Labeling | None = None,
                 labeler: Labeler | None = None, fit: np.ndarray | None = None, start: np.ndarray | None = None,
                 progress: Progress | None = None, cache: RunCache | None = None,
                 solves: list[tuple[str, HandSolve]] | None = None) -> TakeResult:
    """Label ``take`` (unless it is labeled already), check it, solve the hand(s) and fill the gaps
    as ``outputs`` asks; ``solves`` (``[(side, HandSolve)]``, e.g. a scene's rig) are used instead
    of solving again. The other keywords go to :func:`.pipeline.label_take`.

    A take labeled as one hand in which the no-hand rule finds none is read as two hands where it may
    hold two (one hand forced, or two hands rejected for one): see :func:`_two_hand_reading`.

    Raises:
        MocapInputError: no hand found (the no-hand rule), or a take the steps cannot work with.
    """
    progress = progress or no_progress
    cache = cache if cache is not None else RunCache()
    seconds: dict[str, float] = {}
    labeling, doubt, picked, checks, warnings = None, None, None, [], []
    if outputs.label:
        layout, labeling, doubt, picked = _label(take, layout, settings, outputs, corrections or Corrections(), seconds,
                                                 progress, cache, previous=previous, labeler=labeler, fit=fit,
                                                 start=start)
        labeled = labeled_take(take, labeling)
        facts = labeling.info["hands"]
        if outputs.check_hand:
            checks = hand_checks(take, layout, labeling, doubt)
            if not any(check.found for _, check in checks):
                other = _two_hand_reading(take, layout, settings, outputs, corrections or Corrections(), labeling,
                                          doubt, cache, progress, labeler=labeler, fit=fit, start=start)
                if isinstance(other, str):
                    raise MocapInputError(take.source, other)
                if other is None:
                    hint = facts.get("warning")  # a take of two hands that never come apart
                    said = [f"{side} hand: " * bool(side) + check.describe(outputs.layout_hint)
                            for side, check in checks]
                    raise MocapInputError(take.source, "; ".join(said + ([hint] if hint else [])))
                labeling, checks = other
                labeled, facts = labeled_take(take, labeling), labeling.info["hands"]
            warnings += [f"{side} hand: {check}" for side, check in checks if not check.found]
        warnings += [str(w) for w in (doubt, work_limit_warning(labeling), occlusion_note(labeling)) if w]
        if facts.get("forced") == 2:
            warnings.append("two hands were forced, one was found")
        if facts.get("warning"):
            warnings.append(facts["warning"])
    else:
        labeled = take
    naming = _naming(labeling, settings)
    if outputs.solve and solves is None:
        from .solve import solve_hands

        t = time.perf_counter()
        solves = solve_hands(labeled, layout, naming, outputs.calibrations, progress=progress, cache=cache,
                             **outputs.solve_options)
        seconds["solve"] = round(time.perf_counter() - t, 4)
    filled = None
    if outputs.fill is not None:
        t = time.perf_counter()
        progress("filling gaps", 0.0)
        # A fill that uses the hand solves it first where it is not solved yet (:func:`.fill.fill_gaps`).
        from .fill import MAX_GAP, fill_gaps

        max_gap = MAX_GAP if outputs.max_gap is None else outputs.max_gap
        filled = fill_gaps(labeled, layout, outputs.fill, max_gap, solves=solves, naming=naming,
                           calibrate=outputs.calibrate, calibrations=outputs.calibrations, **outputs.solve_options)
        if solves is None and filled.solves:
            solves = filled.solves
        seconds["fill"] = round(time.perf_counter() - t, 4)
    return TakeResult(take, layout, labeling, labeled, checks, doubt, picked, solves, filled, warnings, seconds)
