"""Walking the review queue of the take in the panel's Take field: Previous / Next Uncertain (the
queue's segments, with the panel's filters, in time order) and Jump to Segment (a row of the panel's
list). Each sets the frame to the segment's start and selects its marker.
"""

from __future__ import annotations

import bpy
from bpy.props import BoolProperty, IntProperty

from .common import _labeled_take_present, _select_only, reviewed_panel_take


class MOCAPAL_OT_next_uncertain(bpy.types.Operator):
    """Jump to the next (or previous) segment of the review queue in time order (labeled segments in doubt, and
    unlabeled pieces that may be a marker, as the panel's list filters them) and select its marker; segments
    that start on one frame are visited one after the other"""

    bl_idname = "mocap_autolabel.next_uncertain"
    bl_label = "Next Uncertain"
    bl_options = {"REGISTER", "UNDO"}

    previous: BoolProperty(name="Previous", default=False, options={"SKIP_SAVE"})

    @classmethod
    def poll(cls, context):
        return _labeled_take_present(cls, context)

    def execute(self, context):
        from ..blender.lists import queue_filters
        from ..blender.takes import first_frame, load_state, sample_index
        from ..core.review import walk_uncertain

        coll = reviewed_panel_take(context)
        lab = load_state(coll).labeling
        settings = context.scene.mocap_autolabel
        first = first_frame(coll)
        now = sample_index(coll, context.scene.frame_current)
        # The walk stands on the segment it went to last, as long as the frame is still its start.
        current = (settings.walk_frame - first, settings.walk_slot) if settings.walk_slot >= 0 else None
        seg = walk_uncertain(lab, settings.sure, now, current, self.previous, **queue_filters(settings))
        if seg is None:
            self.report({"INFO"}, f"No segment to review {'before' if self.previous else 'after'} this one")
            return {"CANCELLED"}
        _show_segment(context, coll, lab, seg)
        self.report({"INFO"}, _segment_text(coll, lab, seg))
        return {"FINISHED"}


def _segment_text(coll, lab, seg: int) -> str:
    from ..blender.takes import first_frame, trajectory_names

    first = first_frame(coll)
    name = lab.names[lab.label[seg]] if lab.label[seg] >= 0 else "unlabeled"
    # An unlabeled piece's confidence is how sure the vote is that it is no marker.
    sure = "confident" if lab.label[seg] >= 0 else "sure it is no marker"
    return (f"{name} ({trajectory_names(coll)[lab.slot[seg]]}), frames {lab.start[seg] + first}-"
            f"{lab.stop[seg] - 1 + first}, {lab.confidence[seg] * 100:.1f} % {sure}")


def _show_segment(context, coll, lab, seg: int) -> None:
    from ..blender.markers import object_for
    from ..blender.takes import first_frame

    settings = context.scene.mocap_autolabel
    frame = int(lab.start[seg]) + first_frame(coll)
    context.scene.frame_set(frame)
    settings.walk_slot, settings.walk_frame = int(lab.slot[seg]), frame
    _select_only(context, object_for(coll, lab, seg))


class MOCAPAL_OT_jump_to_segment(bpy.types.Operator):
    """Go to a segment of the review list: set the frame to its start and select its marker"""

    bl_idname = "mocap_autolabel.jump_to_segment"
    bl_label = "Jump to Segment"
    bl_options = {"REGISTER", "UNDO", "INTERNAL"}

    index: IntProperty(name="List Index", default=0, min=0)

    @classmethod
    def poll(cls, context):
        return _labeled_take_present(cls, context)

    def execute(self, context):
        import numpy as np

        from ..blender.takes import first_frame, load_state

        settings = context.scene.mocap_autolabel
        if self.index >= len(settings.uncertain):
            return {"CANCELLED"}
        item = settings.uncertain[self.index]
        coll = reviewed_panel_take(context)
        lab = load_state(coll).labeling
        start = item.frame_start - first_frame(coll)
        seg = np.flatnonzero((lab.slot == item.slot) & (lab.start == start))
        if not len(seg):
            self.report({"WARNING"}, "That segment changed; the list is refreshed after the next edit")
            return {"CANCELLED"}
        _show_segment(context, coll, lab, int(seg[0]))
        return {"FINISHED"}


classes = (MOCAPAL_OT_next_uncertain, MOCAPAL_OT_jump_to_segment)
