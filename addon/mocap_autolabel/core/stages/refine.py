"""The stages after the first decision: ``refine`` (the hands' second look, hands that traded
places, IK validation) and ``checks`` (two hands against one, rigid props). Each either changes
the run's labeling or returns a :class:`.run.Retry` for the pipeline's loop."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..hands import HAND_RADIUS, Hands, add_warning, identity_swaps, swap_ranges
from ..labeling import Labeling
from ..props import Prop, find_props, prop_mask, rigid_groups
from ..take import Take
from ..temporal.voting import Segments, label_conflicts
from .decide import decide
from .hands import labeled_handedness
from .look import look_again
from .run import Attempt, LabelRun, Retry

#: Below this share of confident labeled samples a labeling is doubtful: two hands are checked
#: against one, and other layouts are tried (:mod:`..process`).
DOUBTFUL_SHARE = 0.5
#: How much more of the samples another reading of the take must label confidently to be preferred.
CLEARLY_BETTER = 0.3


def _traded_places(run: LabelRun) -> np.ndarray | None:
    """Where the hands touched, the tracker may have carried each hand's identity on with the
    other: the labeled markers' handedness says where (bool ``(F,)``; None: nowhere)."""
    if run.found.count != 2 or run.swaps is not None:
        return None
    traded = identity_swaps(labeled_handedness(run.take, run.layout, run.labeling, 2), run.found.centre)
    return traded if traded.any() else None


def refine_stage(run: LabelRun) -> Retry | None:
    """The hands' second look after the whole labeling (hands that touch, or no vote to look again
    after) and the labeling again with its evidence; where the hands traded places, a new pass
    with those frames swapped."""
    traded = _traded_places(run)  # before more work is spent on this labeling
    if run.found.count == 2 and traded is None and "hands_offered_again" not in run.info:
        rescored = look_again(run, run.labeling)
        if rescored is not None:
            run.labeling = decide(run, run.scores, first=run.labeling, samples=rescored[0])
            traded = _traded_places(run)  # the second look labels more of a hand that traded places
    if traded is not None:
        attempt = replace(run.attempt, corrections=run.corrections.but(hand_swaps=swap_ranges(traded)),
                          labeler=run.labeler)
        return Retry("labeling again: the hands traded places where they touched", attempt)
    run.say("decided", run.decided_share)
    return None


def validate_stage(run: LabelRun) -> None:
    """IK validation: fit the hand to the labels, vote again with the fit's evidence and downgrade
    the segments the hand cannot explain (``info["validation"]``)."""
    if not run.settings.validate:
        return
    from ..validate import downgrade, fit_labeling, fit_scores, segment_residuals

    run.say("validating with the hand fit")
    t = time.perf_counter()
    take, batch = run.take, run.batch
    hand, hand_fit = fit_labeling(take, run.layout, run.labeling, run.settings.validate_hand)
    run.labeling = decide(run, run.scores + fit_scores(batch.points, batch.mask, hand_fit.markers,
                                                       spread=hand_fit.overall_rms()))
    residuals = segment_residuals(take, run.labeling, hand_fit)
    run.info["validation"] = {"hand_length_mm": round(hand.length * 1000, 2), "side": hand.side,
                              "marker_rms_mm": round(hand_fit.overall_rms() * 1000, 3),
                              "downgraded_segments": downgrade(run.labeling, residuals)}
    run.timed("validate", t)


#: Share of the take's frames each of two hands apart must be seen in to never be read as one.
BOTH_PRESENT = 0.5


def hands_apart(found: Hands) -> bool:
    """Whether the two hands found are too far apart to be one hand split in two: both seen in
    :data:`BOTH_PRESENT` of the frames, their centres farther than :data:`..hands.HAND_RADIUS` in
    the median frame where both are. (A sparse layout's two hands label few samples confidently;
    read as one hand, they lost every label. One hand's points and a few ghosts, found as two
    hands, are seen together in fewer frames.)"""
    both = np.isfinite(found.centre).all(axis=(1, 2))
    if not both.any() or min(found.info.get("present_share", [0.0])) < BOTH_PRESENT:
        return False
    gap = np.linalg.norm(found.centre[both, 0] - found.centre[both, 1], axis=1)
    return bool(np.median(gap) > HAND_RADIUS)


def one_hand_stage(run: LabelRun) -> Retry | None:
    """Two hands must explain the take better than one: a hand with more markers than the layout
    (a han19 glove labeled with glove13) also splits into two groups of points. Where two hands
    label under :data:`DOUBTFUL_SHARE` of their samples confidently, the take is labeled as one
    hand, which is kept unless two hands do clearly better."""
    settings = run.settings
    if not (run.found.count == 2 and str(settings.hand_count) == "auto" and not run.constraints):
        return None
    single = Attempt(settings.but(hand_count=1, sides=None, validate=False),
                     run.corrections.but(constraints=(), hand_swaps=None), run.labeler)
    if hands_apart(run.found):
        return _no_hand_among_two(run, single)
    two = run.labeling.summary()["confident_share"]
    if two >= DOUBTFUL_SHARE:
        return None

    def better(one_hand: Labeling) -> Labeling | None:
        one = one_hand.summary()["confident_share"]
        if two < one + CLEARLY_BETTER / 3:
            one_hand.info["hands"].update(two_hands_rejected={"two": round(two, 4), "one": round(one, 4)})
            return one_hand
        return None

    return Retry("checking against one hand", single, better)


def _no_hand_among_two(run: LabelRun, single: Attempt) -> Retry | None:
    """Two groups apart, one of which the no-hand rule finds no hand in (:func:`..checks.hand_checks`):
    a few other markers near one hand (a body's, a prop's) hold as many points as a sparse layout's
    hand and were taken for a second hand. The take is labeled as one hand, which is kept where
    the rule finds the hand in it."""
    from ..checks import check_hand, hand_checks

    checks = hand_checks(run.take, run.layout, run.labeling)
    if all(check.found for _, check in checks) or not any(check.found for _, check in checks):
        return None
    not_found = [side for side, check in checks if not check.found]

    def better(one_hand: Labeling) -> Labeling | None:
        if not check_hand(run.take, run.layout, one_hand).found:
            return None
        one_hand.info["hands"].update(two_hands_rejected={"no_hand_in": not_found})
        add_warning(one_hand.info["hands"], f"two groups of points found, and no hand in the {not_found[0]} one: "
                                            f"labeled as one hand; if it holds two, use --hands 2")
        return one_hand

    return Retry("checking against one hand", single, better)


def props_stage(run: LabelRun) -> Retry | None:
    """Rigid props among the trajectories (:mod:`..props`): a rigid group the labeler mostly left
    null, some of which took hand labels, is kept out and the take labeled again."""
    if not (run.settings.props and run.mode.uses_evidence):
        return None
    t = time.perf_counter()
    found = _props(run.take, run.tracklets, run.labeling, len(run.labels), run.cache)
    run.timed("props", t)
    if not found:
        return None
    exclude = prop_mask(found, run.take.n_frames, run.take.n_points)
    if run.corrections.exclude is not None:
        exclude = exclude | run.corrections.exclude
    attempt = Attempt(run.settings.but(props=False), run.corrections.but(exclude=exclude), run.attempt.labeler,
                      run.attempt.notes + (("props", [p.as_dict() for p in found]),))
    return Retry(f"labeling again without {len(found)} rigid prop(s)", attempt)


def _props(take: Take, tracklets, labeling: Labeling, n_labels: int, cache) -> list[Prop]:
    """The rigid props of a labeled take (:func:`..props.find_props`), judged by the labels its
    trajectories mostly took."""
    per = labeling.per_sample()
    ids = tracklets.id_map(take.n_frames, take.n_points)
    f, p = np.nonzero(ids >= 0)
    votes = np.bincount(ids[f, p].astype(np.int64) * (n_labels + 1) + (per[f, p].astype(np.int64) + 1),
                        minlength=len(tracklets) * (n_labels + 1)).reshape(len(tracklets), n_labels + 1)
    positions = np.where(take.valid[..., None], take.positions, np.nan)
    groups = cache.remember("rigid_groups", cache.take_key(take), lambda: rigid_groups(positions, tracklets, take.rate))
    return find_props(positions, tracklets, take.rate, votes.argmax(axis=1) - 1, groups=groups)


def finger_order_stage(run: LabelRun) -> None:
    """The fingers' order over the whole take, checked by the template hand
    (:mod:`..hand.finger_order`) for the layout-conditioned ``set`` model on a sparse set with a
    hand cluster: a hand whose labels fit the hand clearly better in another order is relabeled,
    and the segments moved stay below "sure" for the reviewer (``info["finger_order"]``); then each
    stretch between the hand's trajectories' starts and ends on its own (:func:`..hand.finger_order.
    checked_spans`). Two hands whose sides were read off their markers' shape with doubt are checked
    the other way round too: a permuted labeling can turn that shape. A reviewer's locked label is
    never moved: a hand whose new order would move one keeps its own, and locks keep the sides."""
    from ..hand.finger_order import (
        SIDES_CHECKED_BELOW,
        checked_order,
        checked_sides,
        checked_spans,
        finger_groups,
        labeler_loss,
    )
    from ..review import SURE
    from .hands import hand_markers

    groups = finger_groups(run.layout)
    if groups is None or not getattr(run.labeler, "layout_conditioned", False):  # duck-typed labelers too
        return
    t = time.perf_counter()
    labeling, m = run.labeling, len(run.layout)
    facts = labeling.info["hands"]
    count = facts.get("count", 1)
    sides = facts.get("sides") or [None] * count  # one hand without a naming has no side decided
    per = labeling.per_sample()
    observed = [hand_markers(run.take, per, m, h) for h in range(count)]
    doubtful_sides = (count == 2 and run.settings.sides is None and "sides_by" not in facts
                      and facts.get("confidence", 1.0) < SIDES_CHECKED_BELOW and not labeling.locked.any())
    if doubtful_sides:
        new_sides, found = checked_sides(observed, run.layout, groups, list(sides))
        if new_sides != list(sides):
            _swap_sides(labeling, facts, m, SURE)
            observed = observed[::-1]
            found = found[::-1]
    else:
        lost = [labeler_loss(run.scores, run.batch.slots, per, m, h, groups) for h in range(count)]
        found = [checked_order(o, run.layout, groups, side, cost) for o, side, cost in zip(observed, sides, lost)]
    checked = []
    for h, (side, (order, fit)) in enumerate(zip(sides, found)):
        if not fit:
            continue
        where = f"the {side} hand's " if side and count == 2 else ""
        mine = (labeling.label >= h * m) & (labeling.label < (h + 1) * m)
        checked.append(_reorder(labeling, groups, order, mine, h, m, facts, where) | {"hand": h, **fit})
        if checked[-1].get("kept_for_locks"):
            continue  # the reviewer's locks say which order is right
        # Then each stretch between the hand's trajectories' starts and ends on its own.
        now = labeling.per_sample()
        observed = hand_markers(run.take, now, m, h)
        bounds = np.unique(np.concatenate([[0, labeling.n_frames], labeling.start[mine], labeling.stop[mine]]))

        def lost_in(start: int, stop: int, h: int = h, now: np.ndarray = now) -> np.ndarray:
            return labeler_loss(run.scores[start:stop], run.batch.slots[start:stop], now[start:stop], m, h, groups)

        for start, stop, span_order, span_fit in checked_spans(observed, run.layout, groups, fit["side"], bounds,
                                                               lost_in):
            inside = mine & (labeling.start >= start) & (labeling.stop <= stop)
            first = start + run.take.first_frame
            checked.append(_reorder(labeling, groups, span_order, inside, h, m, facts,
                                    f"{where}frames {first}-{stop - 1 + run.take.first_frame}: ")
                           | {"hand": h, "frames": [start, stop], **span_fit})
    labeling.info["finger_order"] = checked
    run.timed("finger_order", t)


def _reorder(labeling: Labeling, groups: list[list[int]], order: tuple[int, ...], selected: np.ndarray, h: int,
             m: int, facts: dict, where: str) -> dict:
    """The ``selected`` segments of hand ``h`` relabeled under the finger ``order``, below "sure",
    with a warning (``where`` begins it); none where that would move a reviewer's lock. Returns the
    facts of the change."""
    from ..hand.finger_order import FINGERS, label_map
    from ..review import SURE

    new = labeling.label.astype(np.int64)
    new[selected] = h * m + label_map(groups, order, m)[new[selected] - h * m]
    moved = new != labeling.label
    changed = {FINGERS[a]: FINGERS[b] for a, b in enumerate(order) if a != b}
    if (moved & labeling.locked).any():  # a reviewer's label says this finger is right as it is
        return {"kept_for_locks": changed, "moved": {}, "segments": 0}
    # A stretch's order moves only the segments inside it; one running past its ends keeps its
    # label, which a moved segment must not take too (one label, one sample a frame).
    labels = len(labeling.names)
    if label_conflicts(np.where(new >= 0, new, labels), Segments(labeling.slot, labeling.start, labeling.stop),
                       labels):
        return {"kept_for_overlap": changed, "moved": {}, "segments": 0}
    labeling.label = new.astype(labeling.label.dtype)
    labeling.confidence[moved] = np.minimum(labeling.confidence[moved], np.float32(SURE - 1e-3))
    if changed:
        add_warning(facts, f"{where}finger order changed by the template hand's fit ("
                           + ", ".join(f"{a} -> {b}" for a, b in changed.items()) + "): check these fingers")
    return {"moved": changed, "segments": int(moved.sum())}


def _swap_sides(labeling: Labeling, facts: dict, m: int, sure: float) -> None:
    """Two hands' labeling (left hand's labels first) with its hands' sides swapped: each hand's
    labels become the other's, below "sure" (``facts`` say so)."""
    labeled = labeling.label >= 0
    labeling.label = np.where(labeled, (labeling.label.astype(np.int64) + m) % (2 * m),
                              labeling.label).astype(labeling.label.dtype)
    labeling.confidence[labeled] = np.minimum(labeling.confidence[labeled], np.float32(sure - 1e-3))
    facts["by_hand_order"] = facts["by_hand_order"][::-1]
    facts["sides_by"] = "the template hand's fit"
    add_warning(facts, "the sides read off the markers' shape were swapped by the template hand's fit: "
                       "check the sides (--sides)")


def holders_stage(run: LabelRun) -> None:
    """Which trajectory holds each marker, checked by the template hand (:mod:`..hand.holders`) for
    the layout-conditioned ``set`` model on a sparse set with a hand cluster: a null trajectory
    that fits the hand clearly better in a label's place than the trajectory holding that label
    takes it over its frames (the holder's samples there become null). What moved stays below
    "sure"; a reviewer's locked sample is never moved (``info["holders"]``)."""
    from ..hand.calibrate import detect_side
    from ..hand.finger_order import hand_cluster
    from ..hand.holders import MIN_FRAMES, MOST, better_holders
    from ..labeling import EMPTY, NULL
    from ..review import SURE, relabel_samples
    from .hands import hand_markers, labeled_centre

    layout = run.layout
    if not (hand_cluster(layout) and getattr(run.labeler, "layout_conditioned", False)):
        return
    t = time.perf_counter()
    labeling, m, take = run.labeling, len(layout), run.take
    facts = labeling.info["hands"]
    count = facts.get("count", 1)
    sides = facts.get("sides") or [None] * count
    per = labeling.per_sample()
    positions = take.positions  # NaN where no sample
    pieces = np.flatnonzero((labeling.label == NULL) & (labeling.length >= MIN_FRAMES) & ~labeling.locked)
    pieces = pieces[np.lexsort((labeling.start[pieces], labeling.slot[pieces], -labeling.length[pieces]))]
    locked = labeling.per_sample_locked()
    moved = np.zeros(per.shape, dtype=bool)
    taken = []
    for h, side in enumerate(sides):
        observed = hand_markers(take, per, m, h)
        centre = labeled_centre(observed)
        near = [i for i in pieces if _near(positions, centre, labeling.slot[i], labeling.start[i], labeling.stop[i])]
        if not near:
            continue
        fitted = [f["side"] for f in labeling.info.get("finger_order", []) if f["hand"] == h and "side" in f]
        try:  # the side the finger-order check solved the hand as, where it ran
            side = side or (fitted[0] if fitted else detect_side(observed, layout))
        except ValueError:  # no frame the template can be solved on
            continue
        candidates = [(int(labeling.slot[i]), int(labeling.start[i]), int(labeling.stop[i])) for i in near[:MOST]]
        for holder in better_holders(positions, observed, candidates, layout, side):
            label = h * m + holder.label
            span = slice(holder.start, holder.stop)
            others = per[span] == label
            if moved[span, holder.slot].any() or (moved[span] & others).any():
                continue  # one change per sample: the better one came first
            if locked[span][others].any():
                continue
            per[span][others] = NULL
            moved[span] |= others
            ok = per[span, holder.slot] != EMPTY
            per[span, holder.slot] = np.where(ok, label, per[span, holder.slot])
            moved[span, holder.slot] |= ok
            taken.append({"hand": h, "slot": holder.slot, "frames": [holder.start, holder.stop],
                          "label": labeling.names[label], "residual_mm": round(holder.before * 1000, 2),
                          "fitted_mm": round(holder.fitted * 1000, 2)})
    if taken:
        run.labeling = labeling = relabel_samples(labeling, per, moved, cap=SURE - 1e-3)
        first = take.first_frame
        where = ", ".join(f"{t['label']} in frames {t['frames'][0] + first}-{t['frames'][1] - 1 + first}"
                          for t in taken)
        add_warning(labeling.info["hands"], f"given to another trajectory by the template hand's fit (a ghost "
                                            f"riding with the hand held it?): {where}: check them")
    labeling.info["holders"] = taken
    run.timed("holders", t)


def _near(positions: np.ndarray, centre: np.ndarray, slot: int, start: int, stop: int) -> bool:
    """Whether a trajectory piece stays within :data:`..hands.HAND_RADIUS` of a hand's labeled
    centre ``(F, 3)`` (NaN where none) in its median frame."""
    with np.errstate(invalid="ignore"):
        d = np.linalg.norm(positions[start:stop, slot] - centre[start:stop], axis=1)
    d = d[np.isfinite(d)]
    return bool(len(d)) and float(np.median(d)) < HAND_RADIUS
