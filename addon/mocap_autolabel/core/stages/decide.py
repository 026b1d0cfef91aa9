"""The ``decide`` stage: the temporal mode turns per-frame scores into segments with labels, then
the confidence calibration gives each segment its confidence.

:data:`TEMPORAL_MODES` maps each mode's name to its class; capabilities are class attributes.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from typing import ClassVar

import numpy as np

from ..labeling import EMPTY, NULL, Labeling, segments_from_runs
from ..temporal.confidence import (
    SURE,
    load_calibration,
    load_continuity,
    load_null_prior,
    load_occlusion_prior,
    load_partner,
    load_switch_cost,
    segment_evidence,
    split_doubtful_edges,
)
from ..temporal.continuity import continuity_logp
from ..temporal.partners import partner_logp, take_distances
from ..temporal.voting import FIRST_LOOK_PAIRS, Samples, Segments, vote
from ..tracklets import break_rate
from .look import look_again
from .run import LabelRun
from .scoring import score_samples

#: ``again``: called with the first vote's labeling; new ``(samples, member)`` to vote on, or None.
LookAgain = Callable[[Labeling], "tuple[Samples, np.ndarray | None] | None"]


class TemporalMode:
    """A temporal mode of the registry.

    Attributes:
        name: the mode's name (``--temporal``).
        decides_per_frame: decides frame by frame (the labeler scores every frame).
        splits_swaps: cuts trajectories where two that pass close may have traded markers.
        allows_validation: IK validation can vote again with the hand fit's evidence.
        uses_evidence: reads rigid partners, continuity and the hands' second look off a first decision.
    """

    name: ClassVar[str]
    decides_per_frame: ClassVar[bool] = True
    splits_swaps: ClassVar[bool] = False
    allows_validation: ClassVar[bool] = False
    uses_evidence: ClassVar[bool] = False

    def decide(self, run: LabelRun, scores: np.ndarray, samples: Samples, first: Labeling | None = None,
               again: LookAgain | None = None) -> tuple[Labeling, Samples]:
        """Segments with labels (no confidences yet) from the per-frame ``scores`` ``(F, K, L + 1)``,
        and the samples they were decided on (``again`` may have scored them again)."""
        raise NotImplementedError


class PerFrame(TemporalMode):
    """Per-frame labels as the labeler's assignment gives them (``none``)."""

    name = "none"

    def frame_labels(self, run: LabelRun, scores: np.ndarray, samples: Samples) -> np.ndarray:
        """int16 ``(F, P)``: each sample's label (NULL where none)."""
        per = np.full(run.take.valid.shape, NULL, dtype=np.int16)
        per[samples.frame, samples.slot] = samples.label
        return per

    def decide(self, run: LabelRun, scores: np.ndarray, samples: Samples, first: Labeling | None = None,
               again: LookAgain | None = None) -> tuple[Labeling, Samples]:
        valid, segments = run.take.valid, run.segments
        per = self.frame_labels(run, scores, samples)
        split = np.zeros(valid.shape, dtype=bool)
        split[segments.start, segments.slot] = True
        labeling = segments_from_runs(run.labels.names, per, valid, run.info, split=split)
        labeling.locked = run.locked_at[labeling.start, labeling.slot] != EMPTY
        return labeling, samples


class Viterbi(PerFrame):
    """Alexanderson's N-best hypotheses per frame with a Kalman/Viterbi pass (``viterbi``)."""

    name = "viterbi"

    def frame_labels(self, run: LabelRun, scores: np.ndarray, samples: Samples) -> np.ndarray:
        from ..temporal.viterbi import viterbi_labels

        batch = run.batch
        per = np.full(run.take.valid.shape, NULL, dtype=np.int16)
        f_idx, k_idx = np.nonzero(batch.mask)
        frame_labels = viterbi_labels(scores, batch.mask, batch.points, run.take.rate, n_best=run.settings.n_best)
        per[f_idx, batch.slots[f_idx, k_idx]] = frame_labels[f_idx, k_idx]
        return per


class Vote(TemporalMode):
    """Trajectory voting with exclusivity (``vote``, the default): a first vote, then the vote again
    with the evidence of rigid partners and continuity read off it."""

    name = "vote"
    decides_per_frame = False
    splits_swaps = True
    allows_validation = True
    uses_evidence = True

    def _vote(self, run: LabelRun, scored: Samples, exact_pairs: int | None = None
              ) -> tuple[Segments, np.ndarray, np.ndarray, dict]:
        s = run.settings
        fitted = run.info
        if s.exact_pairs is not None and (exact_pairs is None or s.exact_pairs < exact_pairs):
            exact_pairs = s.exact_pairs
        return vote(scored, run.segments, run.locked_at, s.vote_score, s.power_p, s.power_q, s.split_swaps,
                    null_prior=null_prior(fitted), crossings=run.crossings,
                    switch_cost=tuple(fitted["switch_cost"]), exact_pairs=exact_pairs)

    def decide(self, run: LabelRun, scores: np.ndarray, samples: Samples, first: Labeling | None = None,
               again: LookAgain | None = None) -> tuple[Labeling, Samples]:
        take, labels, member = run.take, run.labels, run.member
        partner, continuity = tuple(run.info["partner"]), tuple(run.info["continuity"])
        rigid = labels.rigid_pairs() if partner and any(partner) else None
        with_rigid, with_continuity = rigid is not None and len(rigid) > 0, any(continuity)
        if first is not None and (with_rigid or with_continuity):
            facts = {"work_limited": 0}
            ids = first.segment_ids()[samples.frame, samples.slot]
            per = np.where(ids >= 0, first.label[np.maximum(ids, 0)], NULL).astype(np.int64)
            held_for = first.length if first.held is None else first.held  # as the vote held the label
            held = np.where(ids >= 0, held_for[np.maximum(ids, 0)], 0)
        else:
            # Where a vote with the evidence of partners or continuity follows, this one's labels are
            # only that evidence: a large programme's relaxation suffices, and never takes minutes.
            decided, label, seg, facts = self._vote(
                run, samples, exact_pairs=FIRST_LOOK_PAIRS if with_rigid or with_continuity else None)
            per = np.where(seg >= 0, label[np.maximum(seg, 0)], NULL)
            held = None
        rescored = None
        if again is not None and first is None:
            rescored = again(Labeling(names=labels.names, n_frames=take.n_frames, n_points=take.n_points,
                                      slot=decided.slot, start=decided.start, stop=decided.stop,
                                      label=label.astype(np.int16), confidence=np.zeros(len(decided), np.float32),
                                      locked=np.zeros(len(decided), dtype=bool), info={}))
            if rescored is not None:
                samples, member = rescored
        if with_rigid or with_continuity or rescored is not None:
            if held is None:
                held = np.where(seg >= 0, (decided.stop - decided.start)[np.maximum(seg, 0)], 0)
            extra = self._evidence(run, samples, per, held, member, rigid if with_rigid else None,
                                   partner, continuity if with_continuity else None)
            if extra.any() or first is not None or rescored is not None:
                stopped = facts["work_limited"]
                # Summed in float64 at once: the vote sums in float64 (one copy fewer of a large array).
                total = np.add(samples.logp, extra, dtype=np.float64)
                decided, label, seg, facts = self._vote(run, replace(samples, logp=total))
                facts["work_limited"] += stopped
        run.info.update(facts)
        first_locked = run.locked_at[decided.start, decided.slot]
        return Labeling(names=labels.names, n_frames=take.n_frames, n_points=take.n_points,
                        slot=decided.slot, start=decided.start, stop=decided.stop,
                        label=label.astype(np.int16), confidence=np.zeros(len(decided), dtype=np.float32),
                        locked=first_locked != EMPTY, info=run.info), samples

    @staticmethod
    def _evidence(run: LabelRun, samples: Samples, per: np.ndarray, held: np.ndarray, member: np.ndarray | None,
                  rigid, partner: tuple[float, float], continuity: tuple[float, float] | None) -> np.ndarray:
        """float32 ``(n, L + 1)``: the evidence of rigid partners and of continuity for each sample,
        read off a first decision's labels ``per`` (n,) and its segments' lengths ``held`` (n,)."""
        labels, take, batch = run.labels, run.take, run.batch
        f_idx, k_idx = np.nonzero(batch.mask)
        extra = np.zeros_like(samples.logp)
        at = batch.points[f_idx, k_idx].astype(np.float64)
        n_labels, m = len(labels), labels.m
        # Each hand's evidence for the samples offered to it (the others score its labels at the
        # floor, far below anything the evidence adds).
        rows = [None] if member is None else [np.flatnonzero(member[:, h]) for h in range(labels.hands)]
        if rigid is not None:
            rigid = take_distances(rigid, at, samples.frame, per, n_labels)
            for h, sel in enumerate(rows):  # one entry per hand
                extra += partner_logp(at, samples.frame, per, n_labels, labels.hand_pairs(rigid, h), *partner,
                                      rows=sel)
        if continuity is not None:
            # Per hand: a marker's neighbours, whose motion carries it across a gap, are its own hand's.
            for h in range(labels.hands):
                own = np.where((per >= h * m) & (per < (h + 1) * m), per - h * m, NULL)
                extra[:, h * m:(h + 1) * m] += continuity_logp(at, samples.frame, samples.slot, own, held,
                                                               run.segments, m, take.rate, *continuity,
                                                               rows=rows[h])[:, :m]
        return extra


#: The temporal modes by name; the first is the default.
TEMPORAL_MODES: dict[str, type[TemporalMode]] = {m.name: m for m in (Vote, Viterbi, PerFrame)}
TEMPORAL = tuple(TEMPORAL_MODES)


def temporal_mode(name: str) -> TemporalMode:
    """The registry's mode ``name``; a ValueError naming the choices for an unknown one."""
    try:
        return TEMPORAL_MODES[name]()
    except KeyError:
        raise ValueError(f"unknown temporal mode {name!r}; choose one of {', '.join(TEMPORAL_MODES)}") from None


def fitted_settings(run: LabelRun) -> None:
    """The run's ``info`` with the labeling's facts and the vote's fitted settings: the settings'
    own, else the ones shipped for this method, mode and layout (none for Ghorbani's score)."""
    s, take = run.settings, run.take
    run.info.update({"method": s.method, "temporal": s.temporal, "layout": run.layout.name, "frames": take.n_frames,
                     "slots": take.n_points, "constraints": len(run.constraints), "stride": run.stride})
    likelihood = s.vote_score == "likelihood"
    for key, given, load in (("null_prior", s.null_prior, load_null_prior), ("switch_cost", s.switch_cost,
                                                                             load_switch_cost),
                             ("partner", s.partner, load_partner), ("continuity", s.continuity, load_continuity),
                             ("occlusion_prior", s.occlusion_prior, load_occlusion_prior)):
        value = given if given is not None else \
            load(s.method, s.temporal, run.layout.name) if likelihood else (0.0, 0.0)
        run.info[key] = [float(v) for v in value]
    run.info["break_rate"] = round(break_rate(run.tracklets, take.n_frames, take.rate), 4)  # the scoring's


def null_prior(info: dict) -> tuple[float, float]:
    """The vote's null prior ``(per tracklet, per sample)`` for the take of a run's ``info``: the
    fitted one, its per-sample part lowered where the take's trajectories break often. Under heavy
    occlusion the labeler sees fewer of the hand's markers and more ghosts in each frame, and gives
    the markers it does see less probability; their short trajectories then lose to null."""
    per_tracklet, per_sample = info["null_prior"]
    knee, slope = info["occlusion_prior"]
    return per_tracklet, per_sample - slope * max(0.0, info["break_rate"] - knee)


#: ``info["confidence"]`` of a labeling whose confidences went through a shipped calibration, and of one
#: whose confidences are the labeler's raw probabilities (no calibration for its method and layout).
CALIBRATED = "calibrated"
RAW = "raw (no calibration for this method)"


def calibrate_confidence(run: LabelRun, labeling: Labeling, samples: Samples) -> Labeling:
    """Each segment's evidence and its confidence: the mean probability, mapped through the shipped
    calibration for this method, mode and layout where one exists (locked segments are certain)."""
    s = run.settings
    labeling = split_doubtful_edges(labeling, samples, run.stride)
    labeling.evidence = segment_evidence(labeling, samples)
    labeling.confidence = labeling.evidence[:, 0].copy()  # the mean probability, until calibrated
    calibration = load_calibration(s.method, s.temporal, run.layout.name) if s.calibrate_confidence else None
    run.info["confidence"] = RAW
    if calibration is not None:
        labeling.confidence = calibration(labeling.evidence, labeled=labeling.label >= 0)
        run.info["confidence"] = CALIBRATED
    elif s.calibrate_confidence and not run.method.sure_of_itself:
        # gmm or nearest on a layout nobody calibrated them for: their probabilities were never
        # measured against the truth there, and a high one is no promise, so none is sure.
        labeling.confidence = np.minimum(labeling.confidence, SURE - 1e-3)
        run.info["never_confident"] = "uncalibrated"
        run.info["confidence"] = "capped below sure (no calibration for this layout)"
    labeling.confidence[labeling.locked] = 1.0
    if calibration is not None and calibration.never_sure:
        run.info["never_confident"] = True  # front ends say why every segment is uncertain
    return labeling


def decide(run: LabelRun, scores: np.ndarray, first: Labeling | None = None, samples: Samples | None = None,
           again: LookAgain | None = None) -> Labeling:
    """Per-frame ``scores`` to a labeling with calibrated confidences (:meth:`TemporalMode.decide`,
    then :func:`calibrate_confidence`). ``first``: an earlier labeling whose evidence is read
    instead of a first vote's; ``samples``: the scores as :func:`.scoring.score_samples` gives them."""
    if samples is None:
        samples = score_samples(scores, run.batch)
    labeling, samples = run.mode.decide(run, scores, samples, first, again)
    return calibrate_confidence(run, labeling, samples)


def decide_stage(run: LabelRun) -> None:
    """The first decision: the vote (with the hands' early second look for two hands)."""
    fitted_settings(run)
    run.say(f"temporal step: {run.settings.temporal}")
    t = time.perf_counter()
    run.samples = score_samples(run.scores, run.batch)
    early = (lambda first: look_again(run, first, early=True)) \
        if run.found.count == 2 and run.mode.uses_evidence else None
    run.labeling = decide(run, run.scores, samples=run.samples, again=early)
    run.times["temporal"] = time.perf_counter() - t - run.times.get("hands_again", 0.0)
