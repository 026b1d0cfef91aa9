"""The Cleanup panel's tools on a labeled take: Find Spikes, Smooth, Delete Short Fragments, Quick Label,
and the Fill Preview (Preview Fill, Fill Gap With, Apply Fill Preview). Each is one undo step; the work
is ``blender/cleanup.py``'s.

Find Spikes, Smooth and Delete Short Fragments act on the selected labeled markers of the panel's take
(all of its labeled markers when none is selected), as Fill Gaps does; their thresholds are the
panel's unless given to the operator. Quick Label and Preview Fill act on the active marker.
"""

from __future__ import annotations

import contextlib

import bpy
from bpy.props import EnumProperty, FloatProperty, IntProperty, StringProperty

from ..blender.cleanup_settings import CUTOFF_HZ, FILTER_ORDER, MAX_ACCEL, MAX_GAP, MAX_SPEED, MIN_FRAMES
from .common import _not_a_take, _present, reviewed_take
from .corrections import _ReviewOperator
from .fill import _METHODS
from .modal import JobModal, in_background, start_modal


def _selected_labels(context, coll) -> list[int] | None:
    """The labels of the selected labeled markers of the take, None (all) when none is selected."""
    from ..blender.takes import take_collection

    labels = [int(o["mocap_label"]) for o in context.selected_objects
              if "mocap_label" in o and take_collection(o) == coll]
    return labels or None


def _panel_values(op, context, *names: str) -> None:
    """The panel's value of each property the caller did not give (the Adjust Last Operation panel then
    shows the values used)."""
    settings = context.scene.mocap_autolabel.cleanup
    for name in names:
        if not op.properties.is_property_set(name):
            setattr(op, name, getattr(settings, name))


@contextlib.contextmanager
def _progress(context):
    """A progress callback ``say(message, share)`` for the window manager's progress bar."""
    wm = context.window_manager
    wm.progress_begin(0, 100)
    try:
        yield lambda _message, share: wm.progress_update(int(100 * share))
    finally:
        wm.progress_end()


class _CleanupOperator(_ReviewOperator):
    """On the panel's take; one-line errors and the undo step of the review operators."""

    from_panel = True
    resolves = True  # no re-solve after it (Re-solve After Each Edit is for corrections)


class MOCAPAL_OT_find_spikes(_CleanupOperator, bpy.types.Operator):
    """Find the samples of the selected labeled markers (all when none is selected) that leave the marker's
    course for a few frames and come back, or jump, faster than a finger can, and mark them for review:
    each becomes a piece of its own, very uncertain (pink keys), which Previous / Next visit"""

    bl_idname = "mocap_autolabel.find_spikes"
    bl_label = "Find Spikes"

    max_accel: FloatProperty(name="Max Acceleration", default=MAX_ACCEL, min=0.1, soft_max=200.0,
                             description="m/s²: the acceleration a marker's course keeps within around a spike "
                                         "(default: the Cleanup panel's)")
    max_speed: FloatProperty(name="Max Speed", default=MAX_SPEED, min=0.01, soft_max=20.0,
                             description="m/s: a step between two frames faster than this is a jump (default: the "
                                         "Cleanup panel's)")

    def apply(self, context, coll, state) -> str:
        from ..blender.cleanup import mark_spikes

        _panel_values(self, context, "max_accel", "max_speed")
        with _progress(context) as say:
            return mark_spikes(context.scene, coll, state, labels=_selected_labels(context, coll), progress=say,
                               **self.as_keywords())["message"]


class MOCAPAL_OT_smooth(_CleanupOperator, bpy.types.Operator):
    """Low-pass the selected labeled markers (all when none is selected) with a zero-lag Butterworth filter:
    the take's samples themselves change (export and a relabel see them); gaps stay gaps"""

    bl_idname = "mocap_autolabel.smooth"
    bl_label = "Smooth"

    cutoff_hz: FloatProperty(name="Cut-off", default=CUTOFF_HZ, min=0.01, soft_max=30.0,
                             description="Hz, below half the take's frame rate (default: the Cleanup panel's)")
    order: IntProperty(name="Order", default=FILTER_ORDER, min=1, max=8,
                       description="The Butterworth filter's order (default: the Cleanup panel's)")

    def apply(self, context, coll, state) -> str:
        from ..blender.cleanup import smooth_markers

        _panel_values(self, context, "cutoff_hz", "order")
        with _progress(context) as say:
            return smooth_markers(context.scene, coll, state, labels=_selected_labels(context, coll), progress=say,
                                  **self.as_keywords())["message"]


class MOCAPAL_OT_delete_short_fragments(_CleanupOperator, bpy.types.Operator):
    """Take the samples in runs shorter than Shorter Than frames off the selected labeled markers (all when none
    is selected): they become unlabeled, by corrections a re-solve keeps"""

    bl_idname = "mocap_autolabel.delete_short_fragments"
    bl_label = "Delete Short Fragments"
    resolves = False  # corrections: Re-solve After Each Edit follows them

    min_frames: IntProperty(name="Shorter Than", default=MIN_FRAMES, min=1, soft_max=240,
                            description="Frames (default: the Cleanup panel's)")

    def apply(self, context, coll, state) -> str:
        from ..blender.cleanup import delete_short_fragments

        _panel_values(self, context, "min_frames")
        return delete_short_fragments(context.scene, coll, state, labels=_selected_labels(context, coll),
                                      **self.as_keywords())["message"]


class MOCAPAL_OT_quick_label(_ReviewOperator, bpy.types.Operator):
    """Give the active marker's trajectory (its whole segment under the current frame) the Next Label of the
    Cleanup panel, as a correction a re-solve keeps, and move Next Label on: click the points in the layout's
    order and Quick Label each"""

    bl_idname = "mocap_autolabel.quick_label"
    bl_label = "Quick Label"

    label: StringProperty(name="Label", options={"SKIP_SAVE"},
                          description="The label's name (default: the Cleanup panel's Next Label)")

    def apply(self, context, coll, state) -> str:
        from ..blender.cleanup import advance_quick_label, quick_constraint

        slot = self._targets(context, coll, state)[0]
        made, text = quick_constraint(context.scene, coll, state, slot=slot, frame=context.scene.frame_current,
                                      **self.as_keywords())
        text += self._edit(context, coll, state, [made])
        return text + advance_quick_label(context.scene, coll, label=made.label)


def _active_labeled(context) -> tuple:
    """``(take, label)`` of the active object where it is a labeled marker of a labeled take, else ``(None, -1)``."""
    from ..blender.takes import take_collection

    obj = context.active_object
    coll = reviewed_take(context) if obj is not None and "mocap_label" in obj else None
    if coll is None or take_collection(obj) != coll:
        return None, -1
    return coll, int(obj["mocap_label"])


class MOCAPAL_OT_fill_preview(JobModal, bpy.types.Operator):
    """List the gaps of the active labeled marker with the fill Fill Gaps' Auto picks for each: its method, the
    markers it is computed from and its expected error; pick another method per gap, then Apply"""

    bl_idname = "mocap_autolabel.fill_preview"
    bl_label = "Preview Fill"
    bl_options = {"REGISTER", "UNDO"}

    max_gap: FloatProperty(name="Max Gap", default=MAX_GAP, min=0.01, soft_max=5.0, unit="TIME_ABSOLUTE",
                           description="Longer gaps are left open, seconds (default: the Cleanup panel's)")

    @classmethod
    def poll(cls, context):
        return _present(cls, _active_labeled(context)[0],
                        _not_a_take(context) or "Select a labeled marker of a labeled take")

    def execute(self, context):
        from ..blender.cleanup import preview_fill

        coll, label = _active_labeled(context)
        _panel_values(self, context, "max_gap")
        try:
            with _progress(context) as say:
                result = preview_fill(context.scene, coll, label=label, progress=say, **self.as_keywords())
        except Exception as exc:
            return self._job_failed(exc)
        self.report({"INFO"}, result["message"])
        return {"FINISHED"}

    def invoke(self, context, event):
        """From the panel: the preview works on a worker thread (the hand may be solved again), the status bar
        shows its stage, Esc cancels; from a script, at once."""
        from ..blender.cleanup import prepare_preview
        from ..core.jobs import Job

        if not in_background(context):
            return self.execute(context)
        coll, label = _active_labeled(context)
        _panel_values(self, context, "max_gap")
        try:
            self._pending = prepare_preview(coll, label=label, **self.as_keywords())
        except Exception as exc:
            return self._job_failed(exc)
        return start_modal(self, context, Job(self._pending.run))

    def _progress(self, job) -> tuple[str, float]:
        request = self._pending
        return f"Previewing the fill of {request.name}: {request.stage}", request.share

    def _job_failed(self, exc: BaseException) -> set[str]:
        from ..core.errors import MocapInputError

        if isinstance(exc, (MocapInputError, ValueError)):
            self.report({"ERROR"}, str(exc))
        else:  # never let an unexpected failure take Blender down
            self.report({"ERROR"}, f"the fill preview failed ({type(exc).__name__}: {exc})")
        return {"CANCELLED"}

    def _job_done(self, context, result) -> set[str]:
        from ..blender.cleanup import finish_preview

        coll = bpy.data.collections.get(self._pending.take_name)
        if coll is None:
            self.report({"ERROR"}, f"the take {self._pending.take_name!r} was removed while its fill was previewed")
            return {"CANCELLED"}
        try:
            result = finish_preview(context.scene, coll, self._pending, result)
        except Exception as exc:
            return self._job_failed(exc)
        self.report({"INFO"}, result["message"])
        return {"FINISHED"}


class _PreviewOperator:
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        settings = context.scene.mocap_autolabel.cleanup
        return _present(cls, settings.preview_take if len(settings.preview) else None,
                        "Preview the fill of a labeled marker first (Cleanup panel > Preview Fill)")

    def _run(self, call) -> set[str]:
        from ..core.errors import MocapInputError

        try:
            result = call()
        except (MocapInputError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        self.report({"INFO"}, result["message"])
        return {"FINISHED"}


class MOCAPAL_OT_fill_preview_method(_PreviewOperator, bpy.types.Operator):
    """Fill a gap of the fill preview by another method (the list's active gap)"""

    bl_idname = "mocap_autolabel.fill_preview_method"
    bl_label = "Fill Gap With"

    method: EnumProperty(name="Method", items=_METHODS, default="auto")
    row: IntProperty(name="Gap", default=-1, min=-1, options={"SKIP_SAVE"},
                     description="Row of the Fill Preview list (default: its active row)")

    def execute(self, context):
        from ..blender.cleanup import choose_fill_method

        return self._run(lambda: choose_fill_method(context.scene, **self.as_keywords()))


class MOCAPAL_OT_fill_preview_apply(_PreviewOperator, bpy.types.Operator):
    """Write the fills of the fill preview into its marker, as Fill Gaps writes fills (Generated keys, exported
    as computed samples)"""

    bl_idname = "mocap_autolabel.fill_preview_apply"
    bl_label = "Apply Fill Preview"

    def execute(self, context):
        from ..blender.cleanup import apply_fill_preview

        return self._run(lambda: apply_fill_preview(context.scene))


classes = (MOCAPAL_OT_find_spikes, MOCAPAL_OT_smooth, MOCAPAL_OT_delete_short_fragments, MOCAPAL_OT_quick_label,
           MOCAPAL_OT_fill_preview, MOCAPAL_OT_fill_preview_method, MOCAPAL_OT_fill_preview_apply)
