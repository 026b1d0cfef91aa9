"""The marker empties of a labeled take: their colours by finger, their keyframe types by confidence
class, and which empty shows which label or point slot.

A labeled take's "Labeled" collection (or its "Left hand" and "Right hand" children) holds one
empty per label (``mocap_label``), its "Unlabeled" collection one per point slot with unassigned
samples (``mocap_null``); :mod:`.review` writes them.
"""

from __future__ import annotations

import bpy
import numpy as np

from ..core.labeling import EMPTY, Labeling
from ..core.layout import Layout
from ..core.review import KEY_TYPES
from . import animio

#: Channel-group colour set of each digit (Blender's bone colour sets: red, orange, green,
#: blue, violet, grey); the viewport overlay draws the same colours.
FINGER_COLOR_SETS = {"thumb": "THEME01", "index": "THEME02", "middle": "THEME03", "ring": "THEME04",
                     "little": "THEME06", "palm": "THEME13"}


FINGERS = tuple(FINGER_COLOR_SETS)


def finger_of(layout: Layout, label: int) -> str:
    """The digit a layout marker sits on (``thumb`` ... ``little``), or ``palm``."""
    bone = layout.markers[label].bone
    return "palm" if bone == "palm" else bone.split("_")[0]


def key_type_values() -> np.ndarray:
    """int ``(4,)``: the keyframe type enum value of each confidence class."""
    return np.array([animio.key_type_value(t) for t in KEY_TYPES], dtype=np.int32)


def theme_color(finger: str) -> tuple[float, float, float]:
    """The RGB of a digit's colour set in the current theme."""
    index = int(FINGER_COLOR_SETS[finger][5:]) - 1
    return tuple(bpy.context.preferences.themes[0].bone_color_sets[index].normal)


def labeled_objects(coll: bpy.types.Collection) -> dict[int, bpy.types.Object]:
    """The labeled empties of a take's "Labeled" collection, by label."""
    # all_objects: a two-hand take's labeled empties sit in one child collection per hand
    return {int(o["mocap_label"]): o for o in coll.all_objects if "mocap_label" in o}


def null_objects(coll: bpy.types.Collection) -> dict[int, bpy.types.Object]:
    """The unlabeled empties of a take's "Unlabeled" collection, by point slot."""
    return {int(o["mocap_null"]): o for o in coll.objects if "mocap_null" in o}


def slot_of(obj: bpy.types.Object, labeling: Labeling, index: int) -> int | None:
    """The point slot an empty shows at sample ``index`` (None where it shows nothing)."""
    if not 0 <= index < labeling.n_frames:
        return None
    if "mocap_label" in obj:
        per = labeling.per_sample()[index]
        hit = np.flatnonzero(per == int(obj["mocap_label"]))
        return int(hit[0]) if len(hit) else None
    for key in ("mocap_null", "mocap_slot"):
        if key in obj:
            slot = int(obj[key])
            return slot if labeling.per_sample()[index, slot] != EMPTY else None
    return None


def labeled_object(take_coll: bpy.types.Collection, label: int) -> bpy.types.Object | None:
    """The empty of a layout label in the take's "Labeled" collection (or None)."""
    coll = take_coll.get("mocap_labeled")
    return labeled_objects(coll).get(int(label)) if coll is not None and label >= 0 else None


def object_for(take_coll: bpy.types.Collection, labeling: Labeling, segment: int) -> bpy.types.Object | None:
    """The empty that shows a segment: the labeled marker, or the slot's unlabeled empty."""
    label = int(labeling.label[segment])
    if label >= 0:
        coll = take_coll.get("mocap_labeled")
        return labeled_objects(coll).get(label) if coll is not None else None
    coll = take_coll.get("mocap_unlabeled")
    return null_objects(coll).get(int(labeling.slot[segment])) if coll is not None else None
