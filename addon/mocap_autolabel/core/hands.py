"""Hands in a take: how many of a layout's hands it holds, which trajectories belong to which, and
which hand is the left one.

The decision is made over whole trajectories, not frame by frame: a fixed per-frame radius (Han
et al. 2018 cluster markers within 200 mm) fails exactly where hands touch, while a trajectory
that was seen on one hand before the hands met stays on it through the contact.

1. Two hand centres are tracked through the take (2-means seeded on the best separated frame,
   carried frame to frame; a hand that leaves the volume is re-found where points appear far
   from the hand that stayed).
2. Each tracklet goes to the hand whose centre it stays nearer on average (refined twice with
   centres recomputed from the tracklets); one that is nearly as near to both is offered to both
   hands, and the joint vote (:func:`.pipeline.label_take`) decides it with the labels.
3. Where a trajectory truly passes from one hand to the other (a capture-system swap while the
   hands touch), it is cut there.
4. A hand counts when it holds at least a third of the layout's markers in at least a tenth of
   the frames with points (ghosts and stray body markers never do).

Sides: the ``set`` labeler is mirror-blind by design, so handedness is decided afterwards from each
hand's labeled markers: the turn of the layout's most chiral marker tetrahedron, which a mirror
image flips (:func:`chiral_tetrahedron`, :func:`side_evidence`), jointly for two hands (one left,
one right).

Names: a two-hand labeling names its points with a side token (:class:`HandNaming`, e.g.
``L_ThumbTip``); reading a labeled file back (:func:`split_hands`) understands the same
convention.
"""

from __future__ import annotations

import functools
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from .errors import MocapInputError
from .layout import Layout
from .take import Take
from .tracklets import find_tracklets, mask_runs

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
SIDES = ("left", "right")


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


def find_hands(take: Take, layout: Layout, hands: str | int = "auto",
               ignore: np.ndarray | None = None, swaps: np.ndarray | None = None) -> Hands:
    """How many of ``layout``'s hands ``take`` holds and which samples belong to which.

    Args:
        take: the raw take (metres).
        layout: the layout of one hand (M markers).
        hands: ``"auto"``, or 1 / 2 to force the count (a take with one hand where two are forced
            still gets one: ``info["forced"]`` says so).
        ignore: optional bool ``(P,)``: slots kept out of every hand (named body markers), or
            ``(F, P)``: samples kept out (a prop's trajectories).
        swaps: optional bool ``(F,)``: frames where the centre tracker's two hands traded places
            (found by :func:`identity_swaps` on a first labeling): the tracker's hands are swapped
            back there before trajectories are given to them.

    Returns:
        :class:`Hands`.
    """
    hands = str(hands)
    if hands not in HANDS:
        raise ValueError(f"hands must be one of {', '.join(HANDS)}, not {hands!r}")
    m = len(layout)
    valid = take.valid.copy()
    if ignore is not None:
        valid &= ~(ignore if ignore.ndim == 2 else ignore[None, :])
    frames, points = valid.shape
    pos = np.where(valid[..., None], take.positions, np.nan).astype(np.float64)
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
    tracklets = find_tracklets(replace_valid(take, valid))
    ids = tracklets.id_map(frames, points)
    centre, joined, joined_at = _track_centres(pos, valid, ids, m, take.rate)
    if swaps is not None and swaps.any():
        # A tracklet keeps the hand it joined: one that joined where the tracker had the hands
        # swapped joined the other one.
        flip = np.asarray(swaps, dtype=bool)[np.maximum(joined_at, 0)] & (joined >= 0)
        joined = np.where(flip, 1 - joined, joined)
    f_idx, p_idx = np.nonzero(ids >= 0)
    tid = ids[f_idx, p_idx]
    x = pos[f_idx, p_idx]
    n = len(tracklets)
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
    # Is there a second hand? Count the markers each hand holds per frame.
    own = hand_of[tid]
    keep = ~far[tid]
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
    real = (share >= PRESENT_FRAMES) & crowded & (apart or hands == "2")
    info = {"present_share": [round(float(s), 4) for s in share],
            "median_points_both": float(np.median(total)) if len(total) else 0.0,
            "apart_share": round(float(np.mean(gap >= APART)), 4) if len(gap) else 0.0,
            "median_markers": [int(np.median(per_frame[present[:, h], h])) if present[:, h].any() else 0
                               for h in range(2)]}
    if not real.all():
        one.info.update(info, count=1, **({"forced": 2} if hands == "2" else {}))
        if crowded and (share >= PRESENT_FRAMES).all() and not apart:
            one.info["warning"] = (f"the take holds {info['median_points_both']:.0f} points in a typical frame, "
                                   f"{len(layout)} markers per hand, in two groups that never come "
                                   f"{100 * APART:.0f} mm apart: labeled as one hand; if it holds two, use --hands 2")
        return one
    # Two hands: per sample, its tracklet's hand; offered to both where the tracklet is ambiguous.
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


# --- sides -----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SideEvidence:
    """Handedness read off one hand's labeled markers: in how many frames the layout's most
    chiral marker tetrahedron turns as on a right hand (``right``) or as on a left one (``left``)."""

    left: int
    right: int

    @classmethod
    def of(cls, frames: np.ndarray | None) -> SideEvidence | None:
        """The votes of per-frame :func:`handedness` ``(F,)``; None where no frame has one."""
        if frames is None or not frames.any():
            return None
        return cls(left=int((frames < 0).sum()), right=int((frames > 0).sum()))

    @property
    def side(self) -> str:
        return "left" if self.left > self.right else "right"

    @property
    def confidence(self) -> float:
        """The share of frames that agree with :attr:`side` (0.5: no evidence)."""
        total = self.left + self.right
        return 0.5 if total == 0 else max(self.left, self.right) / total

    def log_odds_right(self) -> float:
        """log P(right) / P(left), with one frame of doubt on each side."""
        return float(np.log((self.right + 1) / (self.left + 1)))


@functools.lru_cache(maxsize=16)
def chiral_tetrahedron(layout: Layout, poses: int = 96,
                       seed: int = 0) -> tuple[tuple[int, int, int, int], float] | None:
    """The four markers of ``layout`` whose signed volume keeps its sign best over random poses of
    an average right hand (a mirror image flips it), and that sign's consistency in [0, 1]; None
    for a layout of fewer than four markers."""
    from itertools import combinations

    from .hand.ik import HandSolver
    from .hand.skeleton import N_DOF, HandModel
    from .synth.poses import sample_joint_angles

    if len(layout) < 4:
        return None
    hand = HandModel(side="right")
    pose = np.zeros((poses, N_DOF))
    pose[:, 6:] = sample_joint_angles(np.random.default_rng(seed), poses)
    x = HandSolver(hand, layout.place(hand)[0]).markers(pose)  # (P, M, 3)
    quads = np.array(list(combinations(range(len(layout)), 4)))
    e = x[:, quads[:, 1:]] - x[:, quads[:, :1]]  # (P, Q, 3, 3)
    vol = np.linalg.det(e)  # (P, Q)
    # Consistent sign and not nearly flat: the share of poses with the majority sign, then size.
    sign = np.sign(np.median(vol, axis=0))
    agree = (np.sign(vol) == sign).mean(axis=0)
    size = np.median(np.abs(vol), axis=0) ** (1 / 3)
    best = int(np.lexsort((size, np.round(agree, 2)))[-1])
    q = tuple(int(v) for v in quads[best])
    return (q if sign[best] > 0 else (q[1], q[0], q[2], q[3])), float(agree[best])


def handedness(observed: np.ndarray, layout: Layout) -> np.ndarray | None:
    """int8 ``(F,)``: the handedness of ``observed (F, M, 3)`` labeled markers (metres, NaN where
    missing) in each frame, the sign of :func:`chiral_tetrahedron`'s volume (+1 as on a right
    hand, -1 as on a left one, 0 where its four markers are not all seen); None for a layout of
    fewer than four markers."""
    chiral = chiral_tetrahedron(layout)
    if chiral is None:
        return None
    x = observed[:, list(chiral[0])]
    seen = np.isfinite(x).all(axis=(1, 2))
    out = np.zeros(len(observed), dtype=np.int8)
    out[seen] = np.sign(np.linalg.det(x[seen, 1:] - x[seen, :1]))
    return out


def side_evidence(observed: np.ndarray, layout: Layout) -> SideEvidence | None:
    """Handedness of ``observed (F, M, 3)`` labeled markers over the take (:func:`handedness`);
    None where no frame sees the chiral tetrahedron."""
    return SideEvidence.of(handedness(observed, layout))


#: Nats one frame's handedness of one hand counts for, in :func:`identity_swaps`.
FRAME_NATS = 1.0
#: Nats the two hands found pay to trade places: where the hands touch, every trajectory of one
#: may end and new ones begin nearer the other's centre, and the tracker then carries each hand's
#: identity on with the other hand (seen on long synthetic takes of interacting hands: a third of
#: a 3,000-frame take with the sides the wrong way round). A trade back costs as much: a stretch
#: needs about 24 frames more that say "swapped" than "not" to be called swapped. A labeling's
#: mistakes seldom flip a hand's handedness: at most 8 frames in 3,000 on synthetic takes of
#: interacting hands, while hands that traded places leave few labels (their labelers reject
#: the other hand's points): 15 frames on a 500-frame stretch.
TRADE_NATS = 12.0
#: Metres: the hands trade places only where their centres come this near (or one is lost).
TRADE_DISTANCE = 0.08


def identity_swaps(right: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """bool ``(F,)``: the frames where the two hands found have traded places, against the
    majority of the take.

    A two-state path over the frames (hand 0 is the left hand, or the right one), each frame
    scored by both hands' handedness and changing state only where the hands' centres come within
    :data:`TRADE_DISTANCE`, at :data:`TRADE_NATS` a change (Viterbi).

    Args:
        right: int ``(F, 2)``: each hand's :func:`handedness` per frame.
        centre: ``(F, 2, 3)`` metres: the hands' centres (:attr:`Hands.centre`, NaN where lost).
    """
    frames = len(right)
    if frames == 0:
        return np.zeros(0, dtype=bool)
    # Evidence for state 0 (hand 1 the right one), per frame.
    vote = FRAME_NATS * (right[:, 1].astype(np.float64) - right[:, 0])
    with np.errstate(invalid="ignore"):
        can = ~(np.linalg.norm(centre[:, 0] - centre[:, 1], axis=1) >= TRADE_DISTANCE)
    can[0] = False
    # Between frames where a trade may happen the state holds: one block each, scored as a whole.
    starts = np.concatenate([[0], np.flatnonzero(can)])
    e = np.add.reduceat(vote, starts).tolist()
    came_across = np.zeros((len(e), 2), dtype=bool)  # the best path into (block, state) changed state
    s0, s1 = e[0], -e[0]
    for b in range(1, len(e)):
        a0, a1 = s1 - TRADE_NATS > s0, s0 - TRADE_NATS > s1
        came_across[b] = a0, a1
        s0, s1 = (s1 - TRADE_NATS if a0 else s0) + e[b], (s0 - TRADE_NATS if a1 else s1) - e[b]
    state, path = int(s1 > s0), np.empty(len(e), dtype=np.int8)
    for b in range(len(e) - 1, -1, -1):
        path[b] = state
        if came_across[b, state]:
            state = 1 - state
    per_frame = np.repeat(path, np.diff(np.append(starts, frames)))
    return per_frame != (per_frame.sum() * 2 > frames)


def decide_sides(evidence: list[SideEvidence | None], forced: list[str] | None = None) -> tuple[list[str], dict]:
    """The side of each hand, and facts for the report.

    One hand takes the side most of its frames show. Two hands are one left and one right: the
    one whose frames say "right" more strongly is the right hand (a take whose hands both look
    like right hands is still called one left, one right, and the report warns). ``forced``
    overrides the decision.
    """
    facts: dict = {"frames_left_right": [None if e is None else [e.left, e.right] for e in evidence]}
    if forced is not None:
        if len(forced) != len(evidence) or any(s not in SIDES for s in forced):
            raise ValueError(f"sides must name {len(evidence)} of {', '.join(SIDES)}, not {forced}")
        if len(forced) == 2 and forced[0] == forced[1]:
            raise ValueError("two hands must be one left and one right")
        facts.update(sides=list(forced), confidence=1.0, forced=True)
        return list(forced), facts
    if len(evidence) == 1:
        e = evidence[0]
        sides = ["right" if e is None else e.side]
        facts.update(sides=sides, confidence=0.5 if e is None else round(e.confidence, 4))
        return sides, facts
    a, b = evidence
    ra = 0.0 if a is None else a.log_odds_right()
    rb = 0.0 if b is None else b.log_odds_right()
    # One left, one right: hand b is the right one when its odds beat hand a's.
    sides = ["left", "right"] if rb >= ra else ["right", "left"]
    conf = float(1 / (1 + np.exp(-abs(rb - ra))))
    if a is not None and b is not None and a.side == b.side and min(a.confidence, b.confidence) > 0.9:
        facts["warning"] = (f"both hands look like {a.side} hands ({100 * a.confidence:.0f} % and "
                            f"{100 * b.confidence:.0f} % of their frames); called {sides[0]} and {sides[1]}: "
                            f"check the sides (--sides)")
    facts.update(sides=sides, confidence=round(conf, 4))
    return sides, facts


def swap_ranges(swaps: np.ndarray) -> list[list[int]]:
    """The runs ``[start, stop)`` of frames of a bool ``(F,)`` (:func:`identity_swaps`), for reports."""
    _, start, stop = mask_runs(np.asarray(swaps, dtype=bool)[:, None])
    return [[int(a), int(b)] for a, b in zip(start, stop)]


def traded_text(ranges: Sequence[Sequence[int]], first_frame: int = 0) -> str | None:
    """One line on where the hands traded places (:func:`swap_ranges`' runs, frames numbered from
    ``first_frame``), or None where they did not."""
    if not ranges:
        return None
    return ("hands traded places where they touched, put back in frames "
            + ", ".join(f"{a + first_frame}-{b - 1 + first_frame}" for a, b in ranges))


def swap_frames(ranges: Sequence[Sequence[int]], frames: int) -> np.ndarray:
    """bool ``(F,)`` from :func:`swap_ranges`' runs."""
    out = np.zeros(frames, dtype=bool)
    for a, b in ranges:
        out[max(int(a), 0):max(int(b), 0)] = True
    return out


def _other(side: str) -> str:
    return "left" if side == "right" else "right"


# --- names -----------------------------------------------------------------------------------------

#: Built-in naming conventions for labeled points of a hand; a custom pattern may use
#: ``{S}`` (L / R), ``{side}`` (left / right), ``{Side}`` (Left / Right) and ``{name}``.
NAMINGS = {"prefix": "{S}_{name}", "suffix": "{name}_{S}", "vicon": "{Side}Hand:{name}"}
DEFAULT_NAMING = "prefix"


@dataclass(frozen=True)
class HandNaming:
    """How a labeled point's name carries its hand's side, e.g. ``L_ThumbTip`` or ``LeftHand:ThumbTip``.

    ``pattern`` is one of :data:`NAMINGS`' keys or a pattern with ``{name}`` and one of ``{S}``,
    ``{side}``, ``{Side}``.
    """

    pattern: str = DEFAULT_NAMING

    def __post_init__(self) -> None:
        p = NAMINGS.get(self.pattern, self.pattern)
        if "{name}" not in p or not any(t in p for t in ("{S}", "{side}", "{Side}")):
            raise ValueError(f"hand naming {self.pattern!r} needs {{name}} and one of {{S}}, {{side}}, {{Side}} "
                             f"(or one of {', '.join(NAMINGS)})")

    @property
    def template(self) -> str:
        return NAMINGS.get(self.pattern, self.pattern)

    def name(self, side: str, name: str) -> str:
        return self.template.format(S=side[0].upper(), side=side, Side=side.capitalize(), name=name)

    def names(self, side: str, layout: Layout) -> list[str]:
        return [self.name(side, n) for n in layout.names]


def sided_layout_names(layout: Layout, sides: list[str], naming: HandNaming | None) -> list[str]:
    """Label names of a labeling of ``len(sides)`` hands: the layout's names, with side tokens where
    ``naming`` is given (always given for two hands)."""
    if naming is None:
        return list(layout.names)
    return [n for side in sides for n in naming.names(side, layout)]


def hands_in_names(names: list[str], layout: Layout, naming: HandNaming | None = None) -> dict[str, list[int]]:
    """The hands a labeled take's point ``names`` hold: ``{side: columns in layout order}`` for each
    side whose every layout marker is named by the convention (every built-in one when ``naming``
    is None), else ``{}``. Plain layout names (a one-hand take) give ``{"": columns}``."""
    where = {n: i for i, n in enumerate(names)}
    found: dict[str, list[int]] = {}
    candidates = [naming] if naming is not None else [HandNaming(k) for k in NAMINGS]
    for conv in candidates:
        for side in SIDES:
            cols = [where.get(n, -1) for n in conv.names(side, layout)]
            if min(cols) >= 0 and side not in found:
                found[side] = cols
    if not found and all(n in where for n in layout.names):
        found[""] = [where[n] for n in layout.names]
    return found


def split_hands(take: Take, layout: Layout, naming: HandNaming | None = None) -> list[tuple[str, Take]]:
    """Each hand of a labeled take as ``(side, take)`` whose points carry the layout's plain names
    (side ``""`` for a take labeled with plain names).

    Raises:
        MocapInputError: no hand of ``layout`` is named in the take.
    """
    found = hands_in_names(take.names, layout, naming)
    if not found:
        sided = [n for n in take.names if re.search("|".join(re.escape(x) for x in layout.names), n)]
        hint = f" (names such as {', '.join(sided[:3])} do not follow a known hand naming)" if sided else ""
        raise MocapInputError(take.source, f"is not labeled with layout {layout.name!r}: no hand's markers are "
                                           f"all named{hint}")
    out = []
    for side, cols in found.items():
        res = None if take.residuals is None else take.residuals[:, cols]
        filled = None if take.filled is None else take.filled[:, cols]
        out.append((side, replace(take, positions=take.positions[:, cols], names=list(layout.names), residuals=res,
                                  filled=filled)))
    return out



def labeled_layout(take: Take, naming: HandNaming | None = None) -> Layout:
    """The built-in layout whose hands a labeled take's names carry (plain names, or each hand's
    named by side); of several (a han19 file also names every tips5 marker), the one with most
    markers.

    Raises:
        MocapInputError: no built-in layout's hand is named in the take.
    """
    from .layout import builtin_layouts, load_layout

    best = None
    for name in builtin_layouts():
        layout = load_layout(name)
        if hands_in_names(take.names, layout, naming) and (best is None or len(layout) > len(best)):
            best = layout
    if best is None:
        raise MocapInputError(take.source, f"is not labeled with a built-in layout ({', '.join(builtin_layouts())}): "
                                           f"no hand's markers are all named (label it first, or give --layout)")
    return best


def sided_path(path: str, side: str) -> str:
    """``take.fbx`` -> ``take_left.fbx``: an output of one hand of a two-hand take (unchanged for
    side ``""``, a one-hand take)."""
    if not side:
        return path
    stem, ext = os.path.splitext(path)
    return f"{stem}_{side}{ext}"


# --- a labeling's hands, for whoever shows or relabels it (the Blender review, a re-solve) ----------

def labeling_sides(info: dict) -> list[str]:
    """The side of each hand of a labeling, in label order, from its ``info``: ``["left", "right"]``
    for two hands (labels ``0..M-1`` the left hand's, ``M..2M-1`` the right's), ``[""]`` for one
    (its side, where one was named, stays in the names)."""
    facts = info.get("hands", {}) if info else {}
    if facts.get("count", 1) == 2:
        return list(facts.get("sides") or SIDES)
    return [""]


def relabel_plan(info: dict | None, layout: Layout, hands: str | int = "auto") -> tuple[dict, list[str], bool]:
    """How to label a take again that was labeled before with ``info`` (None: never labeled).

    ``hands`` ``"auto"`` keeps a two-hand labeling's hands and sides (:func:`relabel_options`) and
    lets a one-hand take be found again as the first labeling was; ``1`` / ``2`` force the count.

    Returns:
        ``label_take``'s hand keywords, the label names that labeling will have (where the count
        is known: a one-hand take under ``"auto"`` may still be found to hold two), and whether the
        count of hands changes (then the corrections that name a hand's labels cannot follow).
    """
    earlier = relabel_options(info) if info is not None else {}
    options = earlier
    if str(hands) in ("1", "2"):
        n = int(hands)
        options = earlier if n == 2 and earlier else {"hands": n}
    two = options.get("hands") == 2
    names = sided_layout_names(layout, list(SIDES), options.get("naming", HandNaming())) if two else list(layout.names)
    changed = info is not None and two != bool(earlier)
    return options, names, changed


def relabel_options(info: dict) -> dict:
    """``label_take`` keywords that keep a labeling's hands when the take is labeled again with its
    corrections: the count, each hand's side in :func:`find_hands`' order (so that no labeling run
    is spent deciding them again and every correction's label keeps its hand), the frames where the
    hands traded places (:func:`identity_swaps`) and the naming.
    Empty for a one-hand labeling (labeled again as it was first, ``hands="auto"``)."""
    facts = info.get("hands", {}) if info else {}
    if facts.get("count", 1) != 2:
        return {}
    out: dict = {"hands": 2}
    if facts.get("by_hand_order"):
        out["sides"] = list(facts["by_hand_order"])
    if facts.get("naming"):
        out["naming"] = HandNaming(facts["naming"])
    out["hand_swaps"] = [list(r) for r in facts.get("swaps", [])]
    return out
