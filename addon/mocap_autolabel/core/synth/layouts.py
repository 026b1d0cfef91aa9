"""Random marker layouts: what the layout-conditioned ``set`` model is trained on.

A studio's finger set is a few markers per digit on the back of the fingers, nearly always the
tips, often one or two more along the fingers, and often a few markers on the back of the hand
or at the wrist. :func:`random_layout` samples such sets over the whole template hand, from 3 to
25 markers, with and without hand markers.

One band is never sampled, so that a benchmark can test layouts whose positions the training never
saw (:data:`HELD_OUT`): the middle of every proximal phalanx (``along`` 0.55-0.75), where han19's
``*MCP`` markers and most of glove13's ``*_middle`` markers sit.
"""

from __future__ import annotations

import numpy as np

from ..hand.skeleton import FINGERS, HandModel
from ..layout import Layout, Marker

#: What :func:`random_layout` never samples (see the module docstring).
HELD_OUT = {"proximal_phalanx_along": (0.55, 0.75)}
#: Markers nearer than this at rest (metres, average hand) are not both kept: no glove puts two there.
MIN_SPACING = 0.012
#: Fewest and most markers of a sampled layout.
SIZES = (3, 25)

_DIGITS = ("thumb",) + tuple(FINGERS)


def _along(rng: np.random.Generator, low: float, high: float, bone: str) -> float:
    """``along`` uniform in ``[low, high]``, outside the held-out band on proximal phalanges."""
    while True:
        a = float(rng.uniform(low, high))
        lo, hi = HELD_OUT["proximal_phalanx_along"]
        if not (bone.endswith("_prox") and lo <= a < hi):
            return a


def _angle(rng: np.random.Generator) -> float:
    """Degrees about the bone from its back: mostly dorsal, now and then on a side."""
    if rng.random() < 0.92:
        return float(np.clip(rng.normal(0.0, 20.0), -60.0, 60.0))
    return float(rng.choice([-90.0, 90.0]))


def _candidates(rng: np.random.Generator) -> list[Marker]:
    """One layout's candidate markers before spacing and size limits, tips first."""
    tips, others = [], []
    p_tip = rng.uniform(0.4, 1.0)
    tip_along = rng.uniform(0.3, 1.0)
    p_prox, p_mid, p_meta = (rng.uniform(0.0, 1.0) if rng.random() < 0.6 else 0.0 for _ in range(3))
    if rng.random() < 0.15:  # now and then a dense glove
        p_tip, p_prox, p_mid, p_meta = 1.0, rng.uniform(0.7, 1.0), rng.uniform(0.7, 1.0), rng.uniform(0.3, 1.0)
    for digit in _DIGITS:
        dist = f"{digit}_dist"
        if rng.random() < p_tip:
            tips.append(Marker(f"{dist}_tip", dist, float(np.clip(tip_along + rng.normal(0, 0.08), 0.2, 1.0)),
                               angle_deg=_angle(rng)))
        if digit == "thumb":
            bones = [("thumb_prox", p_prox), ("thumb_meta", p_meta)]
        else:
            bones = [(f"{digit}_mid", p_mid), (f"{digit}_prox", p_prox), (f"{digit}_meta", p_meta * 0.5)]
        for bone, p in bones:
            if rng.random() < p:
                low = 0.6 if bone.endswith("_meta") and digit != "thumb" else 0.1  # finger metacarpals: the knuckles
                along = _along(rng, low, 0.95, bone)
                others.append(Marker(f"{bone}_{len(others)}", bone, along, angle_deg=_angle(rng)))
        if rng.random() < 0.05:  # now and then a second marker on the distal phalanx
            others.append(Marker(f"{dist}_{len(others)}", dist, _along(rng, 0.1, 0.4, dist), angle_deg=_angle(rng)))
    if rng.random() < 0.65:  # markers on the back of the hand or at the wrist
        for i in range(int(rng.integers(1, 5))):
            others.append(Marker(f"palm_{i}", "palm", float(rng.uniform(-0.05, 0.45)), float(rng.uniform(-0.5, 0.5))))
    return tips + [others[i] for i in rng.permutation(len(others))]


def random_layout(rng: np.random.Generator, name: str = "random") -> Layout:
    """A random finger set of 3 to 25 markers (see the module docstring); markers in random order."""
    hand = HandModel()
    while True:
        kept: list[Marker] = []
        rest: list[np.ndarray] = []
        for marker in _candidates(rng):
            at = Layout("one", (marker,)).place(hand)[0].rest[0]
            if all(np.linalg.norm(at - r) >= MIN_SPACING for r in rest):
                kept.append(marker)
                rest.append(at)
            if len(kept) == SIZES[1]:
                break
        if len(kept) >= SIZES[0]:
            order = rng.permutation(len(kept))
            return Layout(name, tuple(kept[i] for i in order), description="random layout (training)")
