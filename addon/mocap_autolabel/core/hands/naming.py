"""How a labeled point's name carries its hand's side (:class:`HandNaming`, e.g. ``L_ThumbTip``),
and reading the hands of a labeled take back by those names (:func:`split_hands`)."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, replace

from ..errors import MocapInputError
from ..layout import Layout, builtin_layouts, load_layout
from ..take import Take

SIDES = ("left", "right")
#: Built-in naming conventions for labeled points of a hand; a custom pattern may use
#: ``{S}`` (L / R), ``{side}`` (left / right), ``{Side}`` (Left / Right) and ``{name}``.
NAMINGS = {"prefix": "{S}_{name}", "suffix": "{name}_{S}", "vicon": "{Side}Hand:{name}"}
DEFAULT_NAMING = "prefix"


@dataclass(frozen=True)
class HandNaming:
    """How a labeled point's name carries its hand's side, e.g. ``L_ThumbTip`` or ``LeftHand:ThumbTip``.

    ``pattern`` is one of :data:`NAMINGS`' keys or a pattern with ``{name}`` and one of ``{S}``,
    ``{side}``, ``{Side}``.
    """

    pattern: str = DEFAULT_NAMING

    def __post_init__(self) -> None:
        p = NAMINGS.get(self.pattern, self.pattern)
        if "{name}" not in p or not any(t in p for t in ("{S}", "{side}", "{Side}")):
            raise ValueError(f"hand naming {self.pattern!r} needs {{name}} and one of {{S}}, {{side}}, {{Side}} "
                             f"(or one of {', '.join(NAMINGS)})")

    @property
    def template(self) -> str:
        return NAMINGS.get(self.pattern, self.pattern)

    def name(self, side: str, name: str) -> str:
        return self.template.format(S=side[0].upper(), side=side, Side=side.capitalize(), name=name)

    def names(self, side: str, layout: Layout) -> list[str]:
        return [self.name(side, n) for n in layout.names]


def sided_layout_names(layout: Layout, sides: list[str], naming: HandNaming | None) -> list[str]:
    """Label names of a labeling of ``len(sides)`` hands: the layout's names, with side tokens where
    ``naming`` is given (always given for two hands)."""
    if naming is None:
        return list(layout.names)
    return [n for side in sides for n in naming.names(side, layout)]


def hands_in_names(names: list[str], layout: Layout, naming: HandNaming | None = None) -> dict[str, list[int]]:
    """The hands a labeled take's point ``names`` hold: ``{side: columns in layout order}`` for each
    side whose every layout marker is named by the convention (every built-in one when ``naming``
    is None), else ``{}``. Plain layout names (a one-hand take) give ``{"": columns}``."""
    where = {n: i for i, n in enumerate(names)}
    found: dict[str, list[int]] = {}
    candidates = [naming] if naming is not None else [HandNaming(k) for k in NAMINGS]
    for conv in candidates:
        for side in SIDES:
            cols = [where.get(n, -1) for n in conv.names(side, layout)]
            if min(cols) >= 0 and side not in found:
                found[side] = cols
    if not found and all(n in where for n in layout.names):
        found[""] = [where[n] for n in layout.names]
    return found


def split_hands(take: Take, layout: Layout, naming: HandNaming | None = None) -> list[tuple[str, Take]]:
    """Each hand of a labeled take as ``(side, take)`` whose points carry the layout's plain names
    (side ``""`` for a take labeled with plain names).

    Raises:
        MocapInputError: no hand of ``layout`` is named in the take (or none of its points is).
    """
    found = hands_in_names(take.names, layout, naming)
    if not found and take.unlabeled.all():
        raise MocapInputError(take.source, "is not labeled yet (every point is unnamed): label it first "
                                           "(the label command, or Label Markers in Blender)")
    if not found:
        sided = [n for n in take.names if re.search("|".join(re.escape(x) for x in layout.names), n)]
        hint = f" (names such as {', '.join(sided[:3])} do not follow a known hand naming)" if sided else ""
        raise MocapInputError(take.source, f"is not labeled with layout {layout.name!r}: no hand's markers are "
                                           f"all named{hint}")
    out = []
    for side, cols in found.items():
        res = None if take.residuals is None else take.residuals[:, cols]
        filled = None if take.filled is None else take.filled[:, cols]
        out.append((side, replace(take, positions=take.positions[:, cols], names=list(layout.names), residuals=res,
                                  filled=filled)))
    return out



def labeled_layout(take: Take, naming: HandNaming | None = None) -> Layout:
    """The built-in layout whose hands a labeled take's names carry (plain names, or each hand's
    named by side); of several (a han19 file also names every tips5 marker), the one with most
    markers.

    Raises:
        MocapInputError: no built-in layout's hand is named in the take.
    """
    best = None
    for name in builtin_layouts():
        layout = load_layout(name)
        if hands_in_names(take.names, layout, naming) and (best is None or len(layout) > len(best)):
            best = layout
    if best is None:
        raise MocapInputError(take.source, f"is not labeled with a built-in layout ({', '.join(builtin_layouts())}): "
                                           f"no hand's markers are all named (label it first, or give --layout)")
    return best


def sided_path(path: str, side: str) -> str:
    """``take.fbx`` -> ``take_left.fbx``: an output of one hand of a two-hand take (unchanged for
    side ``""``, a one-hand take)."""
    if not side:
        return path
    stem, ext = os.path.splitext(path)
    return f"{stem}_{side}{ext}"
