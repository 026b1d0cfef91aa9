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

Sides: the ``set`` labeler is mirror-blind by design, so handedness is decided afterwards by the
IK fit of a left against a right hand to each hand's labeled markers (:func:`side_evidence`),
jointly for two hands (one left, one right).

Names: a two-hand labeling names its points with a side token (:class:`HandNaming`, e.g.
``L_ThumbTip``); reading a labeled file back (:func:`split_hands`) understands the same
convention.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from .errors import MocapInputError
from .layout import Layout
from .take import Take
from .tracklets import find_tracklets

#: Metres: a marker farther than this from its hand's centre is not of that hand.
HAND_RADIUS = 0.16
#: Metres: a tracklet whose mean distances to the two hand centres differ by less than this is
#: offered to both hands (the labels decide).
AMBIGUOUS = 0.025
#: A hand holds at least this share of the layout's markers in a frame where it is present...
PRESENT_SHARE = 1 / 3
#: ... in at least this share of the frames that have points.
PRESENT_FRAMES = 0.1
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
        spread = np.mean(np.linalg.norm(x - c[lab], axis=1)) + 1e-3
        score = np.linalg.norm(c[0] - c[1]) / spread + min(n.min(), m) / m
        if score > best_score:
            best, best_score = int(f), score
    return best


def _track_centres(pos: np.ndarray, valid: np.ndarray, m: int, rate: float) -> np.ndarray:
    """Two hand centres ``(F, 2, 3)`` carried frame to frame from the seed frame (NaN where lost)."""
    frames = len(pos)
    centre = np.full((frames, 2, 3), np.nan)
    t0 = _seed_frame(pos, valid, m)
    x = pos[t0, valid[t0]]
    if len(x) < 2:
        return centre
    c0, _ = _two_means(x)
    lost_after = max(1, int(LOST_SECONDS * rate))
    for order in (range(t0, frames), range(t0 - 1, -1, -1)):
        c = c0.copy()
        unseen = np.zeros(2, dtype=np.int64)
        for f in order:
            x = pos[f, valid[f]]
            alive = unseen < lost_after
            if len(x):
                d = np.linalg.norm(x[:, None] - c[None], axis=2)
                d[:, ~alive] = np.inf
                lab = np.argmin(d, axis=1)
                near = d[np.arange(len(x)), lab] < HAND_RADIUS
                far = x[~near]
                for h in range(2):
                    mine = x[near & (lab == h)]
                    if len(mine) >= 2:
                        c[h] = mine.mean(axis=0)
                        unseen[h] = 0
                    else:
                        unseen[h] += 1
                # Points far from every live hand: a lost hand comes back there.
                lost = np.flatnonzero(unseen >= lost_after)
                if len(lost) and len(far) >= 3:
                    c[lost[0]] = far.mean(axis=0)
                    unseen[lost[0]] = 0
            else:
                unseen += 1
            alive = unseen < lost_after
            centre[f] = np.where(alive[:, None], c, np.nan)
    return centre


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
               ignore: np.ndarray | None = None) -> Hands:
    """How many of ``layout``'s hands ``take`` holds and which samples belong to which.

    Args:
        take: the raw take (metres).
        layout: the layout of one hand (M markers).
        hands: ``"auto"``, or 1 / 2 to force the count (a take with one hand where two are forced
            still gets one: ``info["forced"]`` says so).
        ignore: optional bool ``(P,)``: slots kept out of every hand (named body markers).

    Returns:
        :class:`Hands`.
    """
    hands = str(hands)
    if hands not in HANDS:
        raise ValueError(f"hands must be one of {', '.join(HANDS)}, not {hands!r}")
    m = len(layout)
    valid = take.valid.copy()
    if ignore is not None:
        valid[:, ignore] = False
    frames, points = valid.shape
    pos = np.where(valid[..., None], take.positions, np.nan).astype(np.float64)
    one = Hands(1, np.where(valid, 0, -1).astype(np.int8), np.zeros_like(valid), np.full((frames, 2, 3), np.nan),
                info={"count": 1})
    if hands == "1" or not valid.any():
        return one
    centre = _track_centres(pos, valid, m, take.rate)
    tracklets = find_tracklets(replace_valid(take, valid))
    ids = tracklets.id_map(frames, points)
    f_idx, p_idx = np.nonzero(ids >= 0)
    tid = ids[f_idx, p_idx]
    x = pos[f_idx, p_idx]
    n = len(tracklets)
    length = np.maximum(np.bincount(tid, minlength=n), 1)
    hand_of = np.zeros(n, dtype=np.int64)
    for _ in range(3):
        filled = np.stack([_fill(centre[:, h]) for h in range(2)], axis=1)
        d = np.linalg.norm(x[:, None] - filled[f_idx], axis=2)  # (S, 2)
        d = np.where(np.isfinite(d), d, 2 * HAND_RADIUS)
        mean = np.stack([np.bincount(tid, weights=np.minimum(d[:, h], 2 * HAND_RADIUS), minlength=n) / length
                         for h in range(2)], axis=1)
        hand_of = np.argmin(mean, axis=1)
        far = mean[np.arange(n), hand_of] > HAND_RADIUS
        # Centres again, from whole tracklets.
        own = hand_of[tid]
        keep = ~far[tid]
        centre = np.full((frames, 2, 3), np.nan)
        for h in range(2):
            sel = keep & (own == h)
            count = np.bincount(f_idx[sel], minlength=frames)
            for k in range(3):
                s = np.bincount(f_idx[sel], weights=x[sel, k], minlength=frames)
                with np.errstate(invalid="ignore", divide="ignore"):
                    centre[:, h, k] = np.where(count > 0, s / np.maximum(count, 1), np.nan)
    # Is there a second hand? Count the markers each hand holds per frame.
    own = hand_of[tid]
    keep = ~far[tid]
    per_frame = np.stack([np.bincount(f_idx[keep & (own == h)], minlength=frames) for h in range(2)], axis=1)
    with_points = max(int(valid.any(axis=1).sum()), 1)
    present = per_frame >= max(3, int(np.ceil(PRESENT_SHARE * m)))
    share = present.sum(axis=0) / with_points
    real = share >= PRESENT_FRAMES
    info = {"present_share": [round(float(s), 4) for s in share],
            "median_markers": [int(np.median(per_frame[present[:, h], h])) if present[:, h].any() else 0
                               for h in range(2)]}
    if hands == "auto" and not real.all():
        one.info.update(info, count=1)
        return one
    if not real.any():
        one.info.update(info, count=1)
        return one
    if hands == "2" and not real.all():
        one.info.update(info, count=1, forced=2)
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
    from dataclasses import replace

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
    """How well a left and a right model hand fit one hand's labeled markers (median marker RMS, metres)."""

    rms_left: float
    rms_right: float

    @property
    def side(self) -> str:
        return "left" if self.rms_left < self.rms_right else "right"

    @property
    def confidence(self) -> float:
        """In [0.5, 1]: 0.5 when both sides fit alike, 1 when one fits twice as well or better."""
        lo, hi = sorted((self.rms_left, self.rms_right))
        if not np.isfinite(hi) or hi <= 0:
            return 0.5
        return float(min(1.0, 0.5 + 0.5 * (hi - lo) / max(lo, 1e-9)))

    def rms(self, side: str) -> float:
        return self.rms_left if side == "left" else self.rms_right


def side_evidence(observed: np.ndarray, layout: Layout) -> SideEvidence | None:
    """Fit a left and a right average hand to ``observed (F, M, 3)`` labeled markers (metres, NaN
    where missing); None where too few frames show enough markers."""
    from .hand.calibrate import _well_seen
    from .hand.ik import HandSolver
    from .hand.skeleton import HandModel

    try:
        frames = _well_seen(observed)
    except ValueError:
        return None
    frames = frames[np.linspace(0, len(frames) - 1, min(24, len(frames))).astype(int)]
    rms = {}
    for side in SIDES:
        h = HandModel(side=side)
        solver = HandSolver(h, layout.place(h)[0])
        rms[side] = float(np.nanmedian(solver.evaluate(solver.cold_start(observed[frames]), observed[frames]).rms))
    return SideEvidence(rms["left"], rms["right"])


def decide_sides(evidence: list[SideEvidence | None], forced: list[str] | None = None) -> tuple[list[str], dict]:
    """The side of each hand, and facts for the report.

    One hand takes the side that fits it better. Two hands are one left and one right: the
    pairing whose summed RMS is lower wins (a take whose hands both fit a right hand better is
    called so jointly, and the report says it). ``forced`` overrides the decision.
    """
    facts: dict = {"rms_mm": [None if e is None else [round(e.rms_left * 1000, 2), round(e.rms_right * 1000, 2)]
                              for e in evidence]}
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
    if a is None and b is None:
        sides, conf = ["left", "right"], 0.5
    elif a is None or b is None:
        known = a if a is not None else b
        s = known.side
        sides = [s, _other(s)] if a is not None else [_other(s), s]
        conf = known.confidence
    else:
        lr = a.rms_left + b.rms_right
        rl = a.rms_right + b.rms_left
        sides = ["left", "right"] if lr <= rl else ["right", "left"]
        lo, hi = sorted((lr, rl))
        conf = float(min(1.0, 0.5 + 0.5 * (hi - lo) / max(lo, 1e-9)))
        if a.side == b.side:
            facts["warning"] = (f"both hands fit a {a.side} hand better (RMS left/right "
                                f"{a.rms_left * 1000:.1f}/{a.rms_right * 1000:.1f} and "
                                f"{b.rms_left * 1000:.1f}/{b.rms_right * 1000:.1f} mm); called "
                                f"{sides[0]} and {sides[1]} by the joint fit: check the sides (--sides)")
    facts.update(sides=sides, confidence=round(conf, 4))
    return sides, facts


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
    from dataclasses import replace

    found = hands_in_names(take.names, layout, naming)
    if not found:
        sided = [n for n in take.names if re.search("|".join(re.escape(x) for x in layout.names), n)]
        hint = f" (names such as {', '.join(sided[:3])} do not follow a known hand naming)" if sided else ""
        raise MocapInputError(take.source, f"is not labeled with layout {layout.name!r}: no hand's markers are "
                                           f"all named{hint}")
    out = []
    for side, cols in found.items():
        res = None if take.residuals is None else take.residuals[:, cols]
        out.append((side, replace(take, positions=take.positions[:, cols], names=list(layout.names), residuals=res)))
    return out

