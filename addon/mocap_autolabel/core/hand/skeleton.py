"""The procedural hand skeleton: 20 bones from published ratios, a 26-DOF pose, forward kinematics.

Frames. The hand frame has its origin at the wrist joint, y pointing distally (to the middle
fingertip), z dorsally (out of the back of the hand). The skeleton is built as a LEFT hand with x
to the thumb side, which is right-handed; a right hand is the same skeleton mirrored in x
(every transform conjugated by ``diag(-1, 1, 1)``), so that all rotations stay proper and a right
hand's frame has x to the little finger. Every bone frame has its origin at the bone's proximal
joint, y along the bone, z to the dorsal side. Lengths are metres, angles radians.

Pose vector (26,): ``[rx, ry, rz]`` the hand frame's rotation vector in the world, ``[x, y, z]``
the wrist in the world (metres), then the 20 joint angles named in :data:`JOINT_NAMES`.
Flexion is positive towards the palm; finger abduction is positive away from the middle finger
(the middle finger itself: towards the thumb); thumb CMC flexion moves the thumb across the palm,
CMC abduction moves it away from the palm.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..rotations import rot_x, rot_y, rot_z, rotvec_to_matrix

DIGITS = ("thumb", "index", "middle", "ring", "little")
FINGERS = DIGITS[1:]

#: Bones in topological order (a parent always comes before its children).
BONE_NAMES: tuple[str, ...] = ("palm", "thumb_meta", "thumb_prox", "thumb_dist") + tuple(
    f"{f}_{s}" for f in FINGERS for s in ("meta", "prox", "mid", "dist")
)
BONE_INDEX = {name: i for i, name in enumerate(BONE_NAMES)}
PARENTS: tuple[int, ...] = tuple(
    -1 if n == "palm" else 0 if n.endswith("_meta") else i - 1 for i, n in enumerate(BONE_NAMES)
)

JOINT_NAMES: tuple[str, ...] = ("thumb_cmc_flex", "thumb_cmc_abd", "thumb_mcp", "thumb_ip") + tuple(
    f"{f}_{j}" for f in FINGERS for j in ("mcp_flex", "mcp_abd", "pip", "dip")
)
DOF_NAMES: tuple[str, ...] = ("rot_x", "rot_y", "rot_z", "loc_x", "loc_y", "loc_z") + JOINT_NAMES
N_DOF = len(DOF_NAMES)  # 26
DOF_INDEX = {name: i for i, name in enumerate(DOF_NAMES)}

#: Joint limits in degrees (HAND.md), in JOINT_NAMES order.
_FINGER_LIMITS = {
    "index": ((-10, 90), (-15, 15), (0, 105), (-10, 85)),
    "middle": ((-10, 90), (-15, 15), (0, 105), (-10, 85)),
    "ring": ((-10, 90), (-15, 15), (0, 105), (-10, 85)),
    "little": ((-10, 90), (-15, 30), (0, 105), (-10, 85)),
}
JOINT_LIMITS_DEG = np.array(
    [(-25, 40), (0, 60), (-10, 60), (-15, 80)] + [lim for f in FINGERS for lim in _FINGER_LIMITS[f]], dtype=float
)
#: ``(2, 26)`` lower and upper bounds of the pose vector; the global part is unbounded.
POSE_LIMITS = np.concatenate(
    [np.full((6, 2), [-np.inf, np.inf]), np.radians(JOINT_LIMITS_DEG)], axis=0
).T

# Anatomy as fractions of hand length HL and breadth HB (HAND.md, after Buchholz 1992).
_LENGTHS_HL = {
    "thumb": (0.251, 0.196, 0.158),
    "index": (0.378, 0.265, 0.143, 0.097),
    "middle": (0.373, 0.277, 0.170, 0.108),
    "ring": (0.338, 0.259, 0.165, 0.107),
    "little": (0.306, 0.206, 0.117, 0.093),
}
_BASE_Y_HL = 0.073  # metacarpal bases, distal of the wrist
_BASE_X_HB = {"thumb": 0.196, "index": 0.126, "middle": 0.0, "ring": -0.129, "little": -0.223}
# Metacarpal heads fan out to about the hand breadth (which is measured across them); spacing
# ~0.21 HB matches the finger thickness, so that straight fingers just touch.
_HEAD_X_HB = {"index": 0.235, "middle": 0.0, "ring": -0.215, "little": -0.41}
_SPLAY_DEG = {"index": 15.0, "middle": 6.0, "ring": 0.0, "little": -7.0}  # rest MCP splay, thumb side +
_ABDUCTION_SIGN = {"index": 1.0, "middle": 1.0, "ring": -1.0, "little": -1.0}  # + = away from the middle finger
# Diameters as fractions of HB: proximal, middle, distal phalanx; metacarpals are 1.2 x proximal.
_THICKNESS_HB = {
    "thumb": (0.229, 0.212),
    "index": (0.229, 0.198, 0.176),
    "middle": (0.216, 0.197, 0.180),
    "ring": (0.203, 0.182, 0.168),
    "little": (0.183, 0.165, 0.149),
}
PALM_HALF_THICKNESS_HB = 0.13
# The thumb: its metacarpal leaves the palm turned radially and sits a little palmar; its
# phalanges flex about an axis pronated about the bone, so that flexion curls towards the palm.
_THUMB_REST_DEG = 35.0
_THUMB_PRONATION_DEG = 50.0
_THUMB_PALMAR_HB = 0.08
# Ring and little metacarpals cup the palm with their MCP flexion (CMC flexion 0-10 / 0-20 deg).
_CUPPING = {"ring": (0.12, 10.0), "little": (0.25, 20.0)}  # (fraction of MCP flexion, max deg)

#: Hand size from ANSUR II (mm): mean and SD of length and breadth, and 5th-95th pct length.
ANSUR = {
    "male": {"length": (193.3, 9.9), "breadth": (88.3, 4.4), "length_5_95": (177.0, 210.0)},
    "female": {"length": (181.1, 10.1), "breadth": (78.2, 3.8), "length_5_95": (165.0, 199.0)},
}
MIRROR = np.diag([-1.0, 1.0, 1.0])
_MIRROR_SIGNS = np.outer(MIRROR.diagonal(), MIRROR.diagonal())


@dataclass(frozen=True)
class _Joint:
    """How one bone hangs from its parent: ``local = T(offset) @ pre @ D(angles) @ post``."""

    offset: np.ndarray  # (3,) in the parent's frame, metres
    pre: np.ndarray  # (3, 3) fixed rotation
    dofs: tuple[tuple[int, str, float], ...]  # (column of the extended angle array, axis, sign)
    post: np.ndarray  # (3, 3) fixed rotation


@dataclass(frozen=True)
class _Topology:
    """How the skeleton's joints hang together, as index arrays (the same for every hand size).

    Bones are kept in level order (the palm, then the bones of each depth, the children of a level
    in their parents' order), so that each level's parents are one slice of the level above. Every
    joint turns about z then x, or about x alone, or not at all (``local = pre @ Rz @ Rx @ post``):
    a turn the joint lacks reads the extra zero row of the angles (an exact identity). Only the
    thumb's metacarpal has a ``post`` rotation.
    """

    dofs: tuple  # every joint's dofs, to check a hand against
    order: np.ndarray  # (B,) bone index at each level-ordered position (position 0 = the palm)
    back: np.ndarray  # (B,) level-ordered position of each bone
    post_at: int  # the level-ordered position (less one) of the bone with a post rotation
    z_col: np.ndarray  # (B - 1,) angle row of the z turn
    z_sign: np.ndarray  # (B - 1, 1)
    x_col: np.ndarray  # (B - 1,) angle row of the x turn
    x_sign: np.ndarray  # (B - 1, 1)
    levels: tuple[tuple[int, int, int, int], ...]  # (start, stop, parents' start, parents' stop)
    parent_at: np.ndarray  # (B - 1,) level-ordered position of each non-palm bone's parent
    dof_axis: np.ndarray  # (D,) in dof_table order: row of the (z, x) axes of all bones, (B - 1) * 2
    dof_at: np.ndarray  # (D,) level-ordered position of its bone (the pivot)

    @classmethod
    def of(cls, joints: tuple[_Joint, ...]) -> _Topology:
        nb = len(joints)
        children = [[c for c in range(nb) if PARENTS[c] == b] for b in range(nb)]
        order, levels, level = [0], [], [0]
        while True:
            nxt = [c for b in level for c in children[b]]
            if not nxt:
                break
            parent_pos = [order.index(PARENTS[c]) for c in nxt]
            start = len(order)
            one = len(set(parent_pos)) == 1  # all from one bone (the palm): its slice broadcasts
            if not one and parent_pos != list(range(parent_pos[0], parent_pos[0] + len(nxt))):
                raise ValueError("the skeleton's levels do not hang from slices of the level above")
            levels.append((start, start + len(nxt), parent_pos[0], parent_pos[-1] + 1))
            order += nxt
            level = nxt
        order = np.array(order)
        back = np.argsort(order)
        zero_col = N_DOF + len(FINGERS)
        z_col, z_sign = np.full(nb - 1, zero_col), np.ones(nb - 1)
        x_col, x_sign = np.full(nb - 1, zero_col), np.ones(nb - 1)
        post_at = None
        rows = []  # row of the axes, in dof_table order
        for b, joint in enumerate(joints):
            i = back[b] - 1
            axes = tuple(a for _, a, _ in joint.dofs)
            if b == 0 and (axes or not np.array_equal(joint.pre, np.eye(3))):
                raise ValueError("the palm carries the global transform alone")
            if axes not in ((), ("x",), ("z", "x")):
                raise ValueError(f"bone {b} turns about {axes}; forward kinematics expects z then x")
            for col, a, sign in joint.dofs:
                if a == "z":
                    z_col[i], z_sign[i] = col, sign
                    rows.append(2 * i)
                else:
                    x_col[i], x_sign[i] = col, sign
                    rows.append(2 * i + 1)
            if not np.array_equal(joint.post, np.eye(3)):
                if post_at is not None:
                    raise ValueError("more than one bone has a post rotation")
                post_at = i
        dof_bone = [b for b, joint in enumerate(joints) for _ in joint.dofs]
        return cls(tuple(j.dofs for j in joints), order, back, int(post_at or 0), z_col, z_sign[:, None], x_col,
                   x_sign[:, None], tuple(levels), back[np.array(PARENTS)[order[1:]]], np.array(rows),
                   back[np.array(dof_bone)])


@dataclass(frozen=True)
class _Chain:
    """One hand's joints as arrays, for forward kinematics over all bones and frames at once.

    Arrays are laid out frames last (``(3, 3, bones, F)``): every elementwise step then runs over
    long contiguous rows instead of numpy's slow inner loops of length 3. A right hand's chain is
    the left one conjugated by the mirror (``M pre M``, ``M post M``, ``M offset``; ``M Rz(a) M =
    Rz(-a)``, ``M Rx(a) M = Rx(a)``), so that no mirror is applied afterwards.
    """

    topo: _Topology
    pre_cols: np.ndarray  # (3 columns, 3 rows, B - 1, 1) each non-palm bone's pre rotation
    post: np.ndarray  # (3, 3) the thumb metacarpal's post rotation
    offset: np.ndarray  # (3, B - 1, 1)
    z_sign: np.ndarray  # (B - 1, 1) the topology's, negated for a mirrored chain
    z_axis_sign: float  # -1 for a mirrored chain: its z turns run the other way

    @classmethod
    def of(cls, joints: tuple[_Joint, ...], mirrored: bool) -> _Chain:
        topo = _TOPOLOGY if _TOPOLOGY is not None and _TOPOLOGY.dofs == tuple(j.dofs for j in joints) \
            else _Topology.of(joints)
        order = topo.order[1:]
        pre = np.stack([joints[b].pre for b in order])  # (B - 1, 3, 3)
        post = joints[topo.order[topo.post_at + 1]].post
        offset = np.stack([joints[b].offset for b in order]).astype(float)  # (B - 1, 3)
        z_sign = topo.z_sign
        if mirrored:
            pre, post, offset = pre * _MIRROR_SIGNS, post * _MIRROR_SIGNS, offset * MIRROR.diagonal()
            z_sign = -z_sign
        return cls(topo, np.ascontiguousarray(pre.transpose(2, 1, 0)[..., None]), post,
                   np.ascontiguousarray(offset.T[..., None]), z_sign, -1.0 if mirrored else 1.0)


#: The skeleton's topology, built once from the average hand below (every hand shares it).
_TOPOLOGY: _Topology | None = None


class ImplausibleHand(ValueError):
    """A hand size outside what a human hand measures (a calibration led astray by wrong labels)."""


@dataclass(frozen=True)
class HandModel:
    """A procedural hand of a given size and side.

    Args:
        length: hand length HL in metres (wrist crease to middle fingertip).
        breadth: hand breadth HB in metres (across the metacarpal heads).
        side: ``"left"`` or ``"right"``.
        bone_scale: optional ``(20,)`` factors on the anatomical bone lengths: proportions that
            differ from the average hand (training data varies them).
    """

    length: float = 0.190
    breadth: float = 0.085
    side: str = "right"
    bone_scale: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {self.side!r}")
        if not (0.05 < self.length < 0.5 and 0.02 < self.breadth < 0.3):
            raise ImplausibleHand(f"implausible hand size: length {self.length * 1000:.0f} mm, breadth "
                                  f"{self.breadth * 1000:.0f} mm")

    # -- geometry -------------------------------------------------------------------------
    @property
    def thumb_side(self) -> float:
        """+1 or -1: the sign of x towards the thumb in the hand and bone frames (a right hand's
        frames are mirrored, so its x points away from the thumb)."""
        return 1.0 if self.side == "left" else -1.0

    @cached_property
    def bone_lengths(self) -> np.ndarray:
        """``(20,)`` bone lengths in metres (the palm: wrist to the middle MCP joint)."""
        hl = self.length
        out = [(_BASE_Y_HL + _LENGTHS_HL["middle"][0]) * hl]
        out += [f * hl for f in _LENGTHS_HL["thumb"]]
        for f in FINGERS:
            out += [x * hl for x in _LENGTHS_HL[f]]
        return np.array(out) * (1.0 if self.bone_scale is None else np.asarray(self.bone_scale))

    @cached_property
    def bone_radii(self) -> np.ndarray:
        """``(20, 2)`` skin radius at the proximal and distal end of each bone, metres."""
        hb = self.breadth
        out = [(PALM_HALF_THICKNESS_HB * hb,) * 2]
        for d in DIGITS:
            t = list(_THICKNESS_HB[d])
            diam = [1.2 * t[0]] + t  # metacarpal, then the phalanges
            for k, dk in enumerate(diam):
                nxt = diam[k + 1] if k + 1 < len(diam) else 0.85 * dk
                out.append((dk / 2 * hb, nxt / 2 * hb))
        return np.array(out)

    @cached_property
    def _joints(self) -> tuple[_Joint, ...]:
        hl, hb = self.length, self.breadth
        eye = np.eye(3)
        lengths = self.bone_lengths
        joints = [_Joint(np.zeros(3), eye, (), eye)]  # palm: the global transform alone
        # Thumb
        j = {n: 6 + i for i, n in enumerate(JOINT_NAMES)}
        base = np.array([_BASE_X_HB["thumb"] * hb, _BASE_Y_HL * hl, -_THUMB_PALMAR_HB * hb])
        pron = rot_y(np.radians(_THUMB_PRONATION_DEG))
        joints.append(_Joint(base, rot_z(np.radians(-_THUMB_REST_DEG)),
                             ((j["thumb_cmc_flex"], "z", 1.0), (j["thumb_cmc_abd"], "x", -1.0)), pron))
        joints.append(_Joint(np.array([0, lengths[1], 0]), eye, ((j["thumb_mcp"], "x", -1.0),), eye))
        joints.append(_Joint(np.array([0, lengths[2], 0]), eye, ((j["thumb_ip"], "x", -1.0),), eye))
        for k, f in enumerate(FINGERS):
            b = 4 + 4 * k
            base = np.array([_BASE_X_HB[f] * hb, _BASE_Y_HL * hl, 0.0])
            dx = (_HEAD_X_HB[f] - _BASE_X_HB[f]) * hb
            meta_angle = np.arcsin(np.clip(dx / lengths[b], -1, 1))  # towards the thumb
            cup = ((N_DOF + FINGERS.index(f), "x", -1.0),) if f in _CUPPING else ()
            joints.append(_Joint(base, rot_z(-meta_angle), cup, eye))
            splay = rot_z(-(np.radians(_SPLAY_DEG[f]) - meta_angle))
            joints.append(_Joint(np.array([0, lengths[b], 0]), splay,
                                 ((j[f"{f}_mcp_abd"], "z", -_ABDUCTION_SIGN[f]), (j[f"{f}_mcp_flex"], "x", -1.0)), eye))
            joints.append(_Joint(np.array([0, lengths[b + 1], 0]), eye, ((j[f"{f}_pip"], "x", -1.0),), eye))
            joints.append(_Joint(np.array([0, lengths[b + 2], 0]), eye, ((j[f"{f}_dip"], "x", -1.0),), eye))
        return tuple(joints)

    # -- kinematics -----------------------------------------------------------------------
    def _extended_angles(self, pose: np.ndarray) -> np.ndarray:
        """Append the coupled angles (CMC cupping of each finger) to the pose: ``(F, 26 + 4)``."""
        cups = np.zeros(pose.shape[:-1] + (len(FINGERS),))
        for i, f in enumerate(FINGERS):
            if f in _CUPPING:
                frac, limit = _CUPPING[f]
                mcp = pose[..., DOF_INDEX[f"{f}_mcp_flex"]]
                cups[..., i] = np.clip(frac * mcp, 0.0, np.radians(limit))
        return np.concatenate([pose, cups], axis=-1)

    def local_rotations(self, pose: np.ndarray) -> np.ndarray:
        """``(F, 20, 3, 3)``: each bone's rotation relative to its rest orientation in the parent.

        This is exactly ``post^-1 D post`` of the joint, i.e. what Blender calls the pose bone's
        basis rotation when the armature's rest frames equal this model's rest frames (hand
        frame, before the global transform). Bone 0 (palm) gets the identity; the global
        rotation is separate.
        """
        pose = np.atleast_2d(np.asarray(pose, dtype=float))
        ext = self._extended_angles(pose)
        out = np.broadcast_to(np.eye(3), (pose.shape[0], len(BONE_NAMES), 3, 3)).copy()
        for b, joint in enumerate(self._joints):
            if not joint.dofs:
                continue
            d = self._dof_rotation(joint, ext)
            out[:, b] = joint.post.T @ d @ joint.post
        if self.side == "right":
            out = MIRROR @ out @ MIRROR
        return out

    @staticmethod
    def _dof_rotation(joint: _Joint, ext: np.ndarray) -> np.ndarray:
        d = None
        for col, axis, sign in joint.dofs:
            r = {"x": rot_x, "y": rot_y, "z": rot_z}[axis](sign * ext[:, col])
            d = r if d is None else d @ r
        return d

    @cached_property
    def _chain(self) -> _Chain:
        return _Chain.of(self._joints, mirrored=self.side == "right")

    def chain_soa(self, pose: np.ndarray, world: bool = True,
                  axes: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Forward kinematics laid out frames last, for solvers: rotations ``(3, 3, 20, F)`` and
        positions ``(3, 20, F)`` of every bone (as :meth:`forward`, transposed), and with ``axes``
        every elementary rotation's axis and pivot ``(3, D, F)`` (as :meth:`forward_axes`).

        Every joint's local rotation is built at once, its turns applied to the columns of ``pre``;
        the chain is walked one depth level (up to five bones) at a time, from the palm's global
        transform (``world``) or the identity.
        """
        pose = np.atleast_2d(np.asarray(pose, dtype=float))
        chain = self._chain
        topo = chain.topo
        n = pose.shape[0]
        angles = np.concatenate([self._extended_angles(pose), np.zeros((n, 1))], axis=1).T  # (31, F)
        z = angles[topo.z_col] * chain.z_sign  # (19, F)
        x = angles[topo.x_col] * topo.x_sign
        cz, sz, cx, sx = np.cos(z), np.sin(z), np.cos(x), np.sin(x)
        p0, p1, p2 = chain.pre_cols  # (3, 19, 1) each
        c0 = cz * p0 + sz * p1  # pre @ Rz, by columns: (3, 19, F)
        c1 = cz * p1 - sz * p0
        local = np.stack([c0, cx * c1 + sx * p2, cx * p2 - sx * c1], axis=1)  # @ Rx: (3 rows, 3 cols, 19, F)
        at = topo.post_at
        thumb = local[:, :, at]  # (3, 3, F)
        local[:, :, at] = (thumb[:, :, None] * chain.post[None, :, :, None]).sum(axis=1)
        rots = np.empty((3, 3, len(topo.order), n))
        locs = np.empty((3, len(topo.order), n))
        if world:
            rots[:, :, 0] = rotvec_to_matrix(pose[:, 0:3]).transpose(1, 2, 0)
            locs[:, 0] = pose[:, 3:6].T
        else:
            rots[:, :, 0] = np.eye(3)[..., None]
            locs[:, 0] = 0.0
        off = chain.offset
        for start, stop, p_start, p_stop in topo.levels:
            up = rots[:, :, p_start:p_stop]  # (3, 3, k or 1, F)
            lo = local[:, :, start - 1:stop - 1]
            rots[:, :, start:stop] = (up[:, 0, None] * lo[None, 0] + up[:, 1, None] * lo[None, 1]
                                      + up[:, 2, None] * lo[None, 2])
            o = off[:, start - 1:stop - 1]
            locs[:, start:stop] = locs[:, p_start:p_stop] + up[:, 0] * o[0] + up[:, 1] * o[1] + up[:, 2] * o[2]
        ax = pv = None
        if axes:
            # The z turn's axis is the parent frame times pre's z column; the x turn's, times pre @ Rz's x column.
            up = rots[:, :, topo.parent_at]  # (3, 3, 19, F)
            z_ax = (up[:, 0] * p2[0] + up[:, 1] * p2[1] + up[:, 2] * p2[2]) * chain.z_axis_sign
            x_ax = up[:, 0] * c0[0] + up[:, 1] * c0[1] + up[:, 2] * c0[2]
            ax = np.stack([z_ax, x_ax], axis=2).reshape(3, 2 * len(topo.parent_at), n)[:, topo.dof_axis]
            pv = locs[:, topo.dof_at]
        return rots[:, :, topo.back], locs[:, topo.back], ax, pv

    def forward(self, pose: np.ndarray, world: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics.

        Args:
            pose: ``(F, 26)`` or ``(26,)`` pose vectors.
            world: apply the global rotation and translation; if False, bones are returned in
                the hand frame.

        Returns:
            rotations ``(F, 20, 3, 3)`` and positions ``(F, 20, 3)`` of every bone frame (origin at
            the bone's proximal joint), metres.
        """
        r, t, _, _ = self.chain_soa(pose, world)
        return np.ascontiguousarray(r.transpose(3, 2, 0, 1)), np.ascontiguousarray(t.transpose(2, 1, 0))

    @cached_property
    def dof_table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every elementary rotation of the skeleton, in :meth:`forward_axes` order.

        Returns ``cols (D,)`` the column of the extended angle array it turns with (>= 26 for the
        coupled CMC cupping), ``bones (D,)`` the bone it rotates (with all its descendants), and
        ``signs (D,)``.
        """
        rows = [(col, b, sign) for b, joint in enumerate(self._joints) for col, _, sign in joint.dofs]
        cols, bones, signs = (np.array(x) for x in zip(*rows))
        return cols, bones, signs.astype(float)

    def forward_axes(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Forward kinematics in the world plus every elementary rotation's axis and pivot.

        Turning the angle of row ``d`` of :attr:`dof_table` by ``dθ`` moves a point ``p`` carried by
        the bone ``bones[d]`` (or a descendant) by ``signs[d] * dθ * axes[d] x (p - pivots[d])``.
        That is the whole analytic Jacobian of the skeleton.

        Returns:
            rotations ``(F, 20, 3, 3)``, positions ``(F, 20, 3)`` (as :meth:`forward`), axes
            ``(F, D, 3)`` unit vectors and pivots ``(F, D, 3)`` metres, all in the world.
        """
        r, t, ax, pv = self.chain_soa(pose, axes=True)
        return (np.ascontiguousarray(r.transpose(3, 2, 0, 1)), np.ascontiguousarray(t.transpose(2, 1, 0)),
                np.ascontiguousarray(ax.transpose(2, 1, 0)), np.ascontiguousarray(pv.transpose(2, 1, 0)))

    def coupling(self, pose: np.ndarray) -> np.ndarray:
        """``(F, 30 - 26)``: derivative of each coupled cupping angle by its finger's MCP flexion."""
        pose = np.atleast_2d(pose)
        out = np.zeros((pose.shape[0], len(FINGERS)))
        for i, f in enumerate(FINGERS):
            if f in _CUPPING:
                frac, limit = _CUPPING[f]
                v = frac * pose[:, DOF_INDEX[f"{f}_mcp_flex"]]
                out[:, i] = np.where((v > 0) & (v < np.radians(limit)), frac, 0.0)
        return out

    @cached_property
    def rest(self) -> tuple[np.ndarray, np.ndarray]:
        """Rest frames in the hand frame: rotations ``(20, 3, 3)`` and positions ``(20, 3)``."""
        r, p = self.forward(np.zeros(N_DOF), world=False)
        return r[0], p[0]

    def skinning_transforms(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-bone maps from rest space (hand frame) to the posed world: ``x' = R x + t``.

        Returns rotations ``(F, 20, 3, 3)`` and translations ``(F, 20, 3)``, ready for
        :func:`mocap_autolabel.core.hand.skin.blend`.
        """
        rots, locs = self.forward(pose)
        r0, p0 = self.rest
        r = rots @ np.swapaxes(r0, -1, -2)
        t = locs - (r @ p0[:, :, None])[..., 0]
        return r, t

    def clip(self, pose: np.ndarray) -> np.ndarray:
        """The pose with every joint angle inside its limits."""
        return np.clip(pose, POSE_LIMITS[0], POSE_LIMITS[1])


_TOPOLOGY = _Topology.of(HandModel()._joints)


def sample_hand_size(rng: np.random.Generator, sex: str | None = None) -> tuple[float, float]:
    """Hand length and breadth in metres drawn from ANSUR II, truncated to the 5th-95th percentile.

    Breadth is correlated with length (r = 0.6, as in anthropometric surveys).
    """
    sex = sex or ("male" if rng.random() < 0.5 else "female")
    a = ANSUR[sex]
    (lm, ls), (bm, bs), (lo, hi) = a["length"], a["breadth"], a["length_5_95"]
    z = rng.standard_normal(2)
    length = float(np.clip(lm + ls * z[0], lo, hi))
    zl = (length - lm) / ls
    breadth = bm + bs * (0.6 * zl + 0.8 * z[1])
    return length / 1000.0, float(np.clip(breadth, bm - 2 * bs, bm + 2 * bs)) / 1000.0
