"""Labeling a take: the stages in order over one run, a loop for the passes they ask for, and the
drivers above it (windows for long takes, a re-solve around a reviewer's change).

Take -> find hands -> score -> decide (temporal mode + confidence calibration) -> refine -> name
sides -> checks (:mod:`.stages`). A stage that needs another pass returns a
:class:`.stages.run.Retry`; :func:`label_take`'s loop runs it. The per-take entry of the front ends
is :func:`.process.process_take`.
"""

from __future__ import annotations

import time

import numpy as np

from .cache import RunCache
from .errors import MocapInputError
from .labelers import Labeler, labeler_method
from .labeling import Labeling
from .layout import Layout
from .review import marker_slack, missing_marker_distance
from .settings import Corrections, LabelSettings
from .stages.decide import TEMPORAL_MODES, decide_stage, temporal_mode
from .stages.hands import find_hands_stage, name_sides_stage
from .stages.refine import (
    finger_order_stage,
    holders_stage,
    one_hand_stage,
    props_stage,
    refine_stage,
    validate_stage,
)
from .stages.run import Attempt, LabelRun, Progress, Retry, no_progress
from .stages.scoring import score_stage
from .take import Take
from .windows import label_in_windows, relabel_around

#: The stages of a pass, in order.
STAGES = (find_hands_stage, score_stage, decide_stage, refine_stage, validate_stage, name_sides_stage,
          one_hand_stage, props_stage, finger_order_stage, holders_stage)

DEFAULT_SETTINGS = LabelSettings()
NO_CORRECTIONS = Corrections()


def label_take(take: Take, layout: Layout, settings: LabelSettings = DEFAULT_SETTINGS, *,
               corrections: Corrections = NO_CORRECTIONS, previous: Labeling | None = None,
               labeler: Labeler | None = None, fit: np.ndarray | None = None, start: np.ndarray | None = None,
               progress: Progress | None = None, cache: RunCache | None = None) -> Labeling:
    """Label every sample of ``take`` with ``layout``'s labels or null.

    Args:
        take: the raw take (metres).
        layout: the marker layout.
        settings: what to do (:class:`.settings.LabelSettings`).
        corrections: a reviewer's locks and splits, honoured exactly (:class:`.settings.Corrections`).
        previous: an earlier labeling of this take (a re-solve): only the frames around the
            corrections changed since are labeled again (:func:`.windows.relabel_around`) where
            the method allows it; elsewhere ``previous`` is kept.
        labeler: a ready labeler instead of one built from ``settings.method`` (e.g. a ``gmm``
            fitted once for a performer).
        fit: ``(F, M, 3)`` labeled positions of the performer (``gmm``; default: the layout's
            synthetic range of motion).
        start: ``(M, 3)`` a labeled first frame (``nearest``; default: ``set``'s labels of it).
        progress: called with a message and the share of the work done as it goes.
        cache: results kept between calls by the caller (a Blender session, a batch run); None:
            kept for this call only.

    Returns:
        the :class:`.labeling.Labeling`; ``info`` holds the settings, the hands found (count,
        sides with their evidence), the corrections honoured and the seconds of each stage.
    """
    method = labeler_method(settings.method)
    mode = temporal_mode(settings.temporal)
    refusal = method.refusal(layout, labeler=labeler is not None, fit=fit is not None, start=start is not None)
    if refusal:
        raise MocapInputError(layout.source or layout.name, refusal)
    if take.n_frames == 0 or take.n_points == 0 or not take.valid.any():
        raise MocapInputError(take.source, "the take has no marker samples to label")
    for c in corrections.constraints:
        if not (0 <= c.slot < take.n_points and 0 <= c.start < c.stop <= take.n_frames):
            raise ValueError(f"constraint {c} lies outside the take ({take.n_frames} frames, {take.n_points} slots)")
    if settings.validate and not mode.allows_validation:
        allowed = ", ".join(name for name, m in TEMPORAL_MODES.items() if m.allows_validation)
        raise ValueError(f"validate needs temporal={allowed!r}, not {settings.temporal!r}")
    cache = cache if cache is not None else RunCache()
    progress = progress or no_progress

    def label_whole(part: Take, part_settings: LabelSettings, part_corrections: Corrections,
                    part_progress: Progress) -> Labeling:
        return _label_passes(part, layout, Attempt(part_settings, part_corrections, labeler), fit, start,
                             part_progress, cache)

    labeling = None
    if previous is not None and corrections.exclude is None and not settings.validate and method.relabels_locally:
        labeling = relabel_around(label_whole, take, layout, previous, settings, corrections, progress, cache)
    if labeling is None and settings.window is not None and take.n_frames > settings.window and not method.whole_take:
        labeling = label_in_windows(label_whole, take, layout, settings, corrections, progress)
    if labeling is None:
        labeling = label_whole(take, settings, corrections, progress)
    # The corrections the labeling honours, as given (a re-solve labels again what changed since).
    labeling.info["locks"] = [[int(c.slot), int(c.start), int(c.stop), int(c.label)] for c in corrections.constraints]
    labeling.info["splits"] = [[int(slot), int(frame)] for slot, frame in corrections.splits]
    return labeling


def _label_passes(take: Take, layout: Layout, attempt: Attempt, fit: np.ndarray | None, start: np.ndarray | None,
                  progress: Progress, cache: RunCache) -> Labeling:
    """The stages over ``take`` until a pass finishes; a stage's :class:`Retry` either replaces the
    pass (a new attempt) or labels an alternative first and lets its ``resolve`` choose."""
    t0 = time.perf_counter()
    run = _new_run(take, layout, attempt, fit, start, progress, cache)
    restarted = 0.0  # seconds spent on passes that were replaced
    while True:
        outcome = _advance(run)
        if isinstance(outcome, Labeling):
            labeling = outcome
            run.times["total"] = time.perf_counter() - t0
            labeling.info["seconds"] = {key: round(v, 4) for key, v in run.times.items()}
            break
        run.say(outcome.reason)
        if outcome.resolve is None:
            restarted += sum(run.times.values())
            run = _new_run(take, layout, outcome.attempt, fit, start, progress, cache)
            continue
        held = run.share  # the alternative's messages are heard at the share reached

        def heard(message: str, _share: float, held: float = held) -> None:
            progress(message, held)

        alternative = _label_passes(take, layout, outcome.attempt, None, None, heard, cache)
        chosen = outcome.resolve(alternative)
        if isinstance(chosen, Labeling):
            labeling = chosen
            labeling.info["seconds"]["total"] = round(time.perf_counter() - t0, 4)
            break
        if isinstance(chosen, Attempt):
            run = _new_run(take, layout, chosen, fit, start, progress, cache)
        # None: the current pass goes on from its next stage.
    for key, value in run.attempt.notes:
        labeling.info[key] = value
    if labeling.missing_mm is None:  # the review queue's fact, once per labeling (a pass votes several times)
        labeling.missing_mm = missing_marker_distance(labeling, take.positions, len(layout), take.rate,
                                                      slack_mm=marker_slack(layout))
    if restarted:  # the passes replaced (hands that traded places, props kept out), in seconds
        labeling.info["seconds"]["restarted"] = round(restarted, 4)
    run.say("labeled", 1.0)
    return labeling


def _new_run(take: Take, layout: Layout, attempt: Attempt, fit: np.ndarray | None, start: np.ndarray | None,
             progress: Progress, cache: RunCache) -> LabelRun:
    """A pass over ``take`` with ``attempt``: its labeler and temporal mode from the registries."""
    settings = attempt.settings
    return LabelRun(take, layout, attempt, labeler_method(settings.method), temporal_mode(settings.temporal), fit,
                    start, progress, cache, labeler=attempt.labeler)


def _advance(run: LabelRun) -> Labeling | Retry:
    """Run the stages from ``run.next_stage`` on: the labeling, or the first stage's Retry."""
    while run.next_stage < len(STAGES):
        stage = STAGES[run.next_stage]
        run.next_stage += 1
        retry = stage(run)
        if retry is not None:
            return retry
    return run.labeling
