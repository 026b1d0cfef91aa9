"""The hands' second look: null trajectories near the other hand offered to both hands and scored again."""

from __future__ import annotations

import time

import numpy as np

from ..labeling import Labeling
from ..temporal.voting import Samples
from .hands import offer_nulls
from .run import LabelRun
from .scoring import all_hand_scores, apply_constraints, joint_scores, offered_to, score_samples

#: The hands' second look is taken right after the first vote, before the evidence of partners
#: and continuity is read off it (one vote fewer), where it offers at most this share of that
#: vote's segments to both hands: hands apart, as han2018's (about 1 % of segments, labels
#: identical to a look after the whole labeling). Hands that touch (5-40 %) take it after the
#: whole labeling, as that evidence then reads off fewer wrong nulls.
LOOK_EARLY_SHARE = 0.03


def look_again(run: LabelRun, looked_at: Labeling, early: bool = False) -> tuple[Samples, np.ndarray] | None:
    """A marker given to the wrong hand is one its labeler rejects: the trajectories ``looked_at``
    left null near the other hand are offered to both hands and scored again (the run's scores
    and samples change). ``early``: ``looked_at`` is the first vote, and the evidence of partners
    and continuity is still to be read off it; where more than :data:`LOOK_EARLY_SHARE` of its
    segments would be offered (hands that touch), nothing is done: the look waits for the whole
    labeling. Returns the samples scored again and the hands each is offered to, or None."""
    most = LOOK_EARLY_SHARE * len(looked_at) if early else np.inf
    offered, rows = offer_nulls(run.found, looked_at, run.take_in, most)
    if offered > most:
        return None
    run.info["hands_offered_again"] = offered
    if not offered:
        return None
    run.say("temporal step: both hands again")
    t = time.perf_counter()
    # A hand whose points did not change keeps its scores (those of a long take are not kept in
    # the cache: passed on here).
    run.hand_scores = [all_hand_scores(run, run.found.members(h), [(run.scored_members[h], run.hand_scores[h])])
                       for h in range(2)]
    run.joint = run.joint.copy()
    run.joint[rows] = joint_scores(run.hand_scores, run.found, run.batch, rows)
    run.member = offered_to(run)
    run.scores = apply_constraints(run.joint, run.batch.slots, run.batch.mask, run.constraints)
    run.samples = score_samples(run.scores, run.batch, rows, run.samples)
    run.times["hands_again"] = time.perf_counter() - t
    return run.samples, run.member
