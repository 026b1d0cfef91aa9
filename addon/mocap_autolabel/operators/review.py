"""Label, review and correct a take in the scene.

Each operator finds the take (the scene's reviewed take, else the active object's), calls the
core (``core.pipeline``, ``core.review``) and the scene layer (``blender.review``), and is one
undo step. Corrections are recorded as constraints on the take, so a re-solve keeps them.
"""

from __future__ import annotations

import os

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from ..blender.properties import LAYOUT_DEFAULT, TEMPORAL_ITEMS, _layouts, _methods


def context_take(context) -> bpy.types.Collection | None:
    """The take an operator works on: the active marker's, else the one in the panel's Take field."""
    from ..blender.review import take_collection

    found = take_collection(context.active_object) if context.active_object else None
    settings = context.scene.mocap_autolabel
    if found is None and settings.take is not None and settings.take.name in bpy.data.collections:
        found = settings.take
    return found


def reviewed_take(context) -> bpy.types.Collection | None:
    """:func:`context_take` where it has been labeled (holds a review), else None."""
    from ..blender.review import has_review

    coll = context_take(context)
    return coll if has_review(coll) else None


def _present(cls, found, message: str) -> bool:
    """A poll result: whether ``found`` exists, with ``message`` shown where it does not."""
    if found is None:
        cls.poll_message_set(message)
        return False
    return True


class _ReviewOperator:
    """Shared poll and error handling of the operators that work on a labeled take."""

    bl_options = {"REGISTER", "UNDO"}
    resolves = False  # the re-solve itself needs no re-solve after it

    @classmethod
    def poll(cls, context):
        return _present(cls, reviewed_take(context), "Label a take first (Mocap sidebar tab > Label)")

    def execute(self, context):
        from ..blender.review import load_state
        from ..core.errors import MocapInputError

        coll = reviewed_take(context)
        try:
            message = self.apply(context, coll, load_state(coll))
        except (MocapInputError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        if context.scene.mocap_autolabel.auto_resolve and not self.resolves:
            message += "; " + _resolve(context, coll)
        self.report({"INFO"}, message)
        return {"FINISHED"}

    def apply(self, context, coll, state) -> str:
        raise NotImplementedError

    # What the reviewer points at: the active (or selected) marker at the current frame.
    def _targets(self, context, coll, state, selected: bool = False) -> list[int]:
        from ..blender.review import sample_index, slot_of

        index = sample_index(coll, context.scene.frame_current)
        objs = list(context.selected_objects) if selected else []
        if context.active_object is not None and context.active_object not in objs:
            objs.insert(0, context.active_object)
        slots = [slot_of(obj, state.labeling, index) for obj in objs]
        slots = [s for s in slots if s is not None]
        if not slots:
            raise ValueError(f"the selected marker has no sample at frame {context.scene.frame_current}")
        return list(dict.fromkeys(slots))

    def _each_selected(self, context, coll, state, correct, what: str) -> str:
        """Make one correction ``correct(labeling, slot, index)`` per selected marker at the current frame."""
        from ..blender.review import sample_index

        index = sample_index(coll, context.scene.frame_current)
        made = [correct(state.labeling, s, index) for s in self._targets(context, coll, state, True)]
        return f"{len(made)} {what}: " + self._edit(context, coll, state, made)

    def _edit(self, context, coll, state, constraints) -> str:
        from ..blender.review import edit
        from ..core.review import apply_constraints

        edit(context.scene, coll, state, apply_constraints(state.labeling, constraints))
        return f"{len(state.review.constraints)} corrections on the take"


def _resolve(context, coll) -> str:
    from ..blender.review import finish_label, prepare_label

    request = prepare_label(coll)
    counts = finish_label(context.scene, coll, request, request.run())
    return f"re-solved: {counts['labeled']} labeled and {counts['unlabeled']} unlabeled markers rewritten"


class MOCAPAL_OT_label(bpy.types.Operator):
    """Label the imported take: every trajectory gets a marker name or is set aside as unlabeled, with
    its confidence shown as keyframe types"""

    bl_idname = "mocap_autolabel.label"
    bl_label = "Label Markers"
    bl_options = {"REGISTER", "UNDO"}

    layout: EnumProperty(name="Layout", items=_layouts, default=LAYOUT_DEFAULT,
                         description="Marker layout to label with")
    layout_file: StringProperty(name="Layout File", subtype="FILE_PATH",
                                description="A layout .toml instead of a built-in layout")
    method: EnumProperty(name="Method", items=_methods, description="Per-frame labeler")
    temporal: EnumProperty(name="Temporal", items=TEMPORAL_ITEMS)
    use_scene_settings: BoolProperty(default=True, options={"HIDDEN", "SKIP_SAVE"},
                                     description="Take layout, method and temporal mode from the panel")

    @classmethod
    def poll(cls, context):
        return _present(cls, context_take(context),
                        "Import a take first (File > Import > C3D Markers), or select one of its markers")

    def _request(self, context):
        from ..blender.review import prepare_label

        settings = context.scene.mocap_autolabel
        src = settings if self.use_scene_settings else self
        layout = bpy.path.abspath(src.layout_file) if src.layout_file else src.layout
        return prepare_label(context_take(context), layout, src.method, src.temporal)

    def _fail(self, exc: Exception, coll_name: str) -> set[str]:
        from ..core.errors import MocapInputError

        if isinstance(exc, (MocapInputError, ValueError)):
            self.report({"ERROR"}, str(exc))
        else:  # never let an unexpected failure take Blender down
            self.report({"ERROR"}, f"{coll_name}: labeling failed ({type(exc).__name__}: {exc})")
        return {"CANCELLED"}

    def _finish(self, context, request, labeling) -> set[str]:
        from ..blender.review import finish_label, summary

        coll = bpy.data.collections.get(request.take_name)
        if coll is None:
            self.report({"ERROR"}, f"the take {request.take_name!r} was removed while it was being labeled")
            return {"CANCELLED"}
        try:
            finish_label(context.scene, coll, request, labeling)
        except ValueError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        s = summary(labeling, context.scene.mocap_autolabel.sure)
        self.report({"INFO"}, f"Labeled {request.take_name}: {s['labels']} labels, {s['confident']:.1f} % of "
                              f"labeled samples confident, {s['uncertain']} uncertain segments")
        if s["layout_doubt"]:
            self.report({"WARNING"}, f"{request.take_name}: {s['layout_doubt']}")
        from ..core.pipeline import time_limit_warning

        hurried = time_limit_warning(labeling)  # as the CLI and batch warn
        if hurried:
            self.report({"WARNING"}, f"{request.take_name}: {hurried}")
        return {"FINISHED"}

    def execute(self, context):
        coll_name = context_take(context).name
        try:
            request = self._request(context)
            labeling = request.run(_printer() if bpy.app.background else None, check_layout=True)
        except Exception as exc:
            return self._fail(exc, coll_name)
        return self._finish(context, request, labeling)

    def invoke(self, context, event):
        from ..core.jobs import Job

        coll_name = context_take(context).name
        try:
            self._pending = self._request(context)
        except Exception as exc:
            return self._fail(exc, coll_name)
        self._job = Job(lambda say: self._pending.run(say, check_layout=True)).start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        wm.progress_begin(0, 100)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS":
            job.cancel()
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if not job.done:
            context.workspace.status_text_set(f"Labeling {self._pending.take_name}: {job.message} "
                                              f"({job.elapsed:.1f} s) - Esc to cancel")
            context.window_manager.progress_update(min(99, int(job.elapsed * 10)))
            return {"PASS_THROUGH"}
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        context.workspace.status_text_set(None)
        if job.cancelled:
            self.report({"WARNING"}, "Labeling cancelled; the scene is unchanged")
            return {"CANCELLED"}
        if job.error is not None:
            return self._fail(job.error, self._pending.take_name)
        return self._finish(context, self._pending, job.result)


def _printer():
    def say(message: str) -> None:
        print(f"mocap_autolabel: {message}", flush=True)

    return say


class MOCAPAL_OT_resolve(_ReviewOperator, bpy.types.Operator):
    """Label the take again honouring every correction; only markers whose decision changes are rewritten"""

    bl_idname = "mocap_autolabel.resolve"
    bl_label = "Re-solve Labels"
    resolves = True

    def apply(self, context, coll, state) -> str:
        return _resolve(context, coll)


def _label_items(self, context):
    from ..blender.review import load_state

    coll = reviewed_take(context)
    names = load_state(coll).labeling.names if coll is not None else []
    items = [(str(i), name, f"Label {name}") for i, name in enumerate(names)]
    _label_items.cache = items  # Blender keeps no reference to dynamic enum strings
    return items


class MOCAPAL_OT_assign_label(_ReviewOperator, bpy.types.Operator):
    """Give the active marker's trajectory a label from the current frame to the end of its segment
    (a label taken from another trajectory leaves that one unlabeled)"""

    bl_idname = "mocap_autolabel.assign_label"
    bl_label = "Assign Label"
    bl_property = "label"

    label: EnumProperty(name="Label", items=_label_items)

    def invoke(self, context, event):
        context.window_manager.invoke_search_popup(self)
        return {"RUNNING_MODAL"}

    def apply(self, context, coll, state) -> str:
        from ..blender.review import sample_index

        slot = self._targets(context, coll, state)[0]
        index = sample_index(coll, context.scene.frame_current)
        c = state.review.assign(state.labeling, slot, index, int(self.label))
        return f"{state.labeling.names[c.label]} from frame {context.scene.frame_current}: " + \
            self._edit(context, coll, state, [c])


class MOCAPAL_OT_swap_labels(_ReviewOperator, bpy.types.Operator):
    """Swap the labels of the two selected markers from the current frame on"""

    bl_idname = "mocap_autolabel.swap_labels"
    bl_label = "Swap Labels"

    def apply(self, context, coll, state) -> str:
        from ..blender.review import sample_index

        objs = [o for o in context.selected_objects if "mocap_label" in o]
        if len(objs) != 2:
            raise ValueError("select exactly two labeled markers to swap")
        a, b = (int(o["mocap_label"]) for o in objs)
        index = sample_index(coll, context.scene.frame_current)
        made = state.review.swap(state.labeling, a, b, index)
        names = state.labeling.names
        return f"swapped {names[a]} and {names[b]}: " + self._edit(context, coll, state, made)


class MOCAPAL_OT_unlabel(_ReviewOperator, bpy.types.Operator):
    """Mark the selected markers' trajectories as ghosts (unlabeled) from the current frame to the end of
    their segments"""

    bl_idname = "mocap_autolabel.unlabel"
    bl_label = "Unlabel"

    def apply(self, context, coll, state) -> str:
        return self._each_selected(context, coll, state, state.review.unlabel, "trajectories unlabeled")


class MOCAPAL_OT_lock(_ReviewOperator, bpy.types.Operator):
    """Lock the selected markers' segments under the current frame as they are: a re-solve keeps them"""

    bl_idname = "mocap_autolabel.lock"
    bl_label = "Lock"

    def apply(self, context, coll, state) -> str:
        return self._each_selected(context, coll, state, state.review.lock, "segments locked")


class MOCAPAL_OT_split(_ReviewOperator, bpy.types.Operator):
    """Cut the active marker's trajectory at the current frame: the two parts are labeled separately"""

    bl_idname = "mocap_autolabel.split"
    bl_label = "Split Trajectory"

    def apply(self, context, coll, state) -> str:
        from ..blender.review import edit, sample_index
        from ..core.review import apply_split

        slot = self._targets(context, coll, state)[0]
        index = sample_index(coll, context.scene.frame_current)
        lab = state.labeling
        if ((lab.slot == slot) & (lab.start == index)).any():
            raise ValueError(f"{context.active_object.name}: a new segment already starts at frame "
                             f"{context.scene.frame_current}; nothing to split")
        state.review.split(lab, slot, index)
        edit(context.scene, coll, state, apply_split(state.labeling, slot, index))
        return f"split slot {slot} at frame {context.scene.frame_current}"


class MOCAPAL_OT_next_uncertain(bpy.types.Operator):
    """Jump to the next (or previous) uncertain segment and select its marker"""

    bl_idname = "mocap_autolabel.next_uncertain"
    bl_label = "Next Uncertain"
    bl_options = {"REGISTER", "UNDO"}

    previous: BoolProperty(name="Previous", default=False, options={"SKIP_SAVE"})

    @classmethod
    def poll(cls, context):
        return reviewed_take(context) is not None

    def execute(self, context):
        import numpy as np

        from ..blender.review import load_state, sample_index
        from ..core.review import uncertain_segments

        coll = reviewed_take(context)
        lab = load_state(coll).labeling
        sure = context.scene.mocap_autolabel.sure
        idx = uncertain_segments(lab, sure)
        now = sample_index(coll, context.scene.frame_current)
        starts = lab.start[idx]
        pick = idx[starts < now] if self.previous else idx[starts > now]
        if not len(pick):
            self.report({"INFO"}, f"No uncertain segment {'before' if self.previous else 'after'} this frame")
            return {"CANCELLED"}
        # Next: the earliest start after now; previous: the latest before it; ties: the worst first.
        edge = lab.start[pick].max() if self.previous else lab.start[pick].min()
        tied = pick[lab.start[pick] == edge]
        seg = int(tied[np.argmin(lab.confidence[tied])])
        _show_segment(context, coll, lab, seg)
        return {"FINISHED"}


def _show_segment(context, coll, lab, seg: int) -> None:
    from ..blender.review import first_frame, object_for

    context.scene.frame_set(int(lab.start[seg]) + first_frame(coll))
    obj = object_for(coll, lab, seg)
    if obj is not None and obj.name in context.view_layer.objects:
        for other in context.selected_objects:
            other.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj


class MOCAPAL_OT_jump_to_segment(bpy.types.Operator):
    """Go to an uncertain segment of the list: set the frame to its start and select its marker"""

    bl_idname = "mocap_autolabel.jump_to_segment"
    bl_label = "Jump to Segment"
    bl_options = {"REGISTER", "UNDO", "INTERNAL"}

    index: IntProperty(name="List Index", default=0, min=0)

    @classmethod
    def poll(cls, context):
        return reviewed_take(context) is not None

    def execute(self, context):
        import numpy as np

        from ..blender.review import first_frame, load_state

        settings = context.scene.mocap_autolabel
        if self.index >= len(settings.uncertain):
            return {"CANCELLED"}
        item = settings.uncertain[self.index]
        coll = reviewed_take(context)
        lab = load_state(coll).labeling
        start = item.frame_start - first_frame(coll)
        seg = np.flatnonzero((lab.slot == item.slot) & (lab.start == start))
        if not len(seg):
            self.report({"WARNING"}, "That segment changed; the list is refreshed after the next edit")
            return {"CANCELLED"}
        _show_segment(context, coll, lab, int(seg[0]))
        return {"FINISHED"}


class MOCAPAL_OT_export_labeled(bpy.types.Operator, ExportHelper):
    """Write the reviewed take as a labeled C3D: the layout's markers by name, then one *N point per
    trajectory left unlabeled"""

    bl_idname = "mocap_autolabel.export_labeled"
    bl_label = "Export Labeled C3D"
    bl_options = {"REGISTER"}

    filename_ext = ".c3d"
    filter_glob: StringProperty(default="*.c3d", options={"HIDDEN"})

    @classmethod
    def poll(cls, context):
        return reviewed_take(context) is not None

    def invoke(self, context, event):
        coll = reviewed_take(context)
        if not self.filepath and coll is not None:
            src = coll.get("mocap_source") or coll.name
            self.filepath = os.path.splitext(bpy.path.abspath(src) if src else coll.name)[0] + "_labeled.c3d"
        return ExportHelper.invoke(self, context, event)

    def execute(self, context):
        from ..blender.review import current_take, load_state
        from ..core.errors import MocapInputError
        from ..core.formats.c3d import write_c3d
        from ..core.labeling import labeled_take

        coll = reviewed_take(context)
        path = bpy.path.abspath(self.filepath)
        try:
            write_c3d(labeled_take(current_take(coll), load_state(coll).labeling), path)
        except (MocapInputError, OSError, ValueError) as exc:
            self.report({"ERROR"}, f"{path}: {exc}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Wrote {path}")
        return {"FINISHED"}


classes = (MOCAPAL_OT_label, MOCAPAL_OT_resolve, MOCAPAL_OT_assign_label, MOCAPAL_OT_swap_labels,
           MOCAPAL_OT_unlabel, MOCAPAL_OT_lock, MOCAPAL_OT_split, MOCAPAL_OT_next_uncertain,
           MOCAPAL_OT_jump_to_segment, MOCAPAL_OT_export_labeled)
