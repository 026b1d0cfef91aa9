"""The fingers' order over a whole take, checked by the template hand.

On sparse sets (five fingertips and a hand cluster) a labeler that sees one frame at a time gets
whole trajectories wrong under one permutation of the fingers for the whole take (the thumb taken
for the index, three fingers cycled); the vote then holds that order throughout. The average
template hand, solved on a few well-seen frames under each candidate order of the fingers, fits the
true order clearly better where the labeling's own order is wrong: the order whose median marker
residual is :data:`MARGIN` of the labeling's own, or less, replaces it.

Only layouts whose five fingers carry the same markers (one fingertip each, or a tip and a
proximal marker each) and that have at least three markers on the hand's back or wrist are checked:
without a hand frame, five tips alone fit several orders about equally well.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np

from ..layout import Layout, Marker
from .calibrate import detect_side
from .ik import HandSolver
from .skeleton import HandModel

#: The fingers, as the hand model's bone names begin.
FINGERS = ("thumb", "index", "middle", "ring", "little")
#: Well-seen frames the template hand is solved on (evenly spread over the take).
FRAMES = 40
#: Another order replaces the labeling's where its median residual is at most this share of the
#: labeling's own (a labeling right already fits best, or within noise).
MARGIN = 0.9
#: A stretch of the take between the starts and ends of a hand's labeled trajectories, at least this
#: many frames long, is checked on its own too (:func:`checked_spans`): the vote may hold a wrong
#: order over a few trajectories' pieces only ...
SPAN_FRAMES = 16
#: ... solved on this many of its frames; weighed with the labeler's word (:data:`EVIDENCE_WEIGHT`)
#: against :data:`MARGIN` as the whole take is. The template alone, an order replaces the stretch's
#: where its median residual is at most this share of the labeling's (fewer frames: a wider margin).
SPAN_SAMPLE = 8
SPAN_MARGIN = 0.7
#: Stretches checked per hand at most, the longest first: a bound on the work (a long take's
#: trajectories break into hundreds of stretches), never on time.
SPANS = 4
#: Two hands' sides read off their markers' shape (:func:`..hands.decide_sides`) are checked by the
#: template hand where that decision's confidence is below this: where both hands look like one
#: side, or their shapes flicker (a labeling with permuted fingers can turn a hand's shape).
SIDES_CHECKED_BELOW = 0.99
#: Markers on the hand's back or wrist (bones ``palm`` and ``*_meta``) that make the hand frame.
HAND_MARKERS = 3
#: The labeler's word in the whole take's and each stretch's check: the log-likelihood (nats) its
#: scores lose when the hand's labeled samples take another order's labels, per frame the template
#: is solved on, counts this much against that order's log residual ratio. Without it the template
#: alone moves orders the labeler was sure of; fitted on han2018 tips + hand cluster takes (the
#: closing notes of issue 46 give the figures).
EVIDENCE_WEIGHT = 0.03
#: Residuals below this (metres, under a marker's noise) count as this in that ratio: a perfect fit
#: is no infinite evidence.
RESIDUAL_FLOOR = 0.0005


def _role(marker: Marker) -> str:
    """A marker's place on its finger, comparable across the fingers (the thumb has no middle phalanx)."""
    segment = marker.bone.split("_", 1)[1]
    return "tip" if segment == "dist" and marker.along >= 0.5 else segment


def hand_cluster(layout: Layout) -> bool:
    """Whether ``layout`` has at least :data:`HAND_MARKERS` markers on the hand's back or wrist: a
    hand frame the template hand's fit can stand on."""
    return sum(m.bone == "palm" or m.bone.endswith("_meta") for m in layout.markers) >= HAND_MARKERS


def finger_groups(layout: Layout) -> list[list[int]] | None:
    """Each finger's markers (indices into ``layout``, in the same order of roles for every finger),
    thumb first; None where the layout cannot be checked (see the module's docstring)."""
    groups, roles = [], None
    for finger in FINGERS:
        members = sorted((_role(m), i) for i, m in enumerate(layout.markers)
                         if m.bone.startswith(finger + "_") and not m.bone.endswith("_meta"))
        these = [r for r, _ in members]
        if not members or "tip" not in these or (roles is not None and these != roles):
            return None
        roles = these
        groups.append([i for _, i in members])
    return groups if hand_cluster(layout) else None


def candidate_orders() -> list[tuple[int, ...]]:
    """The orders tried, the labeling's own first: every swap of two fingers, and every cycle of
    three that moves the thumb (the confusions seen on han2018's sparse sets). ``order[a]`` is the
    finger that finger ``a``'s labels become."""
    identity = tuple(range(len(FINGERS)))
    out = [identity]
    for a, b in itertools.combinations(identity, 2):
        order = list(identity)
        order[a], order[b] = b, a
        out.append(tuple(order))
    for a, b in itertools.permutations(identity[1:], 2):  # thumb -> a -> b -> thumb
        order = list(identity)
        order[0], order[a], order[b] = a, b, 0
        out.append(tuple(order))
    return out


def label_map(groups: list[list[int]], order: tuple[int, ...], m: int) -> np.ndarray:
    """int ``(M,)``: the label each label becomes under the finger ``order``."""
    out = np.arange(m)
    for a, b in enumerate(order):
        out[groups[a]] = groups[b]
    return out


def _well_seen(observed: np.ndarray, frames: int) -> np.ndarray:
    """Up to ``frames`` frame indices with the most labeled markers, spread over the take."""
    seen = np.isfinite(observed[..., 0]).sum(axis=1)
    best = np.flatnonzero(seen == seen.max())
    if len(best) < frames // 2:
        best = np.flatnonzero(seen >= max(4, seen.max() - 1))
    return best[np.linspace(0, len(best) - 1, min(frames, len(best))).astype(int)]


def _per_solved_frame(lost: np.ndarray | None, observed: np.ndarray, frames: int) -> np.ndarray | None:
    """The labeler's loss per order (:func:`labeler_loss`) per frame :func:`order_residuals` solves the
    template on (``frames`` of ``observed``), as :func:`_chosen` weighs it; None stays None."""
    return None if lost is None else lost / len(_well_seen(observed, frames))


def order_residuals(observed: np.ndarray, layout: Layout, groups: list[list[int]], side: str,
                    frames: int = FRAMES) -> np.ndarray | None:
    """float ``(len(candidate_orders()),)``: the median marker residual (metres) of the ``side``
    template hand solved on up to ``frames`` well-seen frames of one hand's labeled markers
    ``observed`` ``(F, M, 3)`` (metres, NaN where unlabeled) under each candidate order; None where
    no frame shows four markers."""
    if np.isfinite(observed[..., 0]).sum(axis=1).max(initial=0) < 4:
        return None
    frames = _well_seen(observed, frames)
    hand = HandModel(side=side)
    solver = HandSolver(hand, layout.place(hand)[0])
    orders = candidate_orders()
    m = len(layout)
    stack = np.empty((len(orders), len(frames), m, 3))
    for i, order in enumerate(orders):
        stack[i][:, label_map(groups, order, m)] = observed[frames]
    stack = stack.reshape(-1, m, 3)
    residuals = solver.evaluate(solver.cold_start(stack), stack).residuals.reshape(len(orders), -1)
    with np.errstate(invalid="ignore"):
        return np.array([np.median(r[np.isfinite(r)]) if np.isfinite(r).any() else np.inf for r in residuals])


def labeler_loss(scores: np.ndarray, slots: np.ndarray, per: np.ndarray, m: int, hand: int,
                 groups: list[list[int]]) -> np.ndarray:
    """float ``(len(candidate_orders()),)``: the log-likelihood (nats, >= 0) the labeler's ``scores``
    ``(F, K, labels + 1)`` (log-probabilities of the packed observations whose take slots are
    ``slots`` ``(F, K)``, -1 for padding) lose when hand ``hand``'s labeled samples (per-sample
    labels ``per`` ``(F, P)``, ``m`` a hand) take each candidate order's labels instead of their own.
    Each finger label's score is the better of the hands' (the sides may have been named after
    scoring, swapping the hands' label blocks)."""
    f, k = np.nonzero(slots >= 0)
    label = per[f, slots[f, k]] - hand * m
    mine = (label >= 0) & (label < m)
    f, k, label = f[mine], k[mine], label[mine]
    hands = max(1, (scores.shape[2] - 1) // m)
    by_label = np.fmax.reduce(scores[f, k, :hands * m].reshape(len(f), hands, m), axis=1).astype(np.float64)
    # A constraint's -inf, or a sample never offered to the hand (NaN): a large finite loss.
    by_label = np.maximum(np.nan_to_num(by_label, nan=-1e4), -1e4)
    rows = np.arange(len(f))
    total = np.array([by_label[rows, label_map(groups, order, m)[label]].sum() for order in candidate_orders()])
    return np.maximum(total[0] - total, 0.0)


def _chosen(median: np.ndarray, margin: float = MARGIN, lost: np.ndarray | None = None) -> int:
    """The candidate order kept: the best, where it is clearly better than the labeling's own (index
    0); ``lost`` (nats per solved frame, :func:`labeler_loss`) counts against each order too."""
    if lost is None or not np.isfinite(median[0]) or median[0] <= 0:
        best = int(np.argmin(median))  # the first of equals: the labeling's own order wins ties
        return best if median[best] <= margin * median[0] else 0
    floored = np.maximum(median, RESIDUAL_FLOOR)
    cost = np.log(floored / floored[0]) + EVIDENCE_WEIGHT * lost
    best = int(np.argmin(cost))
    return best if cost[best] <= np.log(margin) else 0


def _decided(median: np.ndarray, side: str, margin: float = MARGIN,
             lost: np.ndarray | None = None) -> tuple[tuple[int, ...], dict]:
    """The order kept (:func:`_chosen`) from :func:`order_residuals`' ``median``, and its facts: the
    side, the median residuals in mm of the labeling's order and the chosen one."""
    chosen = _chosen(median, margin, lost)
    return candidate_orders()[chosen], {"side": side, "residual_mm": round(float(median[0]) * 1000, 2),
                                        "chosen_mm": round(float(median[chosen]) * 1000, 2)}


def checked_order(observed: np.ndarray, layout: Layout, groups: list[list[int]],
                  side: str | None = None, lost: np.ndarray | None = None) -> tuple[tuple[int, ...], dict]:
    """The finger order the template hand fits best for one hand's labeled markers ``observed``
    ``(F, M, 3)`` (metres, NaN where unlabeled): the labeling's own unless another is clearly better
    (:data:`MARGIN`); and the facts (side, median residuals in mm of the labeling's order and the
    chosen one). ``side``: the hand's, where known (else the side the template fits better in the
    labeling's own order). ``lost``: what each order costs the labeler's scores
    (:func:`labeler_loss`, nats), weighed against the fit (:data:`EVIDENCE_WEIGHT`)."""
    identity = tuple(range(len(groups)))
    try:
        side = side or detect_side(observed, layout)
    except ValueError:  # no frame the template can be solved on
        return identity, {}
    median = order_residuals(observed, layout, groups, side)
    if median is None:
        return identity, {}
    return _decided(median, side, lost=_per_solved_frame(lost, observed, FRAMES))


def checked_sides(observed: list[np.ndarray], layout: Layout, groups: list[list[int]],
                  sides: list[str]) -> tuple[list[str], list[tuple[tuple[int, ...], dict]]]:
    """Two hands' sides and finger orders as the template hand fits them: ``observed`` holds each
    hand's labeled markers ``(F, M, 3)``, ``sides`` the sides decided (one left, one right). The
    other way round replaces them where its summed residual (each hand under its best order) is
    at most :data:`MARGIN` of theirs: a labeling whose fingers are permuted can turn the
    handedness read off its markers. Returns the sides and each hand's :func:`checked_order`."""
    fitted = [{s: order_residuals(o, layout, groups, s) for s in ("left", "right")} for o in observed]
    if any(r is None for f in fitted for r in f.values()):
        return sides, [checked_order(o, layout, groups, s) for o, s in zip(observed, sides)]

    def cost(assigned: list[str]) -> float:
        return sum(float(f[s][_chosen(f[s])]) for f, s in zip(fitted, assigned))

    other = sides[::-1]
    if cost(other) <= MARGIN * cost(sides):
        sides = other
    return sides, [_decided(f[s], s) for f, s in zip(fitted, sides)]


def checked_spans(observed: np.ndarray, layout: Layout, groups: list[list[int]], side: str,
                  bounds: np.ndarray, lost_in: Callable[[int, int], np.ndarray] | None = None,
                  ) -> list[tuple[int, int, tuple[int, ...], dict]]:
    """Stretches of one hand's labeled markers ``observed`` ``(F, M, 3)`` whose finger order the
    template hand fits clearly better otherwise: ``(start, stop, order, facts)`` for each stretch
    between consecutive ``bounds`` (sorted frames where the hand's labeled trajectories start or end)
    of at least :data:`SPAN_FRAMES` frames, the :data:`SPANS` longest. ``lost_in(start, stop)``: what
    each order costs the labeler's scores in those frames (:func:`labeler_loss`), weighed against the
    fit as for the whole take; without it the template alone decides (:data:`SPAN_MARGIN`)."""
    spans = [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:]) if b - a >= SPAN_FRAMES]
    margin = SPAN_MARGIN if lost_in is None else MARGIN
    out = []
    for start, stop in sorted(sorted(spans, key=lambda ab: ab[0] - ab[1])[:SPANS]):
        part = np.full_like(observed, np.nan)
        part[start:stop] = observed[start:stop]
        median = order_residuals(part, layout, groups, side, frames=SPAN_SAMPLE)
        if median is None:
            continue
        lost = _per_solved_frame(None if lost_in is None else lost_in(start, stop), part, SPAN_SAMPLE)
        if _chosen(median, margin, lost):
            out.append((start, stop, *_decided(median, side, margin, lost)))
    return out
