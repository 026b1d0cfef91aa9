"""A labeling's hands, for whoever shows or relabels it (the Blender review, a re-solve): the sides in
label order, and what a new labeling of an already labeled take keeps of its hands."""

from __future__ import annotations

from ..layout import Layout
from .naming import SIDES, HandNaming, sided_layout_names


def labeling_sides(info: dict) -> list[str]:
    """The side of each hand of a labeling, in label order, from its ``info``: ``["left", "right"]``
    for two hands (labels ``0..M-1`` the left hand's, ``M..2M-1`` the right's), ``[""]`` for one
    (its side, where one was named, stays in the names)."""
    facts = info.get("hands", {}) if info else {}
    if facts.get("count", 1) == 2:
        return list(facts.get("sides") or SIDES)
    return [""]


def relabel_plan(info: dict | None, layout: Layout, hands: str | int = "auto") -> tuple[dict, list[str], bool]:
    """How to label a take again that was labeled before with ``info`` (None: never labeled).

    ``hands`` ``"auto"`` keeps a two-hand labeling's hands and sides (:func:`relabel_options`) and
    lets a one-hand take be found again as the first labeling was; ``1`` / ``2`` force the count.

    Returns:
        the hand fields of :class:`..settings.LabelSettings` (and ``hand_swaps`` of
        :class:`..settings.Corrections`), the label names that labeling will have (where the count
        is known: a one-hand take under ``"auto"`` may still be found to hold two), and whether the
        count of hands changes (then the corrections that name a hand's labels cannot follow).
    """
    earlier = relabel_options(info) if info is not None else {}
    options = earlier
    if str(hands) in ("1", "2"):
        n = int(hands)
        options = earlier if n == 2 and earlier else {"hand_count": n}
    two = options.get("hand_count") == 2
    naming = HandNaming(options["naming"]) if options.get("naming") else HandNaming()
    names = sided_layout_names(layout, list(SIDES), naming) if two else list(layout.names)
    changed = info is not None and two != bool(earlier)
    return options, names, changed


def relabel_options(info: dict) -> dict:
    """The settings' hand fields (and the corrections' ``hand_swaps``) that keep a labeling's hands
    when the take is labeled again with its
    corrections: the count, each hand's side in :func:`find_hands`' order (so that no labeling run
    is spent deciding them again and every correction's label keeps its hand), the frames where the
    hands traded places (:func:`identity_swaps`) and the naming.
    Empty for a one-hand labeling (labeled again as it was first, ``hands="auto"``)."""
    facts = info.get("hands", {}) if info else {}
    if facts.get("count", 1) != 2:
        return {}
    out: dict = {"hand_count": 2}
    if facts.get("by_hand_order"):
        out["sides"] = list(facts["by_hand_order"])
    if facts.get("naming"):
        out["naming"] = HandNaming(facts["naming"]).template
    out["hand_swaps"] = [list(r) for r in facts.get("swaps", [])]
    return out
