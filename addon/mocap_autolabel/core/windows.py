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

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from .cache import RunCache
from .hands import DEFAULT_NAMING, HandNaming, sided_layout_names, swap_frames
from .labeling import EMPTY, Labeling
from .layout import Layout
from .settings import WINDOW_FRAMES, Corrections, LabelSettings
from .stages.hands import other_named_points, remembered_hands
from .take import Take

#: ``label(take, settings, corrections, progress)``: a take labeled whole (the pipeline's passes).
LabelWhole = Callable[[Take, LabelSettings, Corrections, Callable[[str, float], None]], Labeling]
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
    """The frame where each window hands over to the next: the quietest in the middle half of
    their overlap (:func:`_quiet_frame`)."""
    middles = [_quiet_frame(valid, start + (stop - start) // 4, stop - (stop - start) // 4)
               for (_, stop), (start, _) in zip(bounds[:-1], bounds[1:])]
    return [0, *middles, valid.shape[0]]


def _quiet_frame(valid: np.ndarray, lo: int, hi: int) -> int:
    """The frame in ``[lo, hi)`` that the fewest trajectories run through (seen in it and the frame before)."""
    lo = max(lo, 1)
    hi = max(hi, lo + 1)
    through = (valid[lo - 1:hi - 1] & valid[lo:hi]).sum(axis=1)
    return lo + int(np.argmin(through))


def _corrections_in(start: int, stop: int, corrections: Corrections) -> Corrections:
    """The constraints, splits, hands' swaps and excluded samples that fall in frames
    ``[start, stop)``, in that stretch's own frames."""
    clipped = []
    for c in corrections.constraints:
        a, b = max(c.start, start), min(c.stop, stop)
        if a < b:
            clipped.append(replace(c, start=a - start, stop=b - start))
    hand_swaps = corrections.hand_swaps
    return Corrections(
        constraints=clipped,
        splits=[(slot, frame - start) for slot, frame in corrections.splits if start <= frame < stop],
        hand_swaps=None if hand_swaps is None else
        [[max(a, start) - start, min(b, stop) - start] for a, b in hand_swaps if max(a, start) < min(b, stop)],
        exclude=None if corrections.exclude is None else corrections.exclude[start:stop])


def _window_take(take: Take, start: int, stop: int) -> Take:
    part = slice(start, stop)
    return replace(take, positions=take.positions[part],
                   residuals=None if take.residuals is None else take.residuals[part],
                   filled=None if take.filled is None else take.filled[part],
                   first_frame=take.first_frame + start, warnings=[])


def label_in_windows(label: LabelWhole, take: Take, layout: Layout, settings: LabelSettings,
                     corrections: Corrections, progress: Callable[[str, float], None],
                     overlap: int = OVERLAP_FRAMES) -> Labeling:
    """Label ``take`` window by window of ``settings.window`` frames with ``label`` and join the
    windows' labelings.

    Constraints, a reviewer's splits, excluded samples and the hands' swaps are handed to the
    windows they fall in. Where some window holds two hands, every window is named by side (a
    window in which one hand is seen names it by its side), and the labels are those of two hands.
    ``settings.sides``: the sides of the hands in each window's order (a list per window, as the
    joined ``info["hands"]["by_hand_order"]`` gives them), or one list for every window.

    Returns:
        one :class:`.labeling.Labeling` of the whole take; ``info`` is the first window's, with
        ``windows`` (each window's frames, cut, hands and seconds), the seconds of each stage
        summed, and the hands' swaps and props of every window.
    """
    bounds = window_bounds(take.n_frames, settings.window, overlap)
    cuts = _cuts(take.valid, bounds)
    sides = settings.sides
    per_window = sides is not None and len(sides) > 0 and not isinstance(sides[0], str)

    def one(i: int, naming) -> Labeling:
        start, stop = bounds[i]
        progress(f"window {i + 1} of {len(bounds)}: frames {start}-{stop - 1}", i / len(bounds))
        window_settings = settings.but(naming=naming, sides=sides[i] if per_window else sides, window=None)
        return label(_window_take(take, start, stop), window_settings, _corrections_in(start, stop, corrections),
                     lambda message, share: progress(message, (i + share) / len(bounds)))

    naming = settings.naming
    parts: list[Labeling] = []
    for i in range(len(bounds)):
        part = one(i, naming)
        if naming is None and part.info.get("hands", {}).get("count") == 2:
            naming = DEFAULT_NAMING
            parts = [one(j, naming) for j in range(i)]  # windows of one hand before: named by side
        parts.append(part)
    names = parts[0].names
    if any(p.names != names for p in parts):  # two hands somewhere, or one hand seen as either side
        names = sided_layout_names(layout, ["left", "right"], None if naming is None else HandNaming(naming))
    return _join(take, parts, bounds, cuts, names)


def _splice(parts: list[Labeling], offsets: list[int], cuts: list[int], names: list[str], n_frames: int,
            n_points: int) -> Labeling:
    """One labeling of ``n_frames`` frames from ``parts``, part ``i`` (whose frame 0 is frame
    ``offsets[i]`` of the whole) kept from ``cuts[i]`` to ``cuts[i + 1]``; labels mapped by name to
    ``names``. ``info`` is left empty."""
    index = {name: i for i, name in enumerate(names)}
    known = all(part.missing_mm is not None for part in parts)  # each unlabeled piece's distance to a missing marker
    pieces = []
    for i, (part, start) in enumerate(zip(parts, offsets)):
        lo, hi = cuts[i] - start, cuts[i + 1] - start
        keep = (part.stop > lo) & (part.start < hi)
        to_global = np.array([index[n] for n in part.names], dtype=np.int64)
        label = part.label[keep].astype(np.int64)
        evidence = part.evidence[keep] if part.evidence is not None else np.zeros((int(keep.sum()), 4), np.float32)
        a, b = np.maximum(part.start[keep], lo), np.minimum(part.stop[keep], hi)
        evidence = evidence.copy()
        evidence[:, 3] = b - a
        missing = part.missing_mm[keep] if known else np.full(int(keep.sum()), -1, np.int32)
        pieces.append((part.slot[keep], a + start, b + start,
                       np.where(label >= 0, to_global[np.maximum(label, 0)], label),
                       part.confidence[keep], part.locked[keep], evidence, missing))
    slot, start, stop, label, confidence, locked, evidence, missing = (np.concatenate(c) for c in zip(*pieces))
    order = np.lexsort((start, slot))
    slot, start, stop, label, confidence, locked, evidence, missing = (
        a[order] for a in (slot, start, stop, label, confidence, locked, evidence, missing))
    # A trajectory both parts gave one label (locked by both or by neither) stays one segment: the
    # lower confidence, the evidence of both weighed by their frames.
    joins = np.flatnonzero((slot[1:] == slot[:-1]) & (start[1:] == stop[:-1]) & (label[1:] == label[:-1])
                           & (locked[1:] == locked[:-1]) & np.isin(start[1:], cuts[1:-1]))
    for j in joins[::-1]:
        w = evidence[[j, j + 1], 3].astype(np.float64)
        evidence[j, :3] = (evidence[j:j + 2, :3] * w[:, None]).sum(axis=0) / max(w.sum(), 1.0)
        evidence[j, 3] = w.sum()
        stop[j] = stop[j + 1]
        confidence[j] = min(confidence[j], confidence[j + 1])
        both = missing[j:j + 2]
        missing[j] = both[both >= 0].min() if (both >= 0).any() else -1  # the nearer
    keep = np.ones(len(slot), dtype=bool)
    keep[joins + 1] = False
    return Labeling(names=list(names), n_frames=n_frames, n_points=n_points, slot=slot[keep],
                    start=start[keep], stop=stop[keep], label=label[keep].astype(np.int16),
                    confidence=confidence[keep].astype(np.float32), locked=locked[keep], info={},
                    evidence=evidence[keep].astype(np.float32),
                    missing_mm=missing[keep].astype(np.int32) if known else None)


def _join(take: Take, parts: list[Labeling], bounds, cuts: list[int], names: list[str]) -> Labeling:
    """One labeling of the take from its windows' (each kept between its cuts)."""
    joined = _splice(parts, [start for start, _ in bounds], cuts, names, take.n_frames, take.n_points)
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
    info["work_limited"] = sum(p.info.get("work_limited", 0) for p in parts)
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
    joined.info = info
    return joined


#: Seconds on each side of what a reviewer changed that a re-solve labels again (at least
#: :data:`MIN_PAD_FRAMES` frames): a correction moves the labels of trajectories that overlap it and
#: of their neighbours; the cut back to the earlier labeling lies in the outer half of this margin.
RESOLVE_PAD_S = 5.0
MIN_PAD_FRAMES = 200
#: A re-solve whose changes, with their margins, cover more than this share of the take labels it whole.
LOCAL_SHARE = 0.5
#: Samples of the margins outside the cuts that the local labeling must label as the earlier one
#: did; fewer, and the take is labeled whole (the region's hands were told apart otherwise).
AGREE = 0.9


def changed_frames(previous: Labeling, constraints, splits) -> list[tuple[int, int]] | None:
    """Frame ranges ``[(start, stop)]`` that a reviewer's corrections changed since ``previous``
    was labeled: locks added, changed or removed, splits added or removed (``info["locks"]`` and
    ``info["splits"]``, as :func:`.pipeline.label_take` records them). None where ``previous`` does
    not record them."""
    if "locks" not in previous.info or "splits" not in previous.info:
        return None
    before = {tuple(c) for c in previous.info["locks"]}
    now = {(int(c.slot), int(c.start), int(c.stop), int(c.label)) for c in constraints}
    ranges = [(c[1], c[2]) for c in before ^ now]
    cuts_before = {tuple(s) for s in previous.info["splits"]}
    cuts_now = {(int(slot), int(frame)) for slot, frame in splits}
    ranges += [(f, f + 1) for _, f in cuts_before ^ cuts_now]
    return sorted(ranges)


def relabel_around(label: LabelWhole, take: Take, layout: Layout, previous: Labeling, settings: LabelSettings,
                   corrections: Corrections, progress: Callable[[str, float], None],
                   cache: RunCache | None = None) -> Labeling | None:
    """A re-solve that labels again only the frames around what a reviewer changed since
    ``previous`` (:func:`changed_frames`, each range with :data:`RESOLVE_PAD_S` seconds on either
    side) and keeps ``previous`` elsewhere: its time is that of the changed stretch, whatever the
    take's length (a 10,000-frame two-hand take: about 4x faster than labeling it whole).

    The stretch is labeled as a take of its own with the corrections that fall in it, each hand
    with the side ``previous`` gave most of its markers there, and joined to ``previous`` at a cut
    in the outer half of each margin where the fewest trajectories run through. A trajectory that
    runs through a cut keeps ``previous``'s label outside it.

    Returns:
        the labeling, or None where the take must be labeled whole: nothing changed, the changes
        cover most of the take, ``previous`` does not fit the take or records no corrections, or
        the stretch's labeling disagrees with ``previous`` beyond the cuts (hands told apart
        otherwise).
    """
    t0 = time.perf_counter()
    if (previous.n_frames, previous.n_points) != (take.n_frames, take.n_points):
        return None
    ranges = changed_frames(previous, corrections.constraints, corrections.splits)
    if not ranges:
        return None
    pad = max(MIN_PAD_FRAMES, int(round(RESOLVE_PAD_S * take.rate)))
    regions: list[list[int]] = []
    for start, stop in ranges:
        a, b = max(0, start - pad), min(take.n_frames, stop + pad)
        if regions and a <= regions[-1][1]:
            regions[-1][1] = max(regions[-1][1], b)
        else:
            regions.append([a, b])
    if sum(b - a for a, b in regions) > LOCAL_SHARE * take.n_frames:
        return None
    two = previous.info.get("hands", {}).get("count", 1) == 2
    before = previous.per_sample()
    current = previous
    for a, b in regions:
        part = _window_take(take, a, b)
        local = _corrections_in(a, b, corrections)
        if two:
            local_sides = _sides_from(part, layout, before[a:b], settings.naming, local.hand_swaps, cache)
            if local_sides is None:
                return None
            local_settings = settings.but(hand_count=2, sides=local_sides, window=None)
        else:
            local_settings = settings.but(hand_count=1, window=None)
        progress(f"labeling frames {a}-{b - 1} again, around the changes", 0.0)
        new = label(part, local_settings, local, progress)
        if new.names != previous.names:
            return None
        cut_left = a if a == 0 else _quiet_frame(take.valid, a + pad // 4, a + pad // 2)
        cut_right = b if b == take.n_frames else _quiet_frame(take.valid, b - pad // 2, b - pad // 4)
        # Beyond the cuts the stretch's labeling must be the earlier one's, or the hands were mixed up.
        mine = new.per_sample()
        outside = np.zeros(b - a, dtype=bool)
        outside[:cut_left - a] = True
        outside[cut_right - a:] = True
        seen = (before[a:b] != EMPTY) & outside[:, None]
        if seen.any() and (mine[seen] == before[a:b][seen]).mean() < AGREE:
            return None
        current = _splice([current, new, current], [0, a, 0], [0, cut_left, cut_right, take.n_frames],
                          list(previous.names), take.n_frames, take.n_points)
    info = {key: value for key, value in previous.info.items() if key not in ("seconds", "locks", "splits")}
    info["relabeled"] = [[int(a), int(b)] for a, b in regions]
    info["seconds"] = {"total": round(time.perf_counter() - t0, 4)}
    current.info = info
    return current


def _sides_from(part: Take, layout: Layout, before: np.ndarray, naming: str | None, hand_swaps,
                cache=None) -> list[str] | None:
    """The sides of the two hands :func:`.hands.find_hands` finds in ``part``, in its order: the side
    whose labels the earlier labeling ``before`` (``(F, P)`` of ``part``'s frames) gave most of each
    hand's samples. None where both come out one side."""
    naming = HandNaming(naming) if isinstance(naming, str) else naming
    swaps = None if hand_swaps is None else swap_frames(hand_swaps, part.n_frames)
    found = remembered_hands(part, layout, 2, other_named_points(part, layout, naming), swaps,
                             cache if cache is not None else RunCache())
    if found.count != 2:
        return None
    m = len(layout)
    sides = []
    for h in range(2):
        held = before[found.members(h)]
        held = held[held >= 0]
        sides.append("left" if (held < m).sum() >= (held >= m).sum() else "right")
    return sides if sides[0] != sides[1] else None
