"""Jump to the worst frames of the reviewed take (the bad-frames overview's first marker)."""

from __future__ import annotations

import bpy
from bpy.props import IntProperty

from .common import _labeled_take_present, reviewed_panel_take


class MOCAPAL_OT_jump_to_worst(bpy.types.Operator):
    """Go to the frames that need a look most (samples of the review queue's segments and labels missing inside
    their span) and select the marker there that comes first in the queue"""

    bl_idname = "mocap_autolabel.jump_to_worst"
    bl_label = "Jump to Worst Frames"
    bl_options = {"REGISTER", "UNDO"}

    rank: IntProperty(name="Rank", default=0, min=0, description="0: the worst run of frames, 1: the next...")

    @classmethod
    def poll(cls, context):
        return _labeled_take_present(cls, context)

    def execute(self, context):
        import numpy as np

        from ..blender.lists import queue_filters
        from ..blender.review import first_frame, load_state, object_for
        from ..core.review import bad_runs, frame_trouble, plural, review_queue

        coll = reviewed_panel_take(context)  # the Review panel's take, as Previous / Next
        lab = load_state(coll).labeling
        sure = context.scene.mocap_autolabel.sure
        filters = queue_filters(context.scene.mocap_autolabel)
        runs = bad_runs(lab, sure, self.rank + 1, **filters)
        if len(runs) <= self.rank:
            self.report({"INFO"}, "No frame needs a look: nothing is left to review and no label is missing")
            return {"CANCELLED"}
        run = runs[self.rank]
        uncertain, missing = frame_trouble(lab, sure, **filters)
        peak = run.start + int(np.argmax((uncertain + missing)[run.start:run.stop]))
        context.scene.frame_set(peak + first_frame(coll))
        # Select the segment there that comes first in the queue, if any, so that Relabel acts on it.
        queue = review_queue(lab, sure, **filters)
        here = queue[(lab.start[queue] <= peak) & (lab.stop[queue] > peak)]
        obj = object_for(coll, lab, int(here[0])) if len(here) else None
        if obj is not None and obj.name in context.view_layer.objects:
            for other in context.selected_objects:
                other.select_set(False)
            obj.select_set(True)
            context.view_layer.objects.active = obj
        self.report({"INFO"}, f"Frame {peak + first_frame(coll)}: {plural(int(uncertain[peak]), 'sample')} to review, "
                              f"{plural(int(missing[peak]), 'label')} missing (frames {run.start + first_frame(coll)}-"
                              f"{run.stop - 1 + first_frame(coll)})")
        return {"FINISHED"}


classes = (MOCAPAL_OT_jump_to_worst,)
