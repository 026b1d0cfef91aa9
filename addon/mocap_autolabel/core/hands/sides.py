"""Which hand is the left one: handedness read off a hand's labeled markers (the turn of the
layout's most chiral marker tetrahedron, which a mirror image flips), the sides of one or two hands
(:func:`decide_sides`), and the stretches where the two hands found traded places
(:func:`identity_swaps`)."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..layout import Layout
from ..tracklets import mask_runs
from .naming import SIDES


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

    from ..hand.ik import HandSolver
    from ..hand.skeleton import N_DOF, HandModel
    from ..synth.poses import sample_joint_angles

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


#: A layout tells a left hand from a right one by its shape only where its most chiral tetrahedron
#: keeps its turn in at least this share of poses (fingertips alone flatten out as fingers spread).
CHIRAL_AGREE = 0.9


def shape_tells_sides(layout: Layout) -> bool:
    """Whether ``layout``'s markers tell a left hand from a right one by their shape alone."""
    chiral = chiral_tetrahedron(layout)
    return chiral is not None and chiral[1] >= CHIRAL_AGREE


def body_side(name: str) -> str | None:
    """The side a labeled body point's name gives (``LWRA``, ``L_Elbow``, ``LeftShoulder``,
    ``right_elbow``, ``Sub:RFIN``), or None."""
    import re

    base = name.rsplit(":", 1)[-1]
    word = re.match(r"(?i)(left|right)", base)
    if word:
        return word.group(1).lower()
    letter = re.match(r"([LR])(?=[A-Z0-9_])", base)
    return {"L": "left", "R": "right"}[letter.group(1)] if letter else None


#: Metres: a hand's nearest side-named body point counts only within this reach (forearm, wrist).
BODY_REACH = 0.35


def body_side_evidence(body: np.ndarray, sides: Sequence[str | None], centres: np.ndarray) -> list[SideEvidence | None]:
    """Sides from a labeled body: in each frame, each hand votes for the side of its nearest
    side-named body point within :data:`BODY_REACH`.

    Args:
        body: ``(F, B, 3)`` the labeled body points (metres, NaN where missing).
        sides: ``(B,)`` the side each one's name gives (:func:`body_side`), or None.
        centres: ``(F, H, 3)`` each hand's centre per frame (NaN where unseen).
    """
    named = np.array([s is not None for s in sides], dtype=bool)
    if not named.any():
        return [None] * centres.shape[1]
    pts = body[:, named]
    left = np.array([s == "left" for s in sides if s is not None])
    out = []
    for h in range(centres.shape[1]):
        with np.errstate(invalid="ignore"):
            d = np.linalg.norm(pts - centres[:, h, None], axis=2)
        d = np.where(np.isfinite(d), d, np.inf)
        near = d.argmin(axis=1)
        ok = d[np.arange(len(d)), near] <= BODY_REACH
        votes = np.where(left[near], -1, 1)[ok]
        out.append(SideEvidence.of(votes.astype(np.int8)))
    return out


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
        centre: ``(F, 2, 3)`` metres: the hands' centres (:attr:`.tracking.Hands.centre`, NaN where lost).
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
