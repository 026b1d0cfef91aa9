"""Our solved hand per frame, as the retargeting reads it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..hand.skeleton import PARENTS, HandModel


@dataclass(frozen=True)
class SourceHand:
    """Our hand's bones over a take, in the world (metres).

    Attributes:
        side: ``"left"`` or ``"right"``.
        rotations: ``(F, 20, 3, 3)`` each bone frame's world rotation (y along the bone, z dorsal),
            bones in :data:`..hand.skeleton.BONE_NAMES` order; NaN on frames without a pose.
        heads: ``(F, 20, 3)`` each bone's proximal joint in the world, metres (the rig object's
            scale taken off: the scene shows them ``scale`` times larger).
        lengths: ``(20,)`` bone lengths, metres.
        radii: ``(20,)`` skin radius at each bone's distal end, metres (:attr:`..hand.skeleton.HandModel.bone_radii`).
        rest: ``(20, 3, 3)`` rest rotations in the hand (palm) frame.
        rest_heads: ``(20, 3)`` rest positions of the bones' heads in the hand frame, metres.
        scale: scene units per metre (the take's import Scale, which our rig object carries).
    """

    side: str
    rotations: np.ndarray
    heads: np.ndarray
    lengths: np.ndarray
    radii: np.ndarray
    rest: np.ndarray
    rest_heads: np.ndarray
    scale: float = 1.0

    @classmethod
    def from_poses(cls, hand: HandModel, poses: np.ndarray) -> SourceHand:
        """From the hand model and its poses ``(F, 26)`` (a :class:`..solve.HandSolve`'s ``fit.poses``)."""
        poses = np.asarray(poses, dtype=float)
        rot, pos = hand.forward(np.nan_to_num(poses))
        bad = ~np.isfinite(poses).all(axis=1)
        rot[bad], pos[bad] = np.nan, np.nan
        return cls(hand.side, rot, pos, np.asarray(hand.bone_lengths, float), np.asarray(hand.bone_radii, float)[:, 1],
                   hand.rest[0], hand.rest[1])

    @classmethod
    def from_bases(cls, side: str, rest: np.ndarray, quaternions: np.ndarray, root_location: np.ndarray,
                   lengths: np.ndarray, radii: np.ndarray, world: np.ndarray | None = None) -> SourceHand:
        """From our keyed rig (:func:`...blender.armature.key_poses`): its bones' rest matrices
        ``(20, 4, 4)`` (armature space = hand frame), pose-basis quaternions ``(F, 20, 4)`` (w first),
        the root bone's basis location ``(F, 3)`` and the object's world matrix (None: identity)."""
        from ..rotations import quaternion_to_matrix

        q = np.asarray(quaternions, dtype=float)
        frames = len(q)
        basis = np.zeros((frames, 20, 4, 4))
        basis[..., :3, :3] = quaternion_to_matrix(q / np.linalg.norm(q, axis=-1, keepdims=True))
        basis[..., 3, 3] = 1.0
        basis[:, 0, :3, 3] = root_location
        posed = np.empty_like(basis)
        for b, p in enumerate(PARENTS):
            if p < 0:
                posed[:, b] = rest[b] @ basis[:, b]
            else:
                posed[:, b] = posed[:, p] @ (np.linalg.inv(rest[p]) @ rest[b]) @ basis[:, b]
        scale = 1.0
        if world is not None:  # bones stay in metres: the object's scale only shows them at the take's size
            w = np.asarray(world, dtype=float)
            scale = float(np.cbrt(abs(np.linalg.det(w[:3, :3]))))
            unit = w.copy()
            unit[:3, :3] /= scale
            unit[:3, 3] /= scale
            posed = unit @ posed
        to_palm = np.linalg.inv(rest[0])
        return cls(side, posed[..., :3, :3], posed[..., :3, 3], np.asarray(lengths, float),
                   np.asarray(radii, float), to_palm[:3, :3] @ rest[:, :3, :3],
                   (to_palm[:3, :3] @ rest[:, :3, 3, None])[..., 0] + to_palm[:3, 3], scale)

    @property
    def frames(self) -> int:
        return len(self.rotations)

    def palm_relative(self) -> np.ndarray:
        """``(F, 20, 3, 3)``: each bone's rotation in the palm's frame (``W_palm^T W_b``)."""
        palm = self.rotations[:, :1]
        return np.swapaxes(palm, -1, -2) @ self.rotations

    def tips(self) -> np.ndarray:
        """``(F, 20, 3)``: each bone's distal end in the world, metres."""
        return self.heads + self.rotations[..., :, 1] * self.lengths[None, :, None]
