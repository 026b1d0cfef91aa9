"""Rigid props among the trajectories: clusters whose distances never change, kept out of the hands.

A prop held in the hand (a tool, a cup, a phone with markers) is a cluster of 3-6 markers whose
distances stay fixed while it moves with the hand and turns in it. Per-frame labelers see each
frame alone, and near the fingers a prop marker can look like a hidden fingertip: on 16 synthetic two-hand takes
with a 4-marker prop in one hand, 2.1 % of the prop's samples took hand labels without this check
(0.2 % with it; ``benchmarks/two_hands.py``).

Found over whole trajectories (:func:`rigid_groups`): two trajectories are rigid partners when
their distance varies by less than :data:`RIGID_SD` over at least :data:`MIN_OVERLAP_S` of shared
life; rigid partners form groups, each split where a hand held still beside the prop joined it
(a prop is rigid with itself always, with a still hand only at times). The back of a hand is such
a group too. After labeling, a group whose trajectories the labeler mostly took is a hand's; one
it mostly left null, but some of whose trajectories (or shorter pieces rigid with them) took hand
labels, is a prop, and the take is labeled again without it (:func:`find_props`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .tracklets import Tracklets

#: Metres: the most a rigid pair's distance may vary (SD): a prop's markers vary by the cameras'
#: noise alone (0.5-2 mm on the synthetic takes), finger markers by centimetres.
RIGID_SD = 0.002
#: Seconds of shared life a pair needs to count as rigid (a still hand is rigid for a moment).
MIN_OVERLAP_S = 1.0
#: Seconds: the shortest trajectory joined to a prop found on longer ones.
MIN_SHORT_S = 0.5
#: Metres: partners farther apart than this are not one object held in a hand.
MAX_SIZE = 0.25
#: Frames: rigidity is measured on every STEP-th frame (enough for an SD over a second).
STEP = 4
#: A group is a hand's only if at most this share of its trajectories is null.
MAX_NULL_SHARE = 1 / 3


@dataclass
class Prop:
    """A rigid group of trajectories that is not part of a hand.

    Attributes:
        tracklets: indices into the take's tracklets ``(n,)``.
        slots: their point slots ``(n,)``; start, stop: their frame ranges ``(n,)``.
    """

    tracklets: np.ndarray
    slots: np.ndarray
    start: np.ndarray
    stop: np.ndarray

    def as_dict(self) -> dict:
        return {"trajectories": len(self.tracklets), "frames": [int(self.start.min()), int(self.stop.max())]}


def _pairs(positions: np.ndarray, tracklets: Tracklets, rate: float, sd: float,
           min_overlap_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The long tracklets (indices) and every pair of them sharing enough life: ``(long, i, j,
    rigid)``, ``i`` and ``j`` indexing ``long`` (each pair once), ``rigid`` bool."""
    min_frames = int(min_overlap_s * rate)
    long = np.flatnonzero(tracklets.stop - tracklets.start >= min_frames)
    sub = positions[::STEP]
    a, b, slot = tracklets.start[long], tracklets.stop[long], tracklets.slot[long]
    lo, hi = -(-a // STEP), -(-b // STEP)  # each long tracklet's range in the subsampled frames
    rows, cols, rigid = [], [], []
    # Each pair once: in order of start, a tracklet with those that start later while it lives
    # (time proportional to the pairs alive together, not to all pairs of a long take).
    order = np.argsort(a, kind="stable")
    first = a[order]
    for p, i in enumerate(order):
        j = order[p + 1:np.searchsorted(first, b[i] - min_frames + STEP, side="right")]  # + STEP: the test is below
        j = j[(np.minimum(hi[i], hi[j]) - np.maximum(lo[i], lo[j])) * STEP >= min_frames]
        if not len(j):
            continue
        window = sub[lo[i]:hi[i]]
        d = np.nan_to_num(np.sqrt(((window - window[:, slot[i]][:, None]) ** 2).sum(axis=2)))  # (n, P)
        # Mean and variance of each partner's distance over the shared frames, from running sums.
        cs = np.concatenate([np.zeros((1, d.shape[1])), np.cumsum(d, axis=0)])
        cs2 = np.concatenate([np.zeros((1, d.shape[1])), np.cumsum(d * d, axis=0)])
        r0, r1 = np.maximum(lo[j], lo[i]) - lo[i], np.minimum(hi[j], hi[i]) - lo[i]
        n = (r1 - r0).astype(np.float64)
        mean = (cs[r1, slot[j]] - cs[r0, slot[j]]) / n
        var = (cs2[r1, slot[j]] - cs2[r0, slot[j]]) / n - mean ** 2
        near = mean < MAX_SIZE
        rows.append(np.full(int(near.sum()), i))
        cols.append(j[near])
        rigid.append((var < sd * sd)[near])
    if not rows:
        return long, np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, bool)
    return long, np.concatenate(rows), np.concatenate(cols), np.concatenate(rigid)


def _peel(members: np.ndarray, shared: np.ndarray, rigid: np.ndarray, share: float = 0.8) -> list[np.ndarray]:
    """Split a rigid group into communities whose members are rigid with most of the members
    they share life with (a prop is rigid with itself always, with a still hand only at times)."""
    out, left = [], members
    while len(left) >= 3:
        core = left.copy()
        while len(core) >= 3:
            s, r = shared[np.ix_(core, core)].sum(axis=1), rigid[np.ix_(core, core)].sum(axis=1)
            ratio = r / np.maximum(s, 1)
            worst = int(np.argmin(ratio))
            if ratio[worst] >= share and r.min() >= 2:
                break
            core = np.delete(core, worst)
        if len(core) < 3:
            break
        out.append(core)
        left = np.setdiff1d(left, core)
    return out


def rigid_groups(positions: np.ndarray, tracklets: Tracklets, rate: float,
                 sd: float = RIGID_SD, min_overlap_s: float = MIN_OVERLAP_S) -> list[np.ndarray]:
    """Groups of tracklet indices (3 or more each), each member rigid with at least two others
    of its group and with most of those it shares life with.

    Args:
        positions: ``(F, P, 3)`` metres, NaN where unseen.
        tracklets: the take's trajectories.
        rate: frames per second.
    """
    long, i, j, is_rigid = _pairs(positions, tracklets, rate, sd, min_overlap_s)
    n = len(long)
    if is_rigid.sum() < 3:
        return []
    shared = np.zeros((n, n), dtype=bool)
    shared[i, j] = shared[j, i] = True
    rigid = np.zeros((n, n), dtype=bool)
    rigid[i[is_rigid], j[is_rigid]] = rigid[j[is_rigid], i[is_rigid]] = True
    count, which = connected_components(coo_matrix(rigid), directed=False)
    groups = []
    for c in range(count):
        members = np.flatnonzero(which == c)
        if len(members) >= 3:
            groups += [long[g] for g in _peel(members, shared, rigid)]
    return groups


def find_props(positions: np.ndarray, tracklets: Tracklets, rate: float, tracklet_label: np.ndarray,
               groups: list[np.ndarray] | None = None) -> list[Prop]:
    """The rigid groups that are not part of a hand, judged by the labels their members took.

    Args:
        positions: ``(F, P, 3)`` metres, NaN where unseen.
        tracklets: the take's trajectories.
        rate: frames per second.
        tracklet_label: int ``(T,)``: the label each tracklet mostly took (negative: null).
        groups: the take's :func:`rigid_groups`, where the caller has them (they depend on the take
            alone).
    """
    out = []
    for group in rigid_groups(positions, tracklets, rate) if groups is None else groups:
        if (tracklet_label[group] < 0).mean() <= MAX_NULL_SHARE:
            continue  # a hand's markers (held still for a while): the labeler took them
        group = np.concatenate([group, _shorter_members(positions, tracklets, rate, group)])
        if not (tracklet_label[group] >= 0).any():
            continue  # nothing stolen: leave it null
        out.append(Prop(group, tracklets.slot[group], tracklets.start[group], tracklets.stop[group]))
    return out


def _shorter_members(positions: np.ndarray, tracklets: Tracklets, rate: float, group: np.ndarray,
                     sd: float = RIGID_SD) -> np.ndarray:
    """Tracklets too short for :func:`rigid_groups` (at least :data:`MIN_SHORT_S`) that live
    wholly beside two or more of ``group``'s and stay rigid with all of them: the prop's markers between
    its gaps."""
    length = tracklets.stop - tracklets.start
    g_slot, g_start, g_stop = tracklets.slot[group], tracklets.start[group], tracklets.stop[group]
    cand = np.flatnonzero((length >= int(MIN_SHORT_S * rate)) & (length < int(MIN_OVERLAP_S * rate))
                          & (tracklets.start >= g_start.min()) & (tracklets.stop <= g_stop.max()))  # in its life
    out = []
    for t in cand:
        a, b, s = tracklets.start[t], tracklets.stop[t], tracklets.slot[t]
        beside = (g_start <= a) & (g_stop >= b) & (g_slot != s)
        if beside.sum() < 2:
            continue
        d = np.linalg.norm(positions[a:b, g_slot[beside]] - positions[a:b, s][:, None], axis=2)  # (n, k)
        if ((d.std(axis=0) < sd) & (d.mean(axis=0) < MAX_SIZE)).all():  # rigid with every one beside it
            out.append(t)
    return np.asarray(out, dtype=np.int64)


def prop_mask(props: list[Prop], n_frames: int, n_points: int) -> np.ndarray:
    """bool ``(F, P)``: the samples of the props' trajectories."""
    mask = np.zeros((n_frames, n_points), dtype=bool)
    for prop in props:
        for s, a, b in zip(prop.slots, prop.start, prop.stop):
            mask[a:b, s] = True
    return mask


__all__ = ["MIN_OVERLAP_S", "Prop", "RIGID_SD", "find_props", "prop_mask", "rigid_groups"]
