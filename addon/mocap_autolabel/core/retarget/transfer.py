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

from .source import SourceHand
from .target import TargetRig

#: How the character's hand bone is driven: not at all (the fingers only), its rotation, or its
#: rotation and world position.
WRIST_MODES = ("fingers", "rotation", "world")


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

    Args:
        reference: ``"rest"``: our hand posed like the character's rest; an int: that frame of
            ``source`` is the character's rest pose.
        wrist: one of :data:`WRIST_MODES`.
        pinch: keep the thumb-to-fingertip distances of the frames where our thumb touches a
            finger, by a small IK correction of the character's thumb and finger.
    """
    raise NotImplementedError
