"""The rotations that put a character's hand bones in our solved pose.

Each mapped bone turns, relative to the character's hand bone, as our bone turns relative to our
palm from a reference pose: by default our hand posed like the character's rest (each of our
bones swung onto the direction of its counterpart), so that a character whose rest fingers are
curled, spread or rolled differently from ours still ends in our pose; or a solved frame the
animator calls "rest". Only the fingers move by default: the character's wrist stays on its own
forearm (``wrist="rotation"`` also turns the hand bone, ``"world"`` moves it to our wrist).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ..errors import MocapInputError
from ..hand.skeleton import BONE_INDEX, BONE_NAMES, FINGERS
from ..rotations import continuous_quaternions, matrix_to_quaternion, matrix_to_rotvec, rotvec_to_matrix
from .source import SourceHand
from .target import TargetRig

#: How the character's hand bone is driven: not at all (the fingers only), its rotation, or its
#: rotation and world position.
WRIST_MODES = ("fingers", "rotation", "world")
#: Our thumb and a fingertip are in contact where their distal bones' tips come within the two
#: bones' radii plus this (metres): pads touching, with the skin's give.
CONTACT_MARGIN = 0.005
#: Frames over which a pinch correction fades in before a contact and out after it.
PINCH_RAMP = 6
#: Damped least-squares iterations of the pinch correction, and its damping (armature units per
#: unit of the chain's length).
PINCH_ITERATIONS = 12
PINCH_DAMPING = 0.05


@dataclass(frozen=True)
class Retargeted:
    """One hand retargeted onto a character.

    Attributes:
        bones: the character's bones keyed (mapped ones), parents first.
        rotations: ``(F, n, 4)`` pose-basis quaternions (w first) of ``bones``, continuous in time.
        location_bone, locations: the bone whose basis location is keyed (``wrist="world"``) and
            its ``(F, 3)`` locations in armature units; None otherwise.
        solved: bool ``(F,)``: frames with a pose (the others get no keys).
        facts: the reference used, contact frames, pinch distances before and after (mm).
    """

    bones: tuple[str, ...]
    rotations: np.ndarray
    solved: np.ndarray
    location_bone: str | None = None
    locations: np.ndarray | None = None
    facts: dict = field(default_factory=dict)


def retarget(source: SourceHand, rig: TargetRig, bones: Mapping[str, str], *, reference: str | int = "rest",
             wrist: str = "fingers", pinch: bool = False) -> Retargeted:
    """Our hand ``source`` onto ``rig`` through ``bones`` (one side's map: our bone -> theirs;
    ``palm`` must be mapped to the character's hand bone).

    Each mapped bone ``j`` (ours ``b``) is posed, in the character's armature space, at
    ``P_j = H U D_b U^T R_j``: ``R_j`` its rest, ``U`` our palm frame laid onto the character's hand
    at rest (from the knuckles), ``D_b`` our bone's turn in our palm frame from the reference pose
    and ``H`` the hand bone's own turn (identity unless ``wrist`` drives it). Unmapped bones of the
    hand ride along with their parents and get no keys.

    Args:
        reference: ``"rest"``: our hand posed like the character's rest (each bone swung onto the
            direction of its counterpart, so that curled or spread rest fingers end in our pose);
            an int: that frame of ``source`` is the character's rest pose.
        wrist: one of :data:`WRIST_MODES`. ``rotation`` and ``world`` turn the hand bone to our
            palm's orientation in the world, relative to its parent at rest (the forearm's own
            animation is the animator's); ``world`` also moves it to our wrist.
        pinch: keep the thumb-to-fingertip distances of the frames where our thumb touches a
            finger, by a small IK correction of the character's thumb and finger (faded in and
            out over :data:`PINCH_RAMP` frames).

    Returns:
        the :class:`Retargeted` pose-basis rotations of the mapped bones.
    """
    if wrist not in WRIST_MODES:
        raise ValueError(f"wrist must be one of {WRIST_MODES}, not {wrist!r}")
    pairs = _pairs(rig, bones)
    ours = np.array([BONE_INDEX[b] for b, _ in pairs])
    theirs = np.array([rig.index(t) for _, t in pairs])
    hand = theirs[0]  # palm first
    rest = _orthonormal(rig.rest[:, :3, :3])
    heads = rig.rest[:, :3, 3]
    u = _palm_alignment(source, rig, dict(pairs))

    frames = source.frames
    solved = np.isfinite(source.rotations).all(axis=(1, 2, 3))
    g = np.where(solved[:, None, None, None], source.palm_relative(), np.eye(3))  # (F, 20, 3, 3)
    g_ref = _reference(source, g, solved, reference, ours, rest[theirs], u)
    delta = g[:, ours] @ np.swapaxes(g_ref, -1, -2)[None]  # (F, n, 3, 3) turns in our palm frame
    turn = np.broadcast_to(np.eye(3), (frames, 3, 3)).copy()  # the hand bone's turn in armature space
    if wrist != "fingers":
        world_rot = _orthonormal(rig.world[:3, :3])
        turn = world_rot.T @ source.rotations[:, 0] @ u.T
        turn[~solved] = np.eye(3)

    mapped = {int(j): i for i, j in enumerate(theirs)}
    moving = Moving(rig, sorted(mapped))
    posed = np.empty((frames, len(moving.bones), 3, 3))  # the moving bones' rotations, armature space
    for k, j in enumerate(moving.bones):  # parents first
        if j == hand:
            posed[:, k] = turn @ rest[j]
        elif j in mapped:
            posed[:, k] = turn @ u @ delta[:, mapped[j]] @ u.T @ rest[j]
        else:  # rides along with its parent
            p = rig.parents[j]
            posed[:, k] = posed[:, moving.slot[p]] @ rest[p].T @ rest[j]

    facts: dict = {"reference": reference if isinstance(reference, str) else int(reference), "wrist": wrist}
    if pinch:
        facts["pinch"] = _keep_pinches(source, rig, pairs, posed, moving, solved)

    basis = np.empty((frames, len(theirs), 3, 3))
    for i, j in enumerate(theirs):
        p = rig.parents[j]
        parent_rest = rest[p] if p >= 0 else np.eye(3)
        if p in moving.slot:
            parent_posed = posed[:, moving.slot[p]]
        elif j == hand:  # the forearm: the animator's, at rest here
            parent_posed = np.broadcast_to(parent_rest, (frames, 3, 3))
        else:  # a helper bone that follows the hand through constraints (a generated Rigify rig's)
            parent_posed = turn @ parent_rest
        basis[:, i] = rest[j].T @ parent_rest @ np.swapaxes(parent_posed, -1, -2) @ posed[:, moving.slot[j]]
    keep = np.ones(len(theirs), dtype=bool)
    if wrist == "fingers":
        keep[0] = False  # the hand bone stays the animator's
    quats = continuous_quaternions(matrix_to_quaternion(basis[:, keep]), axis=0)
    location_bone, locations = None, None
    if wrist == "world":
        location_bone = rig.names[hand]
        locations = _hand_locations(source, rig, hand, rest, heads)
    return Retargeted(tuple(rig.names[j] for j in theirs[keep]), quats, solved, location_bone, locations, facts)


def _pairs(rig: TargetRig, bones: Mapping[str, str]) -> list[tuple[str, str]]:
    """``[(our bone, their bone)]``, palm first, then in our bone order; checked."""
    unknown = [b for b in bones if b not in BONE_INDEX]
    missing = [t for t in bones.values() if t not in rig.names]
    if unknown or missing:
        raise MocapInputError("bone map", f"unknown hand bones {unknown}, bones not in the armature: {missing}")
    if "palm" not in bones:
        raise MocapInputError("bone map", "the hand bone (our 'palm') is not mapped")
    if len(set(bones.values())) != len(bones):
        raise MocapInputError("bone map", "one of the armature's bones is mapped twice")
    return [(b, bones[b]) for b in BONE_NAMES if b in bones]


def _orthonormal(m: np.ndarray) -> np.ndarray:
    """The rotation part of ``(..., 3, 3)`` matrices (scale and shear taken off, by SVD)."""
    a, _, bt = np.linalg.svd(m)
    return a @ bt


def _knuckles(source: SourceHand, rig: TargetRig, pairs: dict[str, str]) -> tuple[list, list]:
    """The knuckles (heads of the proximal phalanges) of two mapped fingers, ours in the palm frame
    and theirs in armature space: index and middle where both are mapped (their metacarpals are the
    palm's rigid ones; the ring and little metacarpals cup with the grip), else the first two mapped."""
    ours, theirs = [], []
    for f in sorted(FINGERS, key=lambda f: f not in ("index", "middle")):
        name = pairs.get(f"{f}_prox")
        if name is not None:
            ours.append((f, source.rest_heads[BONE_INDEX[f"{f}_prox"]]))
            theirs.append((f, rig.rest[rig.index(name), :3, 3]))
        elif f"{f}_meta" in pairs:  # the metacarpal's far end
            b, j = BONE_INDEX[f"{f}_meta"], rig.index(pairs[f"{f}_meta"])
            ours.append((f, source.rest_heads[b] + source.rest[b, :, 1] * source.lengths[b]))
            theirs.append((f, rig.rest[j, :3, 3] + _orthonormal(rig.rest[j, :3, :3])[:, 1] * rig.lengths[j]))
    pick = sorted(ours[:2], key=lambda item: FINGERS.index(item[0]))
    order = [f for f, _ in pick]
    return [v for f, v in pick], [v for f in order for g, v in theirs if g == f]


def _frame(wrist: np.ndarray, knuckles: list) -> np.ndarray:
    """An orthonormal frame ``(3, 3)`` (columns) of a hand: y from the wrist to the two knuckles'
    middle, x across them from the second finger to the first, z their cross product."""
    y = np.mean(knuckles, axis=0) - wrist
    y /= np.linalg.norm(y)
    x = knuckles[0] - knuckles[-1]
    x -= y * (x @ y)
    x /= np.linalg.norm(x)
    return np.stack([x, y, np.cross(x, y)], axis=1)


def _palm_alignment(source: SourceHand, rig: TargetRig, pairs: dict[str, str]) -> np.ndarray:
    """``U (3, 3)``: our palm frame's axes in the character's armature space, at rest."""
    ours, theirs = _knuckles(source, rig, pairs)
    if len(ours) < 2:
        raise MocapInputError("bone map", "at least two fingers must be mapped to lay our hand onto the character's")
    hand = rig.index(pairs["palm"])
    return _frame(rig.rest[hand, :3, 3], theirs) @ _frame(source.rest_heads[0], ours).T


def _swing(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The smallest rotations ``(..., 3, 3)`` taking unit vectors ``u`` onto ``v`` ``(..., 3)``."""
    axis = np.cross(u, v)
    s = np.linalg.norm(axis, axis=-1, keepdims=True)
    c = np.sum(u * v, axis=-1, keepdims=True)
    angle = np.arctan2(s, c)
    return rotvec_to_matrix(axis / np.where(s > 1e-12, s, 1.0) * angle)


def _reference(source: SourceHand, g: np.ndarray, solved: np.ndarray, reference: str | int, ours: np.ndarray,
               their_rest: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Our mapped bones' rotations in the palm frame ``(n, 3, 3)`` in the pose that matches the
    character's rest."""
    if isinstance(reference, str):
        if reference != "rest":
            raise ValueError(f"reference must be 'rest' or a frame number, not {reference!r}")
        ours_rest = source.rest[ours]
        wanted = (u.T @ their_rest[..., :, 1, None])[..., 0]  # their bones' directions, our palm frame
        return _swing(ours_rest[..., :, 1], wanted) @ ours_rest
    frame = int(reference)
    if not (0 <= frame < len(g)) or not solved[frame]:
        raise MocapInputError("reference", f"frame {frame} is not a solved frame of the take (0-{len(g) - 1})")
    return g[frame, ours]


class Moving:
    """The bones a retarget moves: the mapped ones and every bone below one (parents first, ``bones``),
    and each one's row in the arrays of posed rotations (``slot``). Only these are held per frame: a
    generated Rigify rig has hundreds of bones, its finger controls below helper bones rather than
    below the hand bone."""

    def __init__(self, rig: TargetRig, mapped: list[int]) -> None:
        inside = np.zeros(len(rig.names), dtype=bool)
        inside[mapped] = True
        for j in range(len(rig.names)):
            p = rig.parents[j]
            inside[j] |= p >= 0 and inside[p]
        self.rig = rig
        self.bones = [int(j) for j in np.flatnonzero(inside)]
        self.slot = {j: k for k, j in enumerate(self.bones)}

    def below(self, bone: int) -> list[int]:
        """Rows of ``bone`` and of every moving bone below it."""
        return [self.slot[j] for j in self.bones if j == bone or _descends(self.rig, j, bone)]


def _hand_locations(source: SourceHand, rig: TargetRig, hand: int, rest: np.ndarray,
                    heads: np.ndarray) -> np.ndarray:
    """``(F, 3)``: the hand bone's basis location that puts its head on our wrist (its parent at rest)."""
    wrist = source.heads[:, 0] * source.scale  # scene units
    inv = np.linalg.inv(rig.world)
    target = (inv[:3, :3] @ wrist[..., None])[..., 0] + inv[:3, 3]
    out = ((target - heads[hand]) @ rest[hand])  # into the bone's rest frame
    return np.where(np.isfinite(out), out, 0.0)


def _heads(posed: np.ndarray, moving: Moving, rest: np.ndarray) -> dict[int, np.ndarray]:
    """``{bone: (F, 3)}`` heads of the moving bones in armature space (a bone below one that does
    not move keeps its rest head)."""
    rig = moving.rig
    heads: dict[int, np.ndarray] = {}
    for j in moving.bones:
        p = rig.parents[j]
        if p in moving.slot:
            offset = rest[p].T @ (rig.rest[j, :3, 3] - rig.rest[p, :3, 3])
            heads[j] = heads[p] + (posed[:, moving.slot[p]] @ offset[:, None])[..., 0]
        else:
            heads[j] = np.broadcast_to(rig.rest[j, :3, 3], (len(posed), 3))
    return heads


def _keep_pinches(source: SourceHand, rig: TargetRig, pairs: list[tuple[str, str]], posed: np.ndarray,
                  moving: Moving, solved: np.ndarray) -> dict:
    """Correct ``posed`` (in place) so that the character's thumb and fingertip keep our distance
    where our thumb touches a finger; facts (frames, distances before and after, mm)."""
    mapping = dict(pairs)
    thumb = [rig.index(mapping[b]) for b in ("thumb_meta", "thumb_prox", "thumb_dist") if b in mapping]
    if "thumb_dist" not in mapping:
        return {"frames": 0, "skipped": "the thumb's distal bone is not mapped"}
    rest = _orthonormal(rig.rest[:, :3, :3])
    tips = source.tips()
    t_idx = BONE_INDEX["thumb_dist"]
    metres_to_armature = source.scale / rig.unit_scale
    fingers = [f for f in FINGERS if f"{f}_dist" in mapping]
    if not fingers:
        return {"frames": 0, "skipped": "no fingertip bone is mapped"}
    dist = np.stack([np.linalg.norm(tips[:, BONE_INDEX[f"{f}_dist"]] - tips[:, t_idx], axis=1) for f in fingers], 1)
    reach = np.array([source.radii[t_idx] + source.radii[BONE_INDEX[f"{f}_dist"]] + CONTACT_MARGIN for f in fingers])
    ratio = np.where(np.isfinite(dist) & solved[:, None], dist / reach, np.inf)
    which = np.argmin(ratio, axis=1)
    contact = ratio[np.arange(len(ratio)), which] < 1.0
    facts = {"frames": int(contact.sum())}
    if not contact.any():
        return facts
    # Each frame near a contact takes the finger of its nearest contact frame, and a weight that
    # fades over PINCH_RAMP frames.
    frames = len(posed)
    idx = np.arange(frames)
    at = np.flatnonzero(contact)
    nearest = at[np.clip(np.searchsorted(at, idx), 0, len(at) - 1)]
    before = at[np.clip(np.searchsorted(at, idx) - 1, 0, len(at) - 1)]
    nearest = np.where(np.abs(before - idx) < np.abs(nearest - idx), before, nearest)
    gap = np.abs(nearest - idx)
    weight = np.clip(1.0 - gap / (PINCH_RAMP + 1), 0.0, 1.0) * solved
    finger = which[nearest]
    before_mm, after_mm = [], []
    for k, f in enumerate(fingers):
        rows = np.flatnonzero((finger == k) & (weight > 0))
        if not len(rows):
            continue
        chain_f = [rig.index(mapping[b]) for b in (f"{f}_prox", f"{f}_mid", f"{f}_dist") if b in mapping]
        want = dist[rows, k] * metres_to_armature
        fixed, gap_before, gap_after = _pinch_ik(posed[rows], moving, rest, thumb, chain_f, want)
        w = weight[rows]
        for j in thumb + chain_f:  # fade: each bone's turn away from the plain retarget, scaled
            k = moving.slot[j]
            change = matrix_to_rotvec(fixed[:, k] @ np.swapaxes(posed[rows, k], -1, -2))
            posed[rows, k] = rotvec_to_matrix(change * w[:, None]) @ posed[rows, k]
        full = contact[rows]
        to_mm = 1000.0 * rig.unit_scale / source.scale
        before_mm.append(gap_before[full] * to_mm)
        after_mm.append(gap_after[full] * to_mm)
    if before_mm:
        b, a = np.abs(np.concatenate(before_mm)), np.abs(np.concatenate(after_mm))
        facts.update(error_before_mm={"median": round(float(np.median(b)), 3), "max": round(float(b.max()), 3)},
                     error_after_mm={"median": round(float(np.median(a)), 3), "max": round(float(a.max()), 3)})
    return facts


def _pinch_ik(posed: np.ndarray, moving: Moving, rest: np.ndarray, thumb: list[int],
              finger: list[int], want: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Damped least squares on the two chains (rotations at each bone's head, in armature space)
    until the thumb's and the finger's tips are ``want (R,)`` apart, each moving half the way
    along the line between them. Returns the corrected ``posed``, and the distance errors before
    and after (armature units)."""
    posed = posed.copy()
    lengths = moving.rig.lengths

    def chain_state(chain):
        heads = _heads(posed, moving, rest)
        h = np.stack([heads[j] for j in chain], axis=1)  # (R, k, 3)
        last = chain[-1]
        tip = heads[last] + posed[:, moving.slot[last], :, 1] * lengths[last]
        return h, tip

    def distance():
        _, tt = chain_state(thumb)
        _, tf = chain_state(finger)
        return tt, tf, np.linalg.norm(tt - tf, axis=1)

    tt, tf, d = distance()
    before = d - want
    for _ in range(PINCH_ITERATIONS):
        tt, tf, d = distance()
        line = (tt - tf) / np.maximum(d, 1e-9)[:, None]
        err = (want - d)[:, None] * 0.5
        for chain, goal in ((thumb, tt + line * err), (finger, tf - line * err)):
            h, tip = chain_state(chain)
            arm = tip[:, None] - h  # (R, k, 3)
            # d tip = omega x arm = -[arm]x omega: the Jacobian's 3x3 blocks, side by side.
            jac = np.concatenate([-_skew(arm[:, i]) for i in range(len(chain))], axis=2)  # (R, 3, 3k)
            damping = (PINCH_DAMPING * lengths[chain].sum()) ** 2
            e = goal - tip
            step = np.swapaxes(jac, 1, 2) @ np.linalg.solve(jac @ np.swapaxes(jac, 1, 2) + damping * np.eye(3),
                                                            e[..., None])
            step = step[..., 0].reshape(len(posed), len(chain), 3)
            for i, j in enumerate(chain):  # a turn at bone j moves it and every bone below it
                turn = rotvec_to_matrix(step[:, i])
                below = moving.below(j)
                posed[:, below] = turn[:, None] @ posed[:, below]
    _, _, d = distance()
    return posed, before, d - want


def _descends(rig: TargetRig, bone: int, ancestor: int) -> bool:
    p = rig.parents[bone]
    while p >= 0:
        if p == ancestor:
            return True
        p = rig.parents[p]
    return False


def _skew(v: np.ndarray) -> np.ndarray:
    """``(..., 3) -> (..., 3, 3)`` cross-product matrices."""
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1), np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)
