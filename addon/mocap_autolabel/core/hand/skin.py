"""The hand's skin: a closed mesh of tapered capsules plus a palm slab, skinning weights, and LBS.

Every skinned point (mesh vertex or marker) is bound to at most two bones. A point on a segment
follows its own bone in the middle and blends linearly towards the neighbouring bone near a joint,
reaching 50/50 on the joint itself: that is what bends the skin smoothly around a knuckle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .skeleton import BONE_NAMES, PALM_HALF_THICKNESS_HB, PARENTS, HandModel

#: Fraction of a segment's length, at each end, over which the skin blends with the neighbour.
BLEND_ZONE = 0.25

_PARENT = np.array(PARENTS)
_CHILD = np.full(len(PARENTS), -1)  # the one child of every digit bone, -1 for tips and the palm
for _b, _p in enumerate(PARENTS):
    if _p > 0:
        _CHILD[_p] = _b


@dataclass(frozen=True)
class Binding:
    """Points bound to bones for linear blend skinning.

    Attributes:
        rest: ``(N, 3)`` rest positions in the hand frame, metres.
        bones: ``(N, 2)`` int bone indices.
        weights: ``(N, 2)`` weights summing to 1.
    """

    rest: np.ndarray
    bones: np.ndarray
    weights: np.ndarray

    def moved(self, offsets: np.ndarray) -> Binding:
        """The same points displaced by ``offsets (N, 3)`` at rest (hand frame, metres)."""
        return Binding(self.rest + offsets, self.bones, self.weights)


def segment_weights(bone: np.ndarray, along: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bones and weights of points at fraction ``along`` (0 = proximal joint, 1 = distal) of ``bone``.

    Args:
        bone: ``(N,)`` bone index of each point.
        along: ``(N,)`` position along the bone as a fraction of its length (may exceed [0, 1]).

    Returns:
        bones ``(N, 2)`` and weights ``(N, 2)``.
    """
    bone = np.asarray(bone, dtype=np.int64)
    along = np.asarray(along, dtype=float)
    parent, child = _PARENT[bone], _CHILD[bone]
    near_base = (along < BLEND_ZONE) & (parent > 0)  # the palm is rigid: no blend into it
    near_tip = (along > 1 - BLEND_ZONE) & (child >= 0)
    other = np.where(near_base, parent, np.where(near_tip, child, bone))
    frac_base = 0.5 * (1 - np.clip(along, 0, BLEND_ZONE) / BLEND_ZONE)
    frac_tip = 0.5 * (1 - np.clip(1 - along, 0, BLEND_ZONE) / BLEND_ZONE)
    w_other = np.where(near_base, frac_base, np.where(near_tip, frac_tip, 0.0))
    bones = np.stack([bone, np.where(w_other > 0, other, bone)], axis=1)
    weights = np.stack([1 - w_other, w_other], axis=1)
    return bones, weights


def blend(rotations: np.ndarray, translations: np.ndarray, binding: Binding) -> np.ndarray:
    """Linear blend skinning of bound points over many frames.

    Args:
        rotations: ``(F, B, 3, 3)`` per-bone rotations from rest to posed space.
        translations: ``(F, B, 3)`` the matching translations, metres.
        binding: the points and their weights.

    Returns:
        ``(F, N, 3)`` posed positions, metres.
    """
    r, t = _blended(rotations, binding), _blended(translations, binding)
    return (r @ binding.rest[:, :, None])[..., 0] + t


def _blended(per_bone: np.ndarray, binding: Binding) -> np.ndarray:
    """Per-point weighted sum of per-bone arrays ``(F, B, ...) -> (F, N, ...)``.

    Blending the matrices first is cheaper than transforming every point by both bones.
    """
    w0, w1 = binding.weights[:, 0], binding.weights[:, 1]
    first = per_bone[:, binding.bones[:, 0]]
    if not w1.any():  # rigidly bound points: no blending to do
        return first
    shape = (1, -1) + (1,) * (per_bone.ndim - 2)
    return first * w0.reshape(shape) + per_bone[:, binding.bones[:, 1]] * w1.reshape(shape)


def blend_directions(rotations: np.ndarray, binding: Binding, directions: np.ndarray) -> np.ndarray:
    """Rotate rest-space unit vectors ``(N, 3)`` (e.g. skin normals) with the points' blended bones.

    Returns ``(F, N, 3)`` unit vectors.
    """
    out = (_blended(rotations, binding) @ directions[:, :, None])[..., 0]
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def skin_point(hand: HandModel, bone: int, along: float, angle: float, lift: float = 0.0) -> tuple[np.ndarray,
                                                                                                     np.ndarray]:
    """A point on (or ``lift`` metres above) the skin of a digit bone, in the hand frame.

    Args:
        bone: bone index (not the palm).
        along: fraction of the bone's length from its proximal joint.
        angle: direction around the bone in radians: 0 dorsal, +pi/2 to the thumb side, pi palmar.
        lift: height above the skin surface, metres.

    Returns:
        position ``(3,)`` and outward unit normal ``(3,)``, both in the hand frame at rest.
    """
    r0, p0 = hand.rest
    radius = np.interp(along, [0.0, 1.0], hand.bone_radii[bone])
    normal_local = np.array([hand.thumb_side * np.sin(angle), 0.0, np.cos(angle)])
    local = np.array([0.0, along * hand.bone_lengths[bone], 0.0]) + (radius + lift) * normal_local
    return r0[bone] @ local + p0[bone], r0[bone] @ normal_local


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh bound to the skeleton: vertices are a :class:`Binding`, faces ``(T, 3)`` int."""

    binding: Binding
    faces: np.ndarray


def build_mesh(hand: HandModel, rings: int = 6, around: int = 12) -> Mesh:
    """The hand's skin: one closed tapered capsule per digit bone and a closed palm slab.

    Args:
        rings: rings of vertices per hemispherical cap (the straight part adds 4 more).
        around: vertices around each ring.
    """
    r0, p0 = hand.rest
    verts, bones, weights, faces = [], [], [], []
    offset = 0
    for b in range(1, len(BONE_NAMES)):
        length = hand.bone_lengths[b]
        ra, rb = hand.bone_radii[b]
        # Profile: (axial position, radius) from the proximal pole to the distal pole.
        cap = np.linspace(0, np.pi / 2, rings + 1)[1:]
        prof = [(-ra * np.cos(c), ra * np.sin(c)) for c in cap]
        prof += [(length * s, ra + (rb - ra) * s) for s in (0.25, 0.5, 0.75)]
        prof += [(length + rb * np.sin(c), rb * np.cos(c)) for c in cap[::-1]]
        prof = np.array(prof[:-1])  # the last ring of the distal cap would have zero radius
        phi = np.linspace(0, 2 * np.pi, around, endpoint=False)
        ring_pts = np.stack([
            np.sin(phi)[None] * prof[:, 1:2], np.broadcast_to(prof[:, 0:1], (len(prof), around)),
            np.cos(phi)[None] * prof[:, 1:2]], axis=-1).reshape(-1, 3)
        poles = np.array([[0.0, -ra, 0.0], [0.0, length + rb, 0.0]])
        local = np.concatenate([ring_pts, poles])
        along = local[:, 1] / length
        bw = segment_weights(np.full(len(local), b), along)
        verts.append(local @ r0[b].T + p0[b])
        bones.append(bw[0])
        weights.append(bw[1])
        n_ring = len(prof)
        idx = np.arange(n_ring * around).reshape(n_ring, around)
        nxt = np.roll(idx, -1, axis=1)
        quads = np.stack([idx[:-1], nxt[:-1], nxt[1:], idx[1:]], axis=-1).reshape(-1, 4)
        tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
        south, north = n_ring * around, n_ring * around + 1
        tris = np.concatenate([
            tris,
            np.stack([np.full(around, south), nxt[0], idx[0]], axis=1),
            np.stack([np.full(around, north), idx[-1], nxt[-1]], axis=1),
        ])
        faces.append(tris + offset)
        offset += len(local)
    palm_v, palm_f = _palm_slab(hand)
    verts.append(palm_v)
    bones.append(np.zeros((len(palm_v), 2), dtype=np.int64))
    weights.append(np.tile([1.0, 0.0], (len(palm_v), 1)))
    faces.append(palm_f + offset)
    binding = Binding(np.concatenate(verts), np.concatenate(bones).astype(np.int64), np.concatenate(weights))
    return Mesh(binding, np.concatenate(faces).astype(np.int64))


def _palm_slab(hand: HandModel) -> tuple[np.ndarray, np.ndarray]:
    """A closed prism over the palm outline (wrist to knuckles), ``PALM_HALF_THICKNESS_HB`` thick."""
    r0, p0 = hand.rest
    hb = hand.breadth
    h = PALM_HALF_THICKNESS_HB * hb
    # Outline from the wrist's little-finger side over the knuckles (MCP joints) to the thumb side.
    little_mcp, index_mcp = p0[17], p0[5]
    side = np.sign(index_mcp[0]) or 1.0  # +1 for a left hand, -1 for a right one (mirrored)
    outline = np.array([
        [-0.30 * hb * side, 0.0],
        [little_mcp[0] - 0.09 * hb * side, 0.5 * little_mcp[1]],
        [little_mcp[0] - 0.09 * hb * side, little_mcp[1]],
        [p0[13][0], p0[13][1] + 0.02 * hb],
        [p0[9][0], p0[9][1] + 0.03 * hb],
        [index_mcp[0] + 0.10 * hb * side, index_mcp[1]],
        [index_mcp[0] + 0.12 * hb * side, 0.45 * index_mcp[1]],
        [0.28 * hb * side, 0.0],
    ])
    if side > 0:
        outline = outline[::-1]  # keep the winding outward after the mirror
    n = len(outline)
    top = np.column_stack([outline, np.full(n, h)])
    bottom = np.column_stack([outline, np.full(n, -h)])
    verts = np.concatenate([top, bottom])
    fan_top = np.stack([np.zeros(n - 2, int), np.arange(1, n - 1), np.arange(2, n)], axis=1)
    fan_bottom = fan_top[:, [0, 2, 1]] + n
    i = np.arange(n)
    j = (i + 1) % n
    sides = np.concatenate([np.stack([i, i + n, j + n], 1), np.stack([i, j + n, j], 1)])
    return verts, np.concatenate([fan_top, fan_bottom, sides])
