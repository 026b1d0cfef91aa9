"""A character's armature as arrays: what the retargeting needs of Blender's bones."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class TargetRig:
    """A character armature at rest, in its armature space (Blender's ``bone.matrix_local``).

    Attributes:
        names: bone names, every parent before its children.
        parents: index of each bone's parent, -1 for a root.
        rest: ``(B, 4, 4)`` rest matrices in armature space (y along the bone, head at the origin
            of the bone frame); armature units.
        lengths: ``(B,)`` head-to-tail lengths, armature units.
        world: ``(4, 4)`` the armature object's world matrix (its scale turns armature units into
            metres where the scene is in metres).
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    rest: np.ndarray
    lengths: np.ndarray
    world: np.ndarray = field(default_factory=lambda: np.eye(4))

    def __post_init__(self) -> None:
        n = len(self.names)
        if len(self.parents) != n or self.rest.shape != (n, 4, 4) or self.lengths.shape != (n,):
            raise ValueError(f"TargetRig: {n} names, {len(self.parents)} parents, rest {self.rest.shape}, "
                             f"lengths {self.lengths.shape}")
        for i, p in enumerate(self.parents):
            if not -1 <= p < i:
                raise ValueError(f"TargetRig: bone {self.names[i]!r} comes before its parent")

    def index(self, name: str) -> int:
        return self.names.index(name)

    @property
    def unit_scale(self) -> float:
        """Metres per armature unit (the object's mean world scale)."""
        return float(np.cbrt(abs(np.linalg.det(self.world[:3, :3]))))
