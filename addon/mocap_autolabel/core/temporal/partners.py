"""Evidence from rigid partners: pairs of markers that keep their distance whatever the pose.

Two markers on one bone (``ThumbIP`` and ``ThumbTip`` of ``han19``, the back-of-hand markers of
a glove) stay a fixed distance apart in every frame. The per-frame labelers see one frame at a
time and cannot use that: a thumb tip pressed against a finger reads as the finger's marker in
every frame of a long trajectory, loses that label to the finger's own trajectory and is left
null, although its distance to the labeled ``ThumbIP`` never changes. A ghost keeps such a
distance for a frame or two at most. Once the vote has labeled the take, every sample earns
evidence for each label whose rigid partner is labeled in its frame: ``inside`` nats where its
distance to that partner is within the tolerance of the pair's distance, ``-outside`` where it
is not. The vote is then run again with that evidence added. A pair's distance is the take's own where
the first vote labeled both markers in enough frames (gloves and hands differ from the average
hand: the han2018 glove's thumb tip sits 11-20 mm off its nominal spot), else the average hand's.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..hand.ik import HandSolver
from ..hand.skeleton import N_DOF, HandModel
from ..layout import Layout
from ..synth.poses import sample_joint_angles

#: A pair is rigid when its distance varies less than this over random poses (metres, SD): the
#: markers of one bone, han19's ThumbIP and ThumbTip (1.1 mm: ThumbIP sits at the IP joint), and
#: pairs across one joint whose angle is tied to its neighbour's (a finger's PIP and tip markers
#: across the DIP joint, 2.4 mm): within the tolerance at 2 SD. han19 has 17 such pairs, glove13 6.
#: (1.5 mm, the bone pairs alone, labeled 0.02 points fewer instances right on synthetic takes.)
RIGID_SD = 0.003
#: Tolerance on a rigid pair's distance: this much plus :data:`TOLERANCE_SHARE` of the distance
#: (hands differ in size by about 10 %, skin and glove slip by millimetres).
TOLERANCE = 0.004
TOLERANCE_SHARE = 0.15
#: Frames in which the first vote labeled both markers of a pair before the take's own distance
#: replaces the average hand's (a median over them: a few mislabeled frames do not move it).
OWN_FRAMES = 30
#: The most tolerance a pair gets at the take's own distance (metres): the share of the distance
#: in :data:`TOLERANCE_SHARE` is for hand sizes, which the own distance has already measured, and
#: left whole it lets a ghost 10-20 mm off a hidden knuckle marker keep that marker's 80 mm to the
#: back of the hand (16 mm tolerance). Chosen on the synthetic validation takes of
#: ``training.confidence`` among 8-12 mm (han19 99.7447 % of instances, 97.68 % of frames right
#: against 99.7400 and 97.59 uncapped; glove13 99.8906 / 98.87 against 99.8895 / 98.85).
OWN_TOLERANCE = 0.010


@dataclass(frozen=True)
class RigidPairs:
    """Pairs of a layout's markers that keep their distance.

    Attributes:
        pairs: int ``(R, 2)`` label indices, both orders listed (a label's partners are the rows
            that start with it).
        distance: ``(R,)`` metres, on an average hand.
        tolerance: ``(R,)`` metres.
    """

    pairs: np.ndarray
    distance: np.ndarray
    tolerance: np.ndarray

    def __len__(self) -> int:
        return int(self.pairs.shape[0])


@functools.lru_cache(maxsize=16)
def rigid_pairs(layout: Layout, poses: int = 256, seed: int = 0) -> RigidPairs:
    """The rigid pairs of ``layout``, found on an average hand in ``poses`` random poses (cached
    per layout: about 30 ms)."""
    hand = HandModel()
    binding, _ = layout.place(hand)
    pose = np.zeros((poses, N_DOF))
    pose[:, 6:] = sample_joint_angles(np.random.default_rng(seed), poses)
    x = HandSolver(hand, binding).markers(pose)  # (P, M, 3)
    d = np.linalg.norm(x[:, :, None] - x[:, None, :], axis=3)
    sd, mean = d.std(axis=0), d.mean(axis=0)
    i, j = np.nonzero((sd < RIGID_SD) & ~np.eye(len(layout), dtype=bool))
    dist = mean[i, j]
    return RigidPairs(np.stack([i, j], axis=1).astype(np.int64), dist, TOLERANCE + TOLERANCE_SHARE * dist)


def take_distances(rigid: RigidPairs, positions: np.ndarray, frame: np.ndarray, label: np.ndarray,
                   n_labels: int, min_frames: int = OWN_FRAMES) -> RigidPairs:
    """``rigid`` with the take's own distance for each pair labeled together in at least
    ``min_frames`` frames (the median, metres) and its tolerance at most :data:`OWN_TOLERANCE`;
    arguments as in :func:`partner_logp`."""
    if not len(rigid) or not len(frame):
        return rigid
    holder = _holders(frame, label, n_labels)
    dist = rigid.distance.copy()
    own = np.zeros(len(rigid), dtype=bool)
    for r, (a, b) in enumerate(rigid.pairs):
        both = np.flatnonzero((holder[:, a] >= 0) & (holder[:, b] >= 0))
        if len(both) >= min_frames:
            dist[r] = np.median(np.linalg.norm(positions[holder[both, a]] - positions[holder[both, b]], axis=1))
            own[r] = True
    tolerance = TOLERANCE + TOLERANCE_SHARE * dist
    return RigidPairs(rigid.pairs, dist, np.where(own, np.minimum(tolerance, OWN_TOLERANCE), tolerance))


def _holders(frame: np.ndarray, label: np.ndarray, n_labels: int) -> np.ndarray:
    """int ``(F, M)``: the sample that holds each label in each frame, -1 where none does."""
    holder = np.full((int(frame.max()) + 1, n_labels), -1, dtype=np.int64)
    held = np.flatnonzero(label >= 0)
    holder[frame[held], label[held]] = held
    return holder


def partner_logp(positions: np.ndarray, frame: np.ndarray, label: np.ndarray, n_labels: int,
                 rigid: RigidPairs, inside: float, outside: float, rows: np.ndarray | None = None) -> np.ndarray:
    """Evidence ``(n, M + 1)`` nats of each sample for each label from its rigid partners.

    Args:
        positions: ``(n, 3)`` metres, the samples' positions.
        frame: int ``(n,)`` their frames.
        label: int ``(n,)`` their labels so far (negative: null).
        n_labels: ``M``.
        rigid: the layout's rigid pairs.
        inside, outside: nats for (against) a label per partner at (not at) its distance.
        rows: the samples to weigh (indices; default all); the others get 0. Partners are found
            among all samples.

    Returns:
        float32 ``(n, M + 1)``; the null column is 0.
    """
    n = len(frame)
    out = np.zeros((n_labels + 1, n), dtype=np.float32)  # label-major: each label's row is added to whole
    if not len(rigid) or not n or (inside == 0 and outside == 0):
        return out.T
    holder = _holders(frame, label, n_labels)
    positions = np.asarray(positions, dtype=np.float32)  # millimetre tolerances: float32 is ample
    inside, outside = np.float32(inside), np.float32(outside)
    q = slice(None) if rows is None else np.asarray(rows)
    # The weighed samples once, and their evidence in rows of their own, written back at the end
    # (gathered and scattered once per partner, they cost half the time of a two-hand take).
    at_q, frame_q, label_q = positions[q], frame[q], label[q]
    evidence = out[:n_labels] if rows is None else np.zeros((n_labels, len(q)), dtype=np.float32)
    for b in np.unique(rigid.pairs[:, 1]):
        # Label b's position in each frame, then every sample's distance to it (NaN: b unseen).
        at = np.full((len(holder), 3), np.nan, dtype=np.float32)
        held = holder[:, b] >= 0
        at[held] = positions[holder[held, b]]
        diff = at_q - at[frame_q]
        d = np.sqrt(np.einsum("ij,ij->i", diff, diff))  # once for every label paired with b
        d[label_q == b] = np.nan  # b's own samples have no partner b
        against = np.where(np.isnan(d), np.float32(0), -outside)
        for r in np.flatnonzero(rigid.pairs[:, 1] == b):
            evidence[rigid.pairs[r, 0]] += np.where(np.abs(d - rigid.distance[r]) <= rigid.tolerance[r],
                                                    inside, against)
    if rows is not None:
        out[:n_labels, q] = evidence
    return out.T
