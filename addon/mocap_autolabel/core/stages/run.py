"""The one object a labeling's stages pass along, and what a stage returns to ask for another pass."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..cache import RunCache
from ..labelers import FrameBatch, Labeler, LabelerMethod
from ..labeling import Labeling
from ..layout import Layout
from ..settings import Corrections, LabelSettings
from ..take import Take

#: Progress, the one protocol of the core: called with a short message and the share of the work
#: done (0 to 1); it may raise to stop the work (a cancelled :class:`..jobs.Job` does).
Progress = Callable[[str, float], None]


def no_progress(_message: str, _share: float) -> None:
    return None


@dataclass(frozen=True)
class Attempt:
    """One pass's plan: its settings, corrections and labeler (None: built for the take); ``notes``
    go into the final labeling's ``info`` (what earlier passes found, e.g. props)."""

    settings: LabelSettings
    corrections: Corrections
    labeler: Labeler | None = None
    notes: tuple[tuple[str, Any], ...] = ()


@dataclass
class Retry:
    """What a stage asks of the pipeline's loop: label ``attempt``.

    ``resolve`` None: the attempt replaces the current pass. Otherwise it is called with the
    attempt's labeling and returns the labeling to finish with, an :class:`Attempt` to label
    instead, or None to go on with the current pass from its next stage.
    """

    reason: str
    attempt: Attempt
    resolve: Callable[[Labeling], Labeling | Attempt | None] | None = None


@dataclass
class LabelRun:
    """A labeling pass: its inputs, then what each stage adds (all arrays in the take's frames).

    Inputs: ``take`` (metres), ``layout``, ``attempt`` (settings, corrections, labeler), ``fit``
    ``(F, M, 3)`` and ``start`` ``(M, 3)`` for the methods that use them, ``progress``, ``cache``.
    """

    take: Take
    layout: Layout
    attempt: Attempt
    method: type[LabelerMethod]
    mode: Any  # a :class:`.decide.TemporalMode`
    fit: np.ndarray | None = None
    start: np.ndarray | None = None
    progress: Progress = no_progress
    cache: RunCache = field(default_factory=RunCache)
    times: dict[str, float] = field(default_factory=dict)
    info: dict = field(default_factory=dict)
    # find_hands
    naming: Any = None
    ignore: np.ndarray | None = None  # bool (P,) or (F, P): samples kept out of the hands
    swaps: np.ndarray | None = None  # bool (F,): frames where the hands found trade places
    found: Any = None  # a ..hands.Hands
    labels: Any = None  # a .hands.HandLabels
    constraints: list = field(default_factory=list)  # in the labels' internal (hands') order
    # score
    take_in: Take | None = None  # the take the hands are offered (ignored samples made invalid)
    batch: FrameBatch | None = None
    tracklets: Any = None
    segments: Any = None
    stride: int = 1
    labeler: Labeler | None = None
    joint: np.ndarray | None = None  # (F, K, labels + 1) before the corrections are applied
    scores: np.ndarray | None = None  # (F, K, labels + 1)
    hand_scores: list | None = None  # two hands: each hand's (F, K, M + 1)
    scored_members: list | None = None
    near: np.ndarray | None = None
    member: np.ndarray | None = None  # bool (n, hands): the hands each scored sample is offered to
    samples: Any = None
    crossings: dict = field(default_factory=dict)
    locked_at: np.ndarray | None = None
    # decide and after
    labeling: Labeling | None = None
    next_stage: int = 0
    share: float = 0.0

    @property
    def settings(self) -> LabelSettings:
        return self.attempt.settings

    @property
    def corrections(self) -> Corrections:
        return self.attempt.corrections

    @property
    def scored_share(self) -> float:
        """The share of the work done once the frames are scored (IK validation costs a calibration)."""
        return 0.5 if self.settings.validate else 0.7

    @property
    def decided_share(self) -> float:
        """The share of the work done once the temporal decision is made."""
        return 0.7 if self.settings.validate else 1.0

    def say(self, message: str, share: float | None = None) -> None:
        """Progress: ``message`` at ``share`` (None: the share reached so far)."""
        if share is not None:
            self.share = share
        self.progress(message, self.share)

    def timed(self, stage: str, since: float) -> None:
        self.times[stage] = time.perf_counter() - since
