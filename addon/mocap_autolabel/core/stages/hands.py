"""Stages about hands: ``find_hands`` (which trajectories are whose) and ``name_sides`` (left and
right, and the labels' names), with the helpers the other stages use to keep two hands apart."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from ..errors import MocapInputError
from ..hands import (
    DEFAULT_NAMING,
    HAND_RADIUS,
    NAMINGS,
    SIDES,
    HandNaming,
    Hands,
    HandTracks,
    SideEvidence,
    add_warning,
    body_side,
    body_side_evidence,
    decide_sides,
    find_hands,
    handedness,
    shape_tells_sides,
    sided_layout_names,
    swap_frames,
    swap_ranges,
    track_hands,
)
from ..labelers import LABELERS
from ..labeling import NULL, Labeling
from ..layout import Layout
from ..settings import Corrections, LabelSettings
from ..take import Take
from ..temporal.partners import RigidPairs, rigid_pairs
from ..temporal.voting import check_constraints
from .run import Attempt, LabelRun, Retry


class HandLabels:
    """The labels a take is decided over: the layout's M for one hand, 2M for two (hand 0's first,
    in the order of :func:`..hands.find_hands` until the sides are known)."""

    def __init__(self, layout: Layout, hands: int):
        self.layout, self.hands = layout, hands
        m = len(layout)
        self.names = list(layout.names) if hands == 1 else [f"{h}:{n}" for h in range(hands) for n in layout.names]
        self.m = m

    def __len__(self) -> int:
        return self.m * self.hands

    def rigid_pairs(self) -> RigidPairs:
        """The layout's rigid pairs, once per hand (never across hands)."""
        one = rigid_pairs(self.layout)
        if self.hands == 1:
            return one
        return RigidPairs(np.concatenate([one.pairs + h * self.m for h in range(self.hands)]),
                          np.tile(one.distance, self.hands), np.tile(one.tolerance, self.hands))

    def hand_pairs(self, rigid: RigidPairs, h: int) -> RigidPairs:
        """The pairs of ``rigid`` (from :meth:`rigid_pairs`) within hand ``h``; all of them for one hand."""
        if self.hands == 1:
            return rigid
        own = rigid.pairs[:, 0] // self.m == h
        return RigidPairs(rigid.pairs[own], rigid.distance[own], rigid.tolerance[own])

    def to_internal(self, label: int, order: list[int]) -> int:
        """A final label (sides' order: left hand first) as the internal one (hands' order)."""
        if label < 0:
            return label
        final_hand, index = divmod(label, self.m)
        return order.index(final_hand) * self.m + index


def hand_order(sides: Sequence[str]) -> list[int]:
    """Final place of each hand (left first) from the hands' sides in their found order."""
    return [0 if s == "left" else 1 for s in sides]


def other_named_points(take: Take, layout: Layout, naming: HandNaming | None = None) -> np.ndarray | None:
    """bool ``(P,)``: slots the file already names that are no marker of ``layout`` (in any side's
    naming): a labeled body or prop, kept out of the hands. None where there are none, or where
    keeping them out would leave under half the layout's markers in the median frame (then the
    names are another labeling of the hand, and everything is relabeled)."""
    own = set(layout.names)
    for conv in ([naming] if naming is not None else [HandNaming(k) for k in NAMINGS]):
        for side in SIDES:
            own.update(conv.names(side, layout))
    out = ~take.unlabeled & np.array([n not in own for n in take.names], dtype=bool)
    if not out.any():
        return None
    # Named points are a body around the hand only where the hand is left to label: a file whose
    # every point has a name of its own (a hand labeled with another layout's names) is relabeled.
    offered = take.valid[:, ~out].sum(axis=1)
    if np.median(offered[take.valid.any(axis=1)]) < len(layout) / 2:
        return None
    return out


def remembered_hands(take: Take, layout: Layout, hands: str | int, ignore: np.ndarray | None,
                     swaps: np.ndarray | None, cache) -> Hands:
    """:func:`..hands.find_hands`, kept in ``cache`` (a copy: callers change ``both``)."""
    tracked = (cache.take_key(take), tuple(layout.names), None if ignore is None else ignore.tobytes())
    key = (*tracked, str(hands), None if swaps is None else swaps.tobytes())

    def tracks() -> HandTracks:  # a pass that finds the hands again with swaps starts from them
        return cache.remember("hand_tracks", tracked, lambda: track_hands(take, layout, ignore))

    found = cache.remember("hands", key, lambda: find_hands(take, layout, hands, ignore=ignore, swaps=swaps,
                                                            tracks=tracks))
    return replace(found, both=found.both.copy(), hand=found.hand.copy(), info=dict(found.info))


def one_of_two(take: Take, layout: Layout, found: Hands, ignore: np.ndarray | None, swaps: np.ndarray | None,
               cache, method: str, joint: str) -> tuple[np.ndarray, Hands]:
    """Two hands found for a method that labels one (``gmm``, ``nearest``): the hand with more samples,
    the other's kept out (the ``ignore`` ``(F, P)`` returned), with a warning that says so. A sparse
    layout's hand beside a body or a prop is often read as two."""
    samples = [int((found.hand == h).sum()) for h in range(2)]
    keep = int(np.argmax(samples))
    other = (found.hand == 1 - keep) & ~found.both
    ignore = other if ignore is None else other | (ignore if ignore.ndim == 2 else ignore[None, :])
    one = remembered_hands(take, layout, "1", ignore, swaps, cache)
    one.info["warning"] = (f"two hands found; {method} labels one hand, the one with more samples "
                           f"({samples[keep]} against {samples[1 - keep]}); {joint} label both")
    return ignore, one


def find_hands_stage(run: LabelRun) -> Retry | None:
    """Which trajectories belong to which hand; the corrections brought to the hands' labels.
    Two hands with corrections and no sides given: a first pass decides the sides (corrections
    name final labels, left hand first), then this pass starts again with them."""
    settings, corrections, take, layout = run.settings, run.corrections, run.take, run.layout
    t0 = time.perf_counter()
    run.naming = HandNaming(settings.naming) if settings.naming is not None else None
    ignore = other_named_points(take, layout, run.naming) if settings.keep_named else None
    if corrections.exclude is not None:
        ignore = corrections.exclude | (False if ignore is None else ignore[None, :])
    run.ignore = ignore
    run.say("finding hands")
    hand_swaps = corrections.hand_swaps
    run.swaps = None if hand_swaps is None else swap_frames(hand_swaps, take.n_frames)
    run.found = found = remembered_hands(take, layout, settings.hand_count, ignore, run.swaps, run.cache)
    run.timed("hands", t0)
    if found.count == 2 and not run.method.labels_two_hands:
        joint = ", ".join(name for name, method in LABELERS.items() if method.labels_two_hands)
        if str(settings.hand_count) == "2":
            raise MocapInputError(take.source or None, f"two hands are labeled with {joint}, not {settings.method} "
                                        "(it labels one hand: leave the hand count to the take, or give 1)")
        run.ignore, found = one_of_two(take, layout, found, ignore, run.swaps, run.cache, settings.method, joint)
        run.found = found
    if found.count == 2 and settings.validate:
        raise ValueError("IK validation works on one hand; the take holds two (force one hand: hands=1)")
    run.labels = HandLabels(layout, found.count)
    constraints = list(corrections.constraints)
    check_constraints(constraints, len(run.labels))
    if found.count == 2 and constraints and settings.sides is None:
        first = Attempt(LabelSettings(method=settings.method, temporal=settings.temporal, model=settings.model,
                                      hand_count=2, keep_named=settings.keep_named, naming=settings.naming),
                        Corrections(hand_swaps=hand_swaps))

        def with_sides(labeled: Labeling) -> Attempt:
            facts = labeled.info["hands"]
            swaps = hand_swaps if hand_swaps is not None else facts.get("swaps", [])
            return replace(run.attempt, settings=settings.but(sides=facts["by_hand_order"]),
                           corrections=corrections.but(hand_swaps=swaps))

        return Retry("deciding the sides before the corrections", first, with_sides)
    if found.count == 2 and settings.sides is not None:
        order = hand_order(settings.sides)
        constraints = [replace(c, label=run.labels.to_internal(c.label, order)) for c in constraints]
    run.constraints = constraints
    return None


def hands_near(found: Hands, near: float) -> np.ndarray:
    """bool ``(F,)``: frames where the two hands' centres are nearer than ``near`` metres."""
    with np.errstate(invalid="ignore"):
        return np.linalg.norm(found.centre[:, 0] - found.centre[:, 1], axis=1) < near


def offer_nulls(found: Hands, labeling: Labeling, take: Take, most: float = np.inf) -> tuple[int, np.ndarray]:
    """Offer to both hands the samples of null segments whose trajectory went to one hand but
    passes within :data:`..hands.HAND_RADIUS` of the other hand's centre; returns how many segments,
    and the frames they hold (to score again). Changes ``found.both`` in place, unless more than
    ``most`` segments would be offered (then nothing is offered and no frames are returned)."""
    per = labeling.per_sample()
    seg = labeling.segment_ids()
    null = (per == NULL) & (found.hand >= 0) & ~found.both
    f, p = np.nonzero(null)
    other = 1 - found.hand[f, p].astype(np.int64)
    centre = found.centre[f, other]
    near = np.linalg.norm(take.positions[f, p] - centre, axis=1) < HAND_RADIUS  # NaN centre: not near
    chosen = np.unique(seg[f[near], p[near]])
    if not len(chosen):
        return 0, np.zeros(0, dtype=np.int64)
    if len(chosen) > most:
        return int(len(chosen)), np.zeros(0, dtype=np.int64)
    offer = np.isin(seg, chosen) & null
    found.both |= offer
    return int(len(chosen)), np.flatnonzero(offer.any(axis=1))


def hand_markers(take: Take, per: np.ndarray, m: int, hand: int) -> np.ndarray:
    """``(F, m, 3)``: hand ``hand``'s labeled markers (labels ``hand * m`` to ``hand * m + m - 1`` of the
    per-sample labels ``per`` ``(F, P)``), metres, NaN where not labeled."""
    observed = np.full((take.n_frames, m, 3), np.nan)
    f, p = np.nonzero((per >= hand * m) & (per < (hand + 1) * m))
    observed[f, per[f, p] - hand * m] = take.positions[f, p]
    return observed


def labeled_centre(observed: np.ndarray) -> np.ndarray:
    """``(F, 3)``: the mean of one hand's labeled markers ``observed`` ``(F, M, 3)`` per frame (metres,
    NaN where none is labeled)."""
    count = np.isfinite(observed[..., 0]).sum(axis=1)
    seen = count > 0  # a mean of frames with labels only: no empty slices
    centre = np.full((len(observed), 3), np.nan)
    centre[seen] = np.nansum(observed[seen], axis=1) / count[seen, None]
    return centre


def labeled_handedness(take: Take, layout: Layout, labeling: Labeling, hands: int) -> np.ndarray:
    """int8 ``(F, hands)``: the handedness of each hand's labeled markers per frame
    (:func:`..hands.handedness`; 0 throughout for a layout of fewer than four markers)."""
    m = len(layout)
    per = labeling.per_sample()
    right = np.zeros((take.n_frames, hands), dtype=np.int8)
    if m < 4:
        return right
    for h in range(hands):
        right[:, h] = handedness(hand_markers(take, per, m, h), layout)
    return right


def body_evidence(take: Take, layout: Layout, labeling: Labeling, hands: int) -> list[SideEvidence | None]:
    """Sides of each hand from the take's side-named body points (:func:`..hands.sides.body_side_evidence`)."""
    named = other_named_points(take, layout)
    if named is None:
        return [None] * hands
    cols = np.flatnonzero(named)
    per = labeling.per_sample()
    centres = np.full((take.n_frames, hands, 3), np.nan)
    for h in range(hands):
        centres[:, h] = labeled_centre(hand_markers(take, per, len(layout), h))
    return body_side_evidence(take.positions[:, cols], [body_side(take.names[c]) for c in cols], centres)


def name_sides_stage(run: LabelRun) -> None:
    """Decide the sides of the hands, put the left hand's labels first and name them; facts in
    ``info["hands"]`` (with the frames where the hands found traded places)."""
    t0 = time.perf_counter()
    take, layout, labeling, found = run.take, run.layout, run.labeling, run.found
    sides, naming, swaps = run.settings.sides, run.naming, run.swaps
    m = len(layout)
    facts = {key: found.info[key] for key in ("present_share", "median_markers", "forced", "both_tracklets",
                                              "cuts", "warning") if key in found.info}
    facts["count"] = found.count
    if found.count == 1 and naming is None and sides is None:
        labeling.info["hands"] = facts
        run.timed("sides", t0)
        return
    if shape_tells_sides(layout):
        evidence = [SideEvidence.of(r) for r in labeled_handedness(take, layout, labeling, found.count).T]
    else:
        evidence = body_evidence(take, layout, labeling, found.count)
        facts["sides_by"] = "body names" if any(e is not None for e in evidence) else "none"
        if sides is None and found.count == 2:
            add_warning(facts, f"layout '{layout.name}' has too few markers off one plane to tell a left hand from a "
                               "right one by shape; " + (
                                   "sides taken from the labeled body's L/R names" if facts["sides_by"] == "body names"
                                   else "no side-named body points either: check the sides (--sides)"))
    side_list, side_facts = decide_sides(evidence, None if sides is None else list(sides))
    if swaps is not None and swaps.any():
        facts["swaps"] = swap_ranges(swaps)
    facts.update(side_facts)
    facts["by_hand_order"] = list(side_list)
    if found.count == 2:
        naming = naming or HandNaming(DEFAULT_NAMING)
        order = hand_order(side_list)
        if order != [0, 1]:
            hand, index = np.divmod(labeling.label.astype(np.int64), m)
            moved = np.where(labeling.label >= 0, np.array(order)[np.clip(hand, 0, 1)] * m + index, labeling.label)
            labeling.label = moved.astype(np.int16)
        side_list = ["left", "right"]
    facts["naming"] = naming.template if naming is not None else None
    labeling.names = sided_layout_names(layout, side_list, naming)
    facts["sides"] = side_list if found.count == 2 else facts["sides"]
    labeling.info["hands"] = facts
    run.timed("sides", t0)
