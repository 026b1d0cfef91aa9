"""Which trajectories of a take belong to which hand: two hand centres tracked through the take,
tracklets given to the hand they stay nearer, trajectories cut where they pass from one hand to the
other, and the count of hands (:func:`find_hands`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..layout import Layout
from ..take import Take
from ..tracklets import Tracklets, find_tracklets

#: Metres: a marker farther than this from its hand's centre is not of that hand.
HAND_RADIUS = 0.16
#: Metres: a tracklet whose mean distances to the two hand centres differ by less than this is
#: offered to both hands (the labels decide).
AMBIGUOUS = 0.025
#: A hand holds at least this share of the layout's markers in a frame where it is present...
PRESENT_SHARE = 1 / 3
#: ... in at least this share of the frames that have points.
PRESENT_FRAMES = 0.1
#: Two hands hold more than this many times the layout's markers in the median frame where both
#: are present (one hand's ghosts stay below: the 316 han2018 raw takes of the temporal benchmark
#: reach at most 1.16 points per marker in their median frame).
CROWDED = 1.35
#: Metres between the nearest points of two hands that are apart: two hands come this far apart in
#: at least :data:`PRESENT_FRAMES` of the frames where both are seen, one hand's points split in
#: two hardly ever (synthetic han19 takes split for glove13, tips3: at most 4 % of frames; two
#: interacting synthetic hands: 12-93 %). Force ``hands=2`` for hands that never let go.
APART = 0.06
#: Seconds a trajectory must stay nearer the other hand (by :data:`SWAP_MARGIN`) to be cut there.
SWAP_SECONDS = 0.1
SWAP_MARGIN = 0.04
#: Seconds after which a hand unseen is lost (its centre no longer attracts points).
LOST_SECONDS = 0.25
HANDS = ("auto", "1", "2")


def add_warning(facts: dict, line: str) -> None:
    """Append ``line`` to the hands' facts' ``"warning"`` (one line, its parts joined by "; ")."""
    facts["warning"] = "; ".join(filter(None, [facts.get("warning"), line]))


@dataclass
class Hands:
    """Which hand each sample of a take belongs to.

    Attributes:
        count: hands found (0, 1 or 2).
        hand: int8 ``(F, P)``: hand index of every sample (0 or 1), -1 for none or no sample.
        both: bool ``(F, P)``: samples offered to both hands (their tracklet is nearly as near to
            each); ``hand`` then holds the nearer one.
        centre: float ``(F, 2, 3)`` metres: each hand's centre per frame (NaN where unseen).
        cuts: ``(slot, frame)`` where a trajectory passes from one hand to the other.
        info: facts for reports (per hand: frames present, median markers; tracklets offered to both).
    """

    count: int
    hand: np.ndarray
    both: np.ndarray
    centre: np.ndarray
    cuts: list[tuple[int, int]] = field(default_factory=list)
    info: dict = field(default_factory=dict)

    def members(self, h: int) -> np.ndarray:
        """bool ``(F, P)``: the samples offered to hand ``h``."""
        return (self.hand == h) | (self.both & (self.hand >= 0))


def _two_means(x: np.ndarray, iterations: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """2-means of points ``(n, 3)`` seeded with the farthest pair: centres ``(2, 3)``, labels ``(n,)``."""
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    a, b = np.unravel_index(np.argmax(d), d.shape)
    c = x[[a, b]].copy()
    lab = np.zeros(len(x), dtype=np.int64)
    for _ in range(iterations):
        lab = np.argmin(np.linalg.norm(x[:, None] - c[None], axis=2), axis=1)
        for h in range(2):
            if (lab == h).any():
                c[h] = x[lab == h].mean(axis=0)
    return c, lab


def _seed_frame(pos: np.ndarray, valid: np.ndarray, m: int) -> int:
    """The frame where the points split best into two groups of hand size (most points first)."""
    counts = valid.sum(axis=1)
    candidates = np.argsort(-counts, kind="stable")[:64]
    best, best_score = int(candidates[0]), -np.inf
    for f in candidates:
        x = pos[f, valid[f]]
        if len(x) < 4:
            continue
        c, lab = _two_means(x)
        n = np.bincount(lab, minlength=2)
        if n.min() < max(3, m / 3):  # a stray ghost is no hand
            continue
        # Best: the two groups' nearest points far apart for their size.
        gap = np.min(np.linalg.norm(x[lab == 0][:, None] - x[lab == 1][None], axis=2))
        spread = np.mean(np.linalg.norm(x - c[lab], axis=1)) + 1e-3
        score = gap / spread + min(n.min(), m) / m
        if score > best_score:
            best, best_score = int(f), score
    return best


def _track_centres(pos: np.ndarray, valid: np.ndarray, ids: np.ndarray, m: int,
                   rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two hand centres ``(F, 2, 3)`` carried frame to frame from the seed frame (NaN where lost),
    the hand each tracklet joined when first seen (-1 never near a hand) and the frame it joined
    (the tracker runs forward and backward from the seed frame).

    A tracklet keeps the hand it joined: identity is carried through a contact by the trajectories
    that live through it, and only trajectories born near both hands are placed by distance.
    """
    frames = len(pos)
    centre = np.full((frames, 2, 3), np.nan)
    joined = np.full(int(ids.max()) + 1 if ids.size and ids.max() >= 0 else 0, -1, dtype=np.int64)
    joined_at = np.full(len(joined), -1, dtype=np.int64)
    t0 = _seed_frame(pos, valid, m)
    x = pos[t0, valid[t0]]
    if len(x) < 2:
        return centre, joined, joined_at
    c0, lab0 = _two_means(x)
    joined[ids[t0, valid[t0]]] = lab0
    joined_at[ids[t0, valid[t0]]] = t0
    lost_after = max(1, int(LOST_SECONDS * rate))
    # Each frame's points as one slice of flat arrays: the loop below runs once per frame, so its
    # numpy calls are kept few (both hands' sums in one product).
    rows, cols = np.nonzero(valid)
    bounds = np.searchsorted(rows, np.arange(frames + 1))
    flat_x, flat_id = pos[rows, cols], ids[rows, cols]
    which = np.arange(2)[:, None]
    alive_at = np.zeros((frames, 2), dtype=bool)
    for order in (range(t0, frames), range(t0 - 1, -1, -1)):
        c = c0.copy()
        unseen = np.zeros(2, dtype=np.int64)
        for f in order:
            lo, hi = bounds[f], bounds[f + 1]
            if hi > lo:
                x, tid = flat_x[lo:hi], flat_id[lo:hi]
                lab = joined[tid]
                new = lab < 0
                if new.any():
                    alive = unseen < lost_after
                    d = ((x[new, None] - c[None]) ** 2).sum(axis=2)
                    d[:, ~alive] = np.inf
                    near = np.argmin(d, axis=1)
                    lab[new] = np.where(d[np.arange(len(near)), near] < HAND_RADIUS ** 2, near, -1)
                    # Points far from every live hand: a lost hand comes back there.
                    lost = np.flatnonzero(unseen >= lost_after)
                    if len(lost) and (lab < 0).sum() >= 3:
                        lab[lab < 0] = lost[0]
                    joined[tid[new]] = lab[new]
                    joined_at[tid[new]] = f
                mine = lab == which  # (2, k)
                count = mine.sum(axis=1)
                seen = count >= 2
                c[seen] = (mine @ x)[seen] / count[seen, None]
                unseen = np.where(seen, 0, unseen + 1)
            else:
                unseen += 1
            alive_at[f] = unseen < lost_after
            centre[f] = c
    centre[~alive_at] = np.nan
    return centre, joined, joined_at


def _spread(frames: np.ndarray, most: int) -> np.ndarray:
    """At most ``most`` of ``frames``, evenly spread (a share over them needs no more)."""
    if len(frames) <= most:
        return frames
    return frames[np.linspace(0, len(frames) - 1, most).astype(np.int64)]


def _hand_gap(pos: np.ndarray, hand: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Metres between the nearest points of hand 0 and hand 1 in each of ``frames``."""
    out = np.full(len(frames), np.inf)
    for a in range(0, len(frames), 1024):
        f = frames[a:a + 1024]
        x, h = np.nan_to_num(pos[f]), hand[f]
        # |a - b|^2 = |a|^2 + |b|^2 - 2 a.b as a batched product: the (F, P, P, 3) differences cost
        # ten times as much. Points of neither hand are moved a kilometre away.
        p0 = np.where((h == 0)[..., None], x, 1e3)
        p1 = np.where((h == 1)[..., None], x, -1e3)
        d2 = (p0 * p0).sum(axis=2)[:, :, None] + (p1 * p1).sum(axis=2)[:, None, :] - 2 * p0 @ p1.transpose(0, 2, 1)
        both = (h == 0).any(axis=1) & (h == 1).any(axis=1)
        out[a:a + 1024] = np.where(both, np.sqrt(np.maximum(d2.min(axis=(1, 2)), 0.0)), np.inf)
    return out


def _fill(centre: np.ndarray) -> np.ndarray:
    """``centre (F, 3)`` with its NaN frames filled by the nearest seen frame's value (all NaN stays)."""
    ok = np.isfinite(centre[:, 0])
    if not ok.any() or ok.all():
        return centre
    idx = np.where(ok, np.arange(len(centre)), 0)
    np.maximum.accumulate(idx, out=idx)
    first = int(np.argmax(ok))
    idx[:first] = first
    return centre[idx]


@dataclass(frozen=True)
class HandTracks:
    """A take's trajectories and the hand each joined in the centre tracker (:func:`track_hands`):
    ``tracklets``, the tracklet of each sample ``ids`` int ``(F, P)`` (-1: none), and per tracklet
    the hand it ``joined`` ``(n,)`` (-1: never near one) and the frame it joined at ``(n,)``."""

    tracklets: Tracklets
    ids: np.ndarray
    joined: np.ndarray
    joined_at: np.ndarray


def _kept(take: Take, ignore: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The samples offered to the hands, bool ``(F, P)``, and their positions ``(F, P, 3)`` float64
    (metres, NaN elsewhere): ``ignore`` as in :func:`find_hands`."""
    valid = take.valid.copy()
    if ignore is not None:
        valid &= ~(ignore if ignore.ndim == 2 else ignore[None, :])
    return valid, np.where(valid[..., None], take.positions, np.nan).astype(np.float64)


def track_hands(take: Take, layout: Layout, ignore: np.ndarray | None = None) -> HandTracks:
    """The first step of :func:`find_hands`: two hand centres carried through the take and the hand
    each trajectory joined (``ignore`` as there). Hands found again with other swaps start here."""
    valid, pos = _kept(take, ignore)
    tracklets = find_tracklets(replace_valid(take, valid))
    ids = tracklets.id_map(*valid.shape)
    _, joined, joined_at = _track_centres(pos, valid, ids, len(layout), take.rate)
    return HandTracks(tracklets, ids, joined, joined_at)


def find_hands(take: Take, layout: Layout, hands: str | int = "auto",
               ignore: np.ndarray | None = None, swaps: np.ndarray | None = None,
               tracks: Callable[[], HandTracks] | None = None) -> Hands:
    """How many of ``layout``'s hands ``take`` holds and which samples belong to which.

    Args:
        take: the raw take (metres).
        layout: the layout of one hand (M markers).
        hands: ``"auto"``, or 1 / 2 to force the count (a take with one hand where two are forced
            still gets one: ``info["forced"]`` says so).
        ignore: optional bool ``(P,)``: slots kept out of every hand (named body markers), or
            ``(F, P)``: samples kept out (a prop's trajectories).
        swaps: optional bool ``(F,)``: frames where the centre tracker's two hands traded places
            (found by :func:`.sides.identity_swaps` on a first labeling): the tracker's hands are swapped
            back there before trajectories are given to them.
        tracks: called for :func:`track_hands` of the same take and ``ignore`` where they are
            needed (a cache's: passes that find the hands again with swaps track them once).

    Returns:
        :class:`Hands`.
    """
    hands = str(hands)
    if hands not in HANDS:
        raise ValueError(f"hands must be one of {', '.join(HANDS)}, not {hands!r}")
    m = len(layout)
    valid, pos = _kept(take, ignore)
    frames, points = valid.shape
    one = Hands(1, np.where(valid, 0, -1).astype(np.int8), np.zeros_like(valid), np.full((frames, 2, 3), np.nan),
                info={"count": 1})
    if hands == "1" or not valid.any():
        return one
    counts = valid.sum(axis=1)
    if (counts >= CROWDED * m).sum() < PRESENT_FRAMES * (counts > 0).sum():
        # Too few crowded frames for two hands even before any point is set aside: no need to look.
        one.info.update(count=1, crowded_share=round(float((counts >= CROWDED * m).mean()), 4))
        if hands == "2":
            one.info["forced"] = 2
        return one
    tracked = tracks() if tracks is not None else track_hands(take, layout, ignore)
    tracklets, ids, joined = tracked.tracklets, tracked.ids, tracked.joined
    if swaps is not None and swaps.any():
        # A tracklet keeps the hand it joined: one that joined where the tracker had the hands
        # swapped joined the other one.
        flip = np.asarray(swaps, dtype=bool)[np.maximum(tracked.joined_at, 0)] & (joined >= 0)
        joined = np.where(flip, 1 - joined, joined)
    f_idx, p_idx = np.nonzero(ids >= 0)
    samples = _Samples(f_idx, p_idx, ids[f_idx, p_idx], pos[f_idx, p_idx])
    near = _nearer_hands(joined, samples, len(tracklets), frames)
    share, crowded, apart, info = _presence(pos, valid, samples, near, m)
    real = (share >= PRESENT_FRAMES) & crowded & (apart or hands == "2")
    if not real.all():
        return _as_one_hand(one, info, hands, crowded, share, apart, layout)
    return _two_hands(take, tracklets, ids, samples, near, info)


@dataclass(frozen=True)
class _Samples:
    """The samples of a take that belong to a tracklet, flat: frame ``f_idx``, slot ``p_idx``,
    tracklet ``tid`` and position ``x`` ``(S, 3)`` of each."""

    f_idx: np.ndarray
    p_idx: np.ndarray
    tid: np.ndarray
    x: np.ndarray


@dataclass(frozen=True)
class _Nearer:
    """Each tracklet's hand (:func:`_nearer_hands`): ``hand_of`` ``(n,)``, ``far`` ``(n,)`` (near
    neither hand), ``mean`` ``(n, 2)`` mean distance to each hand's centre, ``centre`` ``(F, 2, 3)``
    the centres from whole tracklets, ``d`` ``(S, 2)`` each sample's distance to each centre."""

    hand_of: np.ndarray
    far: np.ndarray
    mean: np.ndarray
    centre: np.ndarray
    d: np.ndarray


def _nearer_hands(joined: np.ndarray, samples: _Samples, n: int, frames: int) -> _Nearer:
    """Each of ``n`` tracklets to the hand whose centre it stays clearly nearer, starting from the
    hand it ``joined`` in the tracker (three rounds, centres recomputed from whole tracklets)."""
    f_idx, tid, x = samples.f_idx, samples.tid, samples.x
    length = np.maximum(np.bincount(tid, minlength=n), 1)
    hand_of = joined.copy()
    far = hand_of < 0
    for _ in range(3):
        # Centres from whole tracklets, then each tracklet to the hand it stays clearly nearer.
        own, keep = hand_of[tid], ~far[tid]
        centre = np.full((frames, 2, 3), np.nan)
        for h in range(2):
            sel = keep & (own == h)
            count = np.bincount(f_idx[sel], minlength=frames)
            for k in range(3):
                s = np.bincount(f_idx[sel], weights=x[sel, k], minlength=frames)
                with np.errstate(invalid="ignore", divide="ignore"):
                    centre[:, h, k] = np.where(count > 0, s / np.maximum(count, 1), np.nan)
        filled = np.stack([_fill(centre[:, h]) for h in range(2)], axis=1)
        d = np.linalg.norm(x[:, None] - filled[f_idx], axis=2)  # (S, 2)
        d = np.where(np.isfinite(d), d, 2 * HAND_RADIUS)
        mean = np.stack([np.bincount(tid, weights=np.minimum(d[:, h], 2 * HAND_RADIUS), minlength=n) / length
                         for h in range(2)], axis=1)
        nearer = np.argmin(mean, axis=1)
        switch = (hand_of < 0) | (mean[np.arange(n), np.maximum(hand_of, 0)] - mean[np.arange(n), nearer] > AMBIGUOUS)
        hand_of = np.where(switch, nearer, hand_of)
        far = mean[np.arange(n), hand_of] > HAND_RADIUS
    return _Nearer(hand_of, far, mean, centre, d)


def _presence(pos: np.ndarray, valid: np.ndarray, samples: _Samples, near: _Nearer,
              m: int) -> tuple[np.ndarray, bool, bool, dict]:
    """Is there a second hand? Each hand's share of the frames with points where it holds a third of
    the ``m`` markers, whether two hands crowd the typical frame with more points than one hand has
    markers, whether they come apart now and then, and the facts for the report."""
    f_idx, p_idx, tid = samples.f_idx, samples.p_idx, samples.tid
    frames, points = valid.shape
    # Count the markers each hand holds per frame.
    own = near.hand_of[tid]
    keep = ~near.far[tid]
    per_frame = np.stack([np.bincount(f_idx[keep & (own == h)], minlength=frames) for h in range(2)], axis=1)
    with_points = max(int(valid.any(axis=1).sum()), 1)
    present = per_frame >= max(3, int(np.ceil(PRESENT_SHARE * m)))
    share = present.sum(axis=0) / with_points
    # A hand split in two looks like two small hands: two hands also hold more points than one
    # hand has markers, in the typical frame where both are present.
    both_present = present.all(axis=1)
    total = per_frame.sum(axis=1)[both_present]
    crowded = bool(len(total)) and float(np.median(total)) >= CROWDED * m
    # ... and come apart now and then: one hand's points split in two always touch.
    sample_hand = np.full((frames, points), -1, dtype=np.int64)
    sample_hand[f_idx, p_idx] = np.where(keep, own, -1)
    gap = _hand_gap(pos, sample_hand, _spread(np.flatnonzero(both_present), 2000))
    apart = bool(len(gap)) and float(np.mean(gap >= APART)) >= PRESENT_FRAMES
    info = {"present_share": [round(float(s), 4) for s in share],
            "median_points_both": float(np.median(total)) if len(total) else 0.0,
            "apart_share": round(float(np.mean(gap >= APART)), 4) if len(gap) else 0.0,
            "median_markers": [int(np.median(per_frame[present[:, h], h])) if present[:, h].any() else 0
                               for h in range(2)]}
    return share, crowded, apart, info


def _as_one_hand(one: Hands, info: dict, hands: str, crowded: bool, share: np.ndarray, apart: bool,
                 layout: Layout) -> Hands:
    """``one`` (the whole take as one hand) with the facts of the second hand that was not real, and a
    warning where two groups of hand size never came apart."""
    one.info.update(info, count=1, **({"forced": 2} if hands == "2" else {}))
    if crowded and (share >= PRESENT_FRAMES).all() and not apart:
        one.info["warning"] = (f"the take holds {info['median_points_both']:.0f} points in a typical frame, "
                               f"{len(layout)} markers per hand, in two groups that never come "
                               f"{100 * APART:.0f} mm apart: labeled as one hand; if it holds two, use --hands 2")
    return one


def _two_hands(take: Take, tracklets, ids: np.ndarray, samples: _Samples, near: _Nearer, info: dict) -> Hands:
    """Two hands: per sample, its tracklet's hand (hand 0 the one at lower x), offered to both where
    the tracklet is ambiguous; trajectories that pass from one hand to the other are cut there."""
    f_idx, p_idx, tid = samples.f_idx, samples.p_idx, samples.tid
    hand_of, far, mean, centre, d = near.hand_of, near.far, near.mean, near.centre, near.d
    frames, points = ids.shape
    n = len(tracklets)
    margin = np.abs(mean[:, 0] - mean[:, 1])
    hand = np.full((frames, points), -1, dtype=np.int8)
    hand[f_idx, p_idx] = np.where(far[tid], -1, hand_of[tid])
    both = np.zeros((frames, points), dtype=bool)
    both[f_idx, p_idx] = (margin[tid] < AMBIGUOUS) & ~far[tid]
    if np.nanmean(centre[:, 0, 0]) > np.nanmean(centre[:, 1, 0]):  # hand 0: the one at lower x
        hand_of, mean, centre = 1 - hand_of, mean[:, ::-1], centre[:, ::-1]
        d = d[:, ::-1]
        info["present_share"], info["median_markers"] = info["present_share"][::-1], info["median_markers"][::-1]
    cuts = _swap_cuts(tracklets, hand_of, far, d, f_idx, p_idx, tid, take.rate)
    for slot, frame, h in cuts:
        stop = tracklets.stop[ids[frame, slot]]
        run = slice(frame, stop)
        hand[run, slot] = np.where(hand[run, slot] >= 0, h, -1)
    info.update(count=2, both_tracklets=int(((margin < AMBIGUOUS) & ~far).sum()), tracklets=n,
                far_tracklets=int(far.sum()), cuts=len(cuts))
    return Hands(2, hand, both, centre, [(s, f) for s, f, _ in cuts], info)


def replace_valid(take: Take, valid: np.ndarray) -> Take:
    """``take`` with the samples outside ``valid`` made missing."""
    return replace(take, positions=np.where(valid[..., None], take.positions, np.nan).astype(np.float32))


def _swap_cuts(tracklets, hand_of: np.ndarray, far: np.ndarray, d: np.ndarray, f_idx: np.ndarray,
               p_idx: np.ndarray, tid: np.ndarray, rate: float) -> list[tuple[int, int, int]]:
    """``(slot, frame, new hand)`` where a tracklet stays nearer the other hand for good (to its end,
    for at least :data:`SWAP_SECONDS`)."""
    need = max(3, int(SWAP_SECONDS * rate))
    own = hand_of[tid]
    other_nearer = (d[np.arange(len(tid)), 1 - own] + SWAP_MARGIN < d[np.arange(len(tid)), own]) & ~far[tid]
    cuts = []
    # Per tracklet: the last run of "other nearer" that reaches its end, if long enough and if the
    # tracklet was on its own hand for as long before.
    order = np.lexsort((f_idx, tid))
    t_sorted, flip = tid[order], other_nearer[order]
    bounds = np.flatnonzero(np.diff(np.concatenate([[-1], t_sorted, [len(hand_of)]])))
    for a, b in zip(bounds[:-1], bounds[1:]):
        run = flip[a:b]
        if len(run) < 2 * need or not run[-1]:
            continue
        tail = len(run) - int(np.argmin(run[::-1])) if not run.all() else 0
        if len(run) - tail >= need and tail >= need:
            i = order[a + tail]
            cuts.append((int(p_idx[i]), int(f_idx[i]), int(1 - hand_of[tid[i]])))
    return cuts
