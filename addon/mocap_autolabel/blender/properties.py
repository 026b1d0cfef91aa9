"""Settings of the review in the scene (``scene.mocap_autolabel``), with its uncertain-segment list and
its list of corrections; and the Retarget panel's character, editable bone map and options
(``scene.mocap_autolabel.retarget``, filled by ``retarget.py``).

The lists are derived from the take's stored labeling and review (``takes.py``) and rebuilt
after every change (and when Confident at or the review queue's filters change) by ``lists.py``;
they live in the scene so that the panel's UILists can show them and undo restores them. The
settings' updates rewrite the take's keys (``review.recolor``): this module sits above ``review.py``,
which never imports it.
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
from ..core.review import QUEUE_MIN_FRAMES, SURE
from .cleanup_settings import MOCAPAL_PG_cleanup
from .cleanup_settings import classes as cleanup_classes
from .lists import refresh_uncertain
from .review import recolor
from .takes import has_review, load_state, take_collection

TEMPORAL_ITEMS = [("vote", "Trajectory voting", "Decide per tracklet (default)"),
                  ("viterbi", "N-best Viterbi", "Alexanderson's N-best hypotheses with a Kalman filter"),
                  ("none", "None", "Per-frame labels as they come")]

#: The command line's --hands. "auto" finds them; a take labeled with two hands before stays two
#: (its corrections name a hand's labels).
HANDS_ITEMS = [("auto", "Find Them", "Find how many hands the take holds (a take labeled with two hands "
                                     "before keeps both, with their sides)"),
               ("1", "One", "Label one hand, whatever the take holds"),
               ("2", "Two", "Label two hands (left and right), named L_ / R_")]


#: A scene stores a layout choice as its item's number: the first five layouts keep the numbers their
#: places in the list gave them before more layouts shipped, later ones a number from their name.
_LAYOUT_NUMBERS = {"glove13": 0, "han19": 1, "tips10": 2, "tips3": 3, "tips5": 4}


def layout_number(name: str) -> int:
    """The stable enum number of a built-in layout (see :data:`_LAYOUT_NUMBERS`)."""
    import zlib

    return _LAYOUT_NUMBERS.get(name, 1000 + zlib.crc32(name.encode()) % 1_000_000)


_LAYOUT_ITEMS: list[tuple] = []  # Blender needs the callback's strings kept alive: built once


def _layouts(_self, _context):
    from ..core.layout import load_layout

    if not _LAYOUT_ITEMS:
        for name in builtin_layouts():
            layout = load_layout(name)
            _LAYOUT_ITEMS.append((name, name, f"{layout.description} ({len(layout)} markers)", "NONE",
                                  layout_number(name)))
    return _LAYOUT_ITEMS


#: The layout enums' default: the command line's (han19), not the first by name (a dynamic enum
#: takes its default as the item's number).
LAYOUT_DEFAULT = layout_number(DEFAULT_LAYOUT)


def _methods(_self, _context):
    from ..core.labelers import METHODS

    return [(m, m, "") for m in METHODS]


def _jump(self, context):
    if 0 <= self.uncertain_index < len(self.uncertain):
        bpy.ops.mocap_autolabel.jump_to_segment(index=self.uncertain_index)


def is_take(_self, coll) -> bool:
    """Poll of the Take field: only collections the importer made (not their Raw, Labeled or
    Unlabeled children, nor any other collection) are offered."""
    return coll is not None and "mocap_source" in coll


def _take_changed(self, context):
    coll = self.take
    if coll is not None and not is_take(self, coll):
        # The field only offers takes, but Python can assign anything: a take's own child collection
        # stands for its take, any other collection for none (labeling it would build a take inside it).
        self.take = take_collection(coll)  # calls this update again
        return
    self["walk_slot"] = -1
    _follow_layout(self, coll)
    if coll is not None and has_review(coll):
        recolor(self.id_data, coll)
        refresh_uncertain(self.id_data, coll, load_state(coll).labeling)
    else:
        self.uncertain.clear()
        self.corrections.clear()
        self.uncertain_total = self.uncertain_hidden = 0


#: The take's custom property holding the layout last in the panel's Layout field while the take was
#: in the Take field (the user's choice, or the one the import picked from the file's point names).
LAYOUT_CHOICE = "mocap_layout_choice"


#: The settings' custom property holding the layout the user last put in the Layout field (a new
#: take whose point names pick no layout gets it, not another take's pick).
USER_LAYOUT = "user_layout"
_automatic = []  # not empty while set_layout writes the field


def set_layout(settings, layout: str) -> None:
    """Put a built-in layout in the Layout field for the take in the Take field (picked from its point
    names, or the take's own), not as the user's choice."""
    _automatic.append(layout)
    try:
        if layout != settings.layout or settings.layout_file:
            settings.layout, settings.layout_file = layout, ""
    finally:
        _automatic.pop()


def _follow_layout(self, coll) -> None:
    """The Take field changed: the Layout field (or the Layout File) shows the new take's layout (the one
    chosen for it, else the one it was labeled with), so that Label does not label it with another
    take's layout."""
    if coll is None:
        return
    layout = coll.get(LAYOUT_CHOICE) or (load_state(coll).layout if has_review(coll) else None)
    if layout in builtin_layouts():
        set_layout(self, layout)
    elif layout and layout != self.layout_file:  # a layout file: the take's own, or the one it was labeled with
        _automatic.append(layout)
        try:
            self.layout_file = layout
        finally:
            _automatic.pop()


def _layout_changed(self, context):
    """The Layout field changed: the take in the Take field remembers it (see :func:`_follow_layout`),
    and where the user changed it, so do the settings (:data:`USER_LAYOUT`)."""
    if is_take(self, self.take):
        self.take[LAYOUT_CHOICE] = self.layout
    if not _automatic:
        self[USER_LAYOUT] = self.layout


def _layout_file_changed(self, context):
    """The Layout File changed: the take in the Take field remembers it as its layout (cleared: the
    Layout field's layout again)."""
    if is_take(self, self.take):
        self.take[LAYOUT_CHOICE] = self.layout_file or self.layout


def _sure_changed(self, context):
    """Confident at moved: the list, the counts, the walk and the key colours follow it."""
    coll = self.take
    if coll is not None and has_review(coll):
        recolor(self.id_data, coll)
        refresh_uncertain(self.id_data, coll, load_state(coll).labeling)


def _queue_changed(self, context):
    """A filter of the review queue changed: the list, its counts and the Timeline's marks follow it."""
    coll = self.take
    if coll is not None and has_review(coll):
        refresh_uncertain(self.id_data, coll, load_state(coll).labeling)


class MOCAPAL_PG_uncertain(bpy.types.PropertyGroup):
    """One segment of the review queue: a label (or none) on a raw trajectory over a frame range, and its
    confidence (of an unlabeled piece: how sure the vote is that it is no marker)."""

    label: StringProperty(name="Label")  # the name of its empty: the label, or the raw trajectory's when unlabeled
    point: StringProperty(name="Trajectory")  # the raw trajectory (*N) that carries it
    unlabeled: BoolProperty(name="Unlabeled")
    slot: IntProperty(name="Slot")
    frame_start: IntProperty(name="Start")
    frame_end: IntProperty(name="End")
    confidence: FloatProperty(name="Confidence", subtype="FACTOR", min=0.0, max=1.0)


class MOCAPAL_PG_correction(bpy.types.PropertyGroup):
    """One correction of the take (a locked decision or a split), as the Corrections list shows it."""

    kind: StringProperty(name="Kind")  # "label", "ghost" or "split"
    text: StringProperty(name="Correction")
    slot: IntProperty(name="Slot")
    frame_start: IntProperty(name="Start")
    frame_end: IntProperty(name="End")


def is_character(_self, obj) -> bool:
    """Poll of the Retarget panel's Armature field: armatures, not our own solved hands."""
    return obj is not None and obj.type == "ARMATURE" and "mocap_calibration" not in obj


def _character_changed(self, context):
    """A new character in the Retarget panel: its bones mapped automatically into the list."""
    from .retarget import fill_map

    arm = self.armature
    if arm is not None and not is_character(self, arm):
        self.armature = None  # Python can assign anything; the field only offers characters
        return
    if arm is None or self.map_armature != arm.name or not self.bone_map:
        fill_map(self, arm)


#: The Retarget panel's Reference: the character's rest pose, or a solved frame.
REFERENCE_ITEMS = [("rest", "Rest Pose", "The character's rest pose is our hand posed like it (each of our bones "
                                         "swung onto its counterpart): rest fingers curled or spread differently "
                                         "still end in our pose"),
                   ("frame", "Frame", "A solved frame of the take is the character's rest pose")]
#: The Retarget panel's Wrist (the core's WRIST_MODES).
WRIST_ITEMS = [("fingers", "Fingers Only", "The character's hand bone stays on its own forearm; the fingers move"),
               ("rotation", "Rotation", "The hand bone also turns as our palm does in the world"),
               ("world", "Rotation and Position", "The hand bone also turns and moves to our wrist")]


class MOCAPAL_PG_bone_pair(bpy.types.PropertyGroup):
    """One row of the Retarget panel's bone map: which of the character's bones is our bone on a side."""

    side: StringProperty(name="Side")
    ours: StringProperty(name="Hand Bone")
    theirs: StringProperty(name="Bone", description="The character's bone that follows this bone of the solved "
                                                    "hand (empty: none)")


class RetargetOptions:
    """The retargeting's options, shared by the Retarget panel's settings and the operator."""

    reference: EnumProperty(name="Reference", items=REFERENCE_ITEMS, default="rest")
    reference_frame: IntProperty(name="Reference Frame", default=1,
                                 description="The solved frame that is the character's rest pose")
    wrist: EnumProperty(name="Wrist", items=WRIST_ITEMS, default="fingers")
    pinch: BoolProperty(name="Keep Pinches", default=False,
                        description="Where our thumb touches a finger, keep the character's thumb and finger "
                                    "tips as close (a small correction of both)")


class MOCAPAL_PG_retarget(RetargetOptions, bpy.types.PropertyGroup):
    """The Retarget panel: the character, its editable bone map and the options."""

    armature: PointerProperty(type=bpy.types.Object, name="Armature", poll=is_character, update=_character_changed,
                              description="The character's armature to key the solved hands on")
    bone_map: CollectionProperty(type=MOCAPAL_PG_bone_pair)
    bone_map_index: IntProperty(name="Bone", default=-1)
    map_armature: StringProperty(options={"HIDDEN"})  # the armature the list was made for
    convention: StringProperty(name="Convention", options={"HIDDEN"})


class MOCAPAL_PG_settings(bpy.types.PropertyGroup):
    take: PointerProperty(type=bpy.types.Collection, name="Take", update=_take_changed, poll=is_take,
                          description="The imported take to label and review")
    layout: EnumProperty(name="Layout", items=_layouts, default=LAYOUT_DEFAULT, update=_layout_changed,
                         description="Marker layout to label with")
    layout_file: StringProperty(name="Layout File", subtype="FILE_PATH", update=_layout_file_changed,
                                description="A layout .toml instead of a built-in layout")
    method: EnumProperty(name="Method", items=_methods, description="Per-frame labeler (set: ours, the default)")
    temporal: EnumProperty(name="Temporal", default="vote", items=TEMPORAL_ITEMS)
    hands: EnumProperty(name="Hands", default="auto", items=HANDS_ITEMS,
                        description="How many hands of the layout the take holds")
    sure: FloatProperty(name="Confident at", default=SURE, min=0.5, max=1.0, subtype="FACTOR", update=_sure_changed,
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
    uncertain_total: IntProperty(name="Uncertain Segments")  # the queue's length (the list shows at most 1000)
    uncertain_hidden: IntProperty(name="Left Out")  # uncertain segments the queue's filters leave out
    queue_labeled_only: BoolProperty(name="Labeled Only", default=False, update=_queue_changed,
                                     description="Show labeled segments in doubt alone, no unlabeled pieces")
    queue_min_frames: IntProperty(name="Unlabeled From", default=QUEUE_MIN_FRAMES, min=1, soft_max=120,
                                  update=_queue_changed, subtype="NONE",
                                  description="Show unlabeled pieces of at least this many frames (shorter ones "
                                              "only where they continue a doubtful label or are more likely a "
                                              "marker than not)")
    corrections: CollectionProperty(type=MOCAPAL_PG_correction)
    corrections_index: IntProperty(name="Correction", default=-1)
    # Where Previous / Next stand: the slot and Blender frame of the segment they last went to
    # (several segments can start on one frame; the frame alone cannot say which one is current).
    walk_slot: IntProperty(default=-1, options={"HIDDEN"})
    walk_frame: IntProperty(default=0, options={"HIDDEN"})
    retarget: PointerProperty(type=MOCAPAL_PG_retarget)
    cleanup: PointerProperty(type=MOCAPAL_PG_cleanup)  # the Cleanup panel (cleanup_settings.py)


@bpy.app.handlers.persistent
def on_load(*_args) -> None:
    """After a file loads: drop the session caches and the bad-frame markers of takes deleted before
    it was saved, and give every scene without a reviewed take the first labeled take it holds (a
    .blend written by the command line has none set)."""
    from .session import forget_all
    from .timeline import clear_orphaned_markers

    forget_all()
    for scene in bpy.data.scenes:
        clear_orphaned_markers(scene)
        settings = getattr(scene, "mocap_autolabel", None)
        if settings is None or settings.take is not None:
            continue
        for coll in scene.collection.children_recursive:
            if has_review(coll):
                settings.take = coll  # its update fills the uncertain list
                break


classes = cleanup_classes + (MOCAPAL_PG_uncertain, MOCAPAL_PG_correction, MOCAPAL_PG_bone_pair, MOCAPAL_PG_retarget,
           MOCAPAL_PG_settings)


def register() -> None:
    bpy.types.Scene.mocap_autolabel = PointerProperty(type=MOCAPAL_PG_settings)
    bpy.app.handlers.load_post.append(on_load)


def unregister() -> None:
    from .session import forget_all

    if on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(on_load)
    forget_all()
    del bpy.types.Scene.mocap_autolabel
