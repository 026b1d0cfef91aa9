"""Long takes labeled in overlapping windows: time linear in the take, memory bounded by a window.

Labeling holds per-sample arrays of the whole take (scores, log-probabilities, evidence): about
14 KB a frame for one hand and 64 KB for two, so a 30-minute two-hand take at 120 Hz (216,000
frames) would need some 14 GB at once. A take longer than :data:`WINDOW_FRAMES` is labeled
window by window instead, each window overlapping the next by :data:`OVERLAP_FRAMES`, and the
windows' labelings are joined at a cut inside each overlap: the frame there that the fewest
trajectories run through, so that the fewest trajectories are decided by two windows. A
trajectory that runs through a cut is decided by both windows, each of which sees at least half
the overlap of it on the other side of the cut; where the two agree it stays one segment.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from .labeling import Constraint, Labeling
from .layout import Layout
from .take import Take

#: Frames a take may have before it is labeled in windows, and a window's length: the peak memory
#: of a 30,000-frame window is about 0.5 GB with one hand and 2 GB with two.
WINDOW_FRAMES = 30_000
#: Frames two neighbouring windows share (10 s at 120 Hz); the cut between them lies in the middle
#: half of the overlap, so that a window sees at least a quarter of it beyond its cut.
OVERLAP_FRAMES = 1_200


def window_bounds(frames: int, window: int = WINDOW_FRAMES, overlap: int = OVERLAP_FRAMES) -> list[tuple[int, int]]:
    """``[(start, stop)]`` frame ranges of the windows of a take of ``frames`` frames: equal
    lengths of at most ``window`` frames, neighbours overlapping by ``overlap`` (at most a quarter
    of a window)."""
    if frames <= window:
        return [(0, frames)]
    overlap = min(overlap, window // 4)
    step = window - overlap
    n = int(np.ceil((frames - overlap) / step))
    length = int(np.ceil((frames + (n - 1) * overlap) / n))
    starts = [min(i * (length - overlap), frames - length) for i in range(n)]
    return [(s, min(s + length, frames)) for s in starts]


def _cuts(valid: np.ndarray, bounds: list[tuple[int, int]]) -> list[int]:
    """The frame where each window hands over to the next: in the middle half of their overlap,
    where the fewest slots are seen in a frame and the one before it."""
    cuts = [0]
    for (_, stop), (start, _) in zip(bounds[:-1], bounds[1:]):
        lo, hi = start + (stop - start) // 4, stop - (stop - start) // 4
        lo, hi = max(lo, 1), max(hi, lo + 1)
        through = (valid[lo - 1:hi - 1] & valid[lo:hi]).sum(axis=1)
        cuts.append(lo + int(np.argmin(through)))
    cuts.append(valid.shape[0])
    return cuts


def _window_constraints(constraints, start: int, stop: int) -> list[Constraint]:
    out = []
    for c in constraints:
        a, b = max(c.start, start), min(c.stop, stop)
        if a < b:
            out.append(replace(c, start=a - start, stop=b - start))
    return out


def _window_take(take: Take, start: int, stop: int) -> Take:
    part = slice(start, stop)
    return replace(take, positions=take.positions[part],
                   residuals=None if take.residuals is None else take.residuals[part],
                   filled=None if take.filled is None else take.filled[part],
                   first_frame=take.first_frame + start, warnings=[])


def label_in_windows(label: Callable[..., Labeling], take: Take, layout: Layout, window: int = WINDOW_FRAMES,
                     overlap: int = OVERLAP_FRAMES, constraints=(), splits=(), exclude: np.ndarray | None = None,
                     hand_swaps=None, naming=None, sides=None, progress: Callable[[str], None] | None = None,
                     done: Callable[[float], None] | None = None, **options) -> Labeling:
    """Label ``take`` window by window with ``label`` (:func:`.pipeline.label_take`, given the
    other ``options``) and join the windows' labelings.

    Constraints, a reviewer's splits, excluded samples and the hands' swaps are handed to the
    windows they fall in. Where some window holds two hands, every window is named by side (a
    window in which one hand is seen names it by its side), and the labels are those of two hands.
    ``sides``: the sides of the hands in each window's order (a list per window, as the joined
    ``info["hands"]["by_hand_order"]`` gives them), or one list for every window.

    Returns:
        one :class:`.labeling.Labeling` of the whole take; ``info`` is the first window's, with
        ``windows`` (each window's frames, cut, hands and seconds), the seconds of each stage
        summed, and the hands' swaps and props of every window.
    """
    from .hands import DEFAULT_NAMING, HandNaming, sided_layout_names

    bounds = window_bounds(take.n_frames, window, overlap)
    cuts = _cuts(take.valid, bounds)
    say = progress or (lambda _msg: None)

    def one(i: int, naming) -> Labeling:
        start, stop = bounds[i]
        say(f"window {i + 1} of {len(bounds)}: frames {start}-{stop - 1}")
        swaps = None if hand_swaps is None else [[max(a, start) - start, min(b, stop) - start]
                                                  for a, b in hand_swaps if max(a, start) < min(b, stop)]
        inner_done = None if done is None else (lambda share, i=i: done((i + share) / len(bounds)))
        per_window = sides is not None and len(sides) > 0 and not isinstance(sides[0], str)
        return label(_window_take(take, start, stop), layout,
                     constraints=_window_constraints(constraints, start, stop),
                     splits=[(s, f - start) for s, f in splits if start <= f < stop],
                     exclude=None if exclude is None else exclude[start:stop], hand_swaps=swaps,
                     naming=naming, sides=sides[i] if per_window else sides, progress=progress, done=inner_done,
                     window=None, **options)

    parts: list[Labeling] = []
    for i in range(len(bounds)):
        part = one(i, naming)
        if naming is None and part.info.get("hands", {}).get("count") == 2:
            naming = HandNaming(DEFAULT_NAMING)
            parts = [one(j, naming) for j in range(i)]  # windows of one hand before: named by side
        parts.append(part)
    names = parts[0].names
    if any(p.names != names for p in parts):  # two hands somewhere, or one hand seen as either side
        names = sided_layout_names(layout, ["left", "right"], HandNaming(naming) if isinstance(naming, str) else naming)
    return _join(take, parts, bounds, cuts, names)


def _join(take: Take, parts: list[Labeling], bounds, cuts: list[int], names: list[str]) -> Labeling:
    """One labeling of the take from its windows' (each kept between its cuts)."""
    index = {name: i for i, name in enumerate(names)}
    pieces = []
    for i, (part, (start, _)) in enumerate(zip(parts, bounds)):
        lo, hi = cuts[i] - start, cuts[i + 1] - start
        keep = (part.stop > lo) & (part.start < hi)
        to_global = np.array([index[n] for n in part.names], dtype=np.int64)
        label = part.label[keep].astype(np.int64)
        evidence = part.evidence[keep] if part.evidence is not None else np.zeros((int(keep.sum()), 4), np.float32)
        a, b = np.maximum(part.start[keep], lo), np.minimum(part.stop[keep], hi)
        evidence = evidence.copy()
        evidence[:, 3] = b - a
        pieces.append((part.slot[keep], a + start, b + start,
                       np.where(label >= 0, to_global[np.maximum(label, 0)], label),
                       part.confidence[keep], part.locked[keep], evidence))
    slot, start, stop, label, confidence, locked, evidence = (np.concatenate(c) for c in zip(*pieces))
    order = np.lexsort((start, slot))
    slot, start, stop, label, confidence, locked, evidence = (
        a[order] for a in (slot, start, stop, label, confidence, locked, evidence))
    # A trajectory both windows gave one label stays one segment (the lower confidence, the
    # evidence of both weighed by their frames).
    joins = np.flatnonzero((slot[1:] == slot[:-1]) & (start[1:] == stop[:-1]) & (label[1:] == label[:-1])
                           & np.isin(start[1:], cuts[1:-1]))
    for j in joins[::-1]:
        w = evidence[[j, j + 1], 3].astype(np.float64)
        evidence[j, :3] = (evidence[j:j + 2, :3] * w[:, None]).sum(axis=0) / max(w.sum(), 1.0)
        evidence[j, 3] = w.sum()
        stop[j] = stop[j + 1]
        confidence[j] = min(confidence[j], confidence[j + 1])
        locked[j] |= locked[j + 1]
    keep = np.ones(len(slot), dtype=bool)
    keep[joins + 1] = False
    info = dict(parts[0].info)
    info["frames"] = take.n_frames
    info["windows"] = [{"frames": [int(s) + take.first_frame, int(e) - 1 + take.first_frame],
                        "cut": int(cuts[i]), "hands": p.info.get("hands", {}).get("count"),
                        "seconds": p.info.get("seconds", {}).get("total")}
                       for i, (p, (s, e)) in enumerate(zip(parts, bounds))]
    seconds: dict[str, float] = {}
    for p in parts:
        for key, value in p.info.get("seconds", {}).items():
            seconds[key] = round(seconds.get(key, 0.0) + value, 4)
    info["seconds"] = seconds
    info["time_limited"] = sum(p.info.get("time_limited", 0) for p in parts)
    hands = dict(info.get("hands", {}))
    hands["count"] = max(p.info.get("hands", {}).get("count", 1) for p in parts)
    if len(parts) > 1:  # each window's hands in its own order: a re-solve hands them back
        facts = [p.info.get("hands", {}) for p in parts]
        hands["by_hand_order"] = [f.get("by_hand_order") for f in facts]
        if hands["count"] == 2:  # the labels are two hands', the left hand's first, in every window
            hands["sides"] = ["left", "right"]
            hands["naming"] = next((f["naming"] for f in facts if f.get("naming")), None)
        sure = [f["confidence"] for f in facts if "confidence" in f]
        if sure:
            hands["confidence"] = min(sure)  # the least sure window's
        warning = next((f["warning"] for f in facts if f.get("warning")), None)
        if warning:
            hands["warning"] = warning
    swaps = [[a + s, b + s] for p, (s, _) in zip(parts, bounds) for a, b in p.info.get("hands", {}).get("swaps", [])]
    if swaps:
        hands["swaps"] = swaps
    info["hands"] = hands
    props = [{**prop, "frames": [prop["frames"][0] + s, prop["frames"][1] + s]}
             for p, (s, _) in zip(parts, bounds) for prop in p.info.get("props", [])]
    if props:
        info["props"] = props
    return Labeling(names=list(names), n_frames=take.n_frames, n_points=take.n_points, slot=slot[keep],
                    start=start[keep], stop=stop[keep], label=label[keep].astype(np.int16),
                    confidence=confidence[keep].astype(np.float32), locked=locked[keep], info=info,
                    evidence=evidence[keep].astype(np.float32))
