"""Settings of the review in the scene (``scene.mocap_autolabel``) and its uncertain-segment list.

The list is derived from the take's stored labeling (``review.py``) and rebuilt after every
change; it lives in the scene so that the panel's UIList can show it and undo restores it.
"""

from __future__ import annotations

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from ..core.layout import DEFAULT_LAYOUT, builtin_layouts
from ..core.review import SURE, uncertain_segments

#: How many uncertain segments the list holds at most (worst first).
LIST_LIMIT = 1000


TEMPORAL_ITEMS = [("vote", "Trajectory voting", "Decide per tracklet (default)"),
                  ("viterbi", "N-best Viterbi", "Alexanderson's N-best hypotheses with a Kalman filter"),
                  ("none", "None", "Per-frame labels as they come")]


def _layouts(_self, _context):
    return [(name, name, f"Built-in layout {name}") for name in builtin_layouts()]


#: The layout enums' default: the command line's (han19), not the first by name. A dynamic enum
#: takes its default as the item's number, which is its place in the list.
LAYOUT_DEFAULT = builtin_layouts().index(DEFAULT_LAYOUT)


def _methods(_self, _context):
    from ..core.labelers import METHODS

    return [(m, m, "") for m in METHODS]


def _jump(self, context):
    if 0 <= self.uncertain_index < len(self.uncertain):
        bpy.ops.mocap_autolabel.jump_to_segment(index=self.uncertain_index)


def _take_changed(self, context):
    from . import review

    if self.take is not None and review.has_review(self.take):
        refresh_uncertain(self.id_data, self.take, review.load_state(self.take).labeling)
    else:
        self.uncertain.clear()


class MOCAPAL_PG_uncertain(bpy.types.PropertyGroup):
    """One uncertain segment: a label on a tracklet over a frame range, and its confidence."""

    label: StringProperty(name="Label")
    slot: IntProperty(name="Slot")
    frame_start: IntProperty(name="Start")
    frame_end: IntProperty(name="End")
    confidence: FloatProperty(name="Confidence", subtype="FACTOR", min=0.0, max=1.0)


class MOCAPAL_PG_settings(bpy.types.PropertyGroup):
    take: PointerProperty(type=bpy.types.Collection, name="Take", update=_take_changed,
                          description="The imported take to label and review")
    layout: EnumProperty(name="Layout", items=_layouts, default=LAYOUT_DEFAULT,
                         description="Marker layout to label with")
    layout_file: StringProperty(name="Layout File", subtype="FILE_PATH",
                                description="A layout .toml instead of a built-in layout")
    method: EnumProperty(name="Method", items=_methods, description="Per-frame labeler (set: ours, the default)")
    temporal: EnumProperty(name="Temporal", default="vote", items=TEMPORAL_ITEMS)
    sure: FloatProperty(name="Confident at", default=SURE, min=0.5, max=1.0, subtype="FACTOR",
                        description="Segments at or above this confidence need no review")
    auto_resolve: BoolProperty(name="Re-solve After Each Edit", default=False,
                               description="Run the labeling again with all corrections after every edit, so a "
                                           "correction's consequences propagate (a label taken here is free elsewhere)")
    show_overlay: BoolProperty(name="Finger Colours", default=True,
                               description="Draw the labeled markers in the viewport coloured by finger, "
                                           "uncertain ones ringed")
    show_sticks: BoolProperty(name="Sticks", default=True, description="Draw lines between markers of one digit")
    uncertain: CollectionProperty(type=MOCAPAL_PG_uncertain)
    uncertain_index: IntProperty(name="Uncertain Segment", default=-1, update=_jump)
    uncertain_total: IntProperty(name="Uncertain Segments")


def refresh_uncertain(scene: bpy.types.Scene, take_coll: bpy.types.Collection, labeling) -> None:
    """Rebuild the scene's list of uncertain segments (worst first) from a labeling: labeled ones, and
    unlabeled ones (possible missed markers) under their unlabeled empty's point name (``*N``)."""
    from ..core.labeling import unlabeled_point_names
    from .review import current_take, first_frame

    settings = scene.mocap_autolabel
    first = first_frame(take_coll)
    idx = uncertain_segments(labeling, settings.sure)
    points = unlabeled_point_names(current_take(take_coll).names, labeling.names) \
        if (labeling.label[idx] < 0).any() else None
    items = settings.uncertain
    items.clear()
    for i in idx[:LIST_LIMIT]:
        item = items.add()
        item.label = labeling.names[labeling.label[i]] if labeling.label[i] >= 0 else points[labeling.slot[i]]
        item.slot = int(labeling.slot[i])
        item.frame_start = int(labeling.start[i]) + first
        item.frame_end = int(labeling.stop[i]) - 1 + first
        item.confidence = float(labeling.confidence[i])
    settings.uncertain_total = len(idx)
    from .timeline import mark_bad_frames

    mark_bad_frames(scene, take_coll, labeling, settings.sure)  # the Timeline's overview follows the list
    # Writing the index directly would jump; the property's raw storage does not call the update.
    settings["uncertain_index"] = -1


@bpy.app.handlers.persistent
def on_load(*_args) -> None:
    """After a file loads: drop the session caches, and give every scene without a reviewed take the
    first labeled take it holds (a .blend written by the command line has none set)."""
    from .review import has_review
    from .session import forget_all

    forget_all()
    for scene in bpy.data.scenes:
        settings = getattr(scene, "mocap_autolabel", None)
        if settings is None or settings.take is not None:
            continue
        for coll in scene.collection.children_recursive:
            if has_review(coll):
                settings.take = coll  # its update fills the uncertain list
                break


classes = (MOCAPAL_PG_uncertain, MOCAPAL_PG_settings)


def register() -> None:
    bpy.types.Scene.mocap_autolabel = PointerProperty(type=MOCAPAL_PG_settings)
    bpy.app.handlers.load_post.append(on_load)


def unregister() -> None:
    from .session import forget_all

    if on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(on_load)
    forget_all()
    del bpy.types.Scene.mocap_autolabel
