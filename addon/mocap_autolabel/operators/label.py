"""Label Markers: label the take in the panel's Take field, on a worker thread while Blender stays
responsive (from a script or in background mode, at once).

The operator gathers everything from the scene on the main thread (``blender.review.prepare_label``),
runs the labeling as a core job (``LabelRequest.run``: no Blender data touched) while its modal
handler shows the stage and the share done (Esc cancels and leaves the scene as it was), and shows
and stores the result on the main thread (``blender.review.finish_label``). One undo step.
"""

from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, StringProperty

from ..blender.properties import HANDS_ITEMS, LAYOUT_DEFAULT, TEMPORAL_ITEMS, _layouts, _methods
from .common import _not_a_take, _present, panel_take
from .modal import JobModal, start_modal


class MOCAPAL_OT_label(JobModal, bpy.types.Operator):
    """Label the take in the panel's Take field: every trajectory gets a marker name or is set aside as
    unlabeled, with its confidence shown as keyframe types"""

    bl_idname = "mocap_autolabel.label"
    bl_label = "Label Markers"
    bl_options = {"REGISTER", "UNDO"}

    layout: EnumProperty(name="Layout", items=_layouts, default=LAYOUT_DEFAULT,
                         description="Marker layout to label with")
    layout_file: StringProperty(name="Layout File", subtype="FILE_PATH",
                                description="A layout .toml instead of a built-in layout")
    method: EnumProperty(name="Method", items=_methods, description="Per-frame labeler")
    temporal: EnumProperty(name="Temporal", items=TEMPORAL_ITEMS)
    hands: EnumProperty(name="Hands", items=HANDS_ITEMS, default="auto",
                        description="How many hands of the layout the take holds")
    use_as_panel_layout: BoolProperty(name="Keep as the Panel's Layout", default=False, options={"SKIP_SAVE"},
                                      description="Also put this layout in the panel's Layout field (the "
                                                  "Review panel's 'Label as' button does)")

    #: The settings the operator shares with the panel: given to the operator (from Python, a
    #: button, or the redo panel), they win; not given, the panel's are used.
    SETTINGS = ("layout", "layout_file", "method", "temporal", "hands")

    @classmethod
    def poll(cls, context):
        return _present(cls, panel_take(context), _not_a_take(context)
                        or "Import a take first (File > Import > C3D Markers), or select one of its markers")

    def _settings(self, context) -> dict:
        """Layout, layout file, method and temporal mode: the operator's own where given, else the panel's.
        The layout and its file go together: a layout given alone is not overridden by the panel's file."""
        panel = context.scene.mocap_autolabel
        given = {name: self.properties.is_property_set(name) for name in self.SETTINGS}
        if given["layout"] or given["layout_file"]:
            given["layout"] = given["layout_file"] = True
        return {name: getattr(self if given[name] else panel, name) for name in self.SETTINGS}

    def _request(self, context):
        from ..blender.properties import LAYOUT_CHOICE, USER_LAYOUT
        from ..blender.review import prepare_label
        from ..blender.takes import has_review
        from ..core.layout import DEFAULT_LAYOUT

        src = self._settings(context)
        layout = bpy.path.abspath(src["layout_file"]) if src["layout_file"] else src["layout"]
        take = panel_take(context)
        request = prepare_label(take, layout, src["method"], src["temporal"], src["hands"])
        # A take's first labeling with a layout nobody chose (not given to the operator, never set in
        # the panel, not picked from the file's names): the take's shape may pick another
        # (see LabelRequest.pick_layout).
        given = self.properties.is_property_set("layout") or self.properties.is_property_set("layout_file")
        settings = context.scene.mocap_autolabel
        request.pick_layout = not (given or src["layout_file"] or settings.get(USER_LAYOUT) or has_review(take)
                                   or take.get(LAYOUT_CHOICE) not in (None, DEFAULT_LAYOUT))
        return request

    def _fail(self, exc: Exception, coll_name: str) -> set[str]:
        from ..core.errors import MocapInputError

        if isinstance(exc, (MocapInputError, ValueError)):
            self.report({"ERROR"}, str(exc))
        else:  # never let an unexpected failure take Blender down
            self.report({"ERROR"}, f"{coll_name}: labeling failed ({type(exc).__name__}: {exc})")
        return {"CANCELLED"}

    def _finish(self, context, request, labeling) -> set[str]:
        from ..blender.review import finish_label, summary
        from ..blender.takes import first_frame
        from ..core.review import plural

        coll = bpy.data.collections.get(request.take_name)
        if coll is None:
            self.report({"ERROR"}, f"the take {request.take_name!r} was removed while it was being labeled")
            return {"CANCELLED"}
        try:
            finish_label(context.scene, coll, request, labeling)
        except ValueError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        settings = context.scene.mocap_autolabel
        if self.use_as_panel_layout and request.layout_ref in {name for name, *_ in _layouts(None, context)}:
            settings.layout, settings.layout_file = request.layout_ref, ""
        if request.picked:
            from ..blender.properties import set_layout

            set_layout(settings, request.picked["to"])  # the panel shows what the take is labeled with
            p = request.picked
            self.report({"INFO"}, f"Layout set to {p['to']}: the take fits it better ({100 * p['better_share']:.0f} % "
                                  f"of labeled samples confident, against {100 * p['share']:.0f} % with {p['from']})")
        s = summary(labeling, context.scene.mocap_autolabel.sure, first_frame(coll))
        if request.dropped:
            self.report({"WARNING"}, self._dropped_message(coll, request))
        kept = len(request.review.constraints) + len(request.review.splits)
        self.report({"INFO"}, f"Labeled {request.take_name} with {request.layout.name}: "
                              f"{s['labels']} labels, {s['confident']:.1f} % of labeled samples confident, "
                              f"{plural(s['uncertain'], 'uncertain segment')}"
                              + (f"; {s['hands']}" if s["hands"] else "")
                              + (f"; {s['hands_traded']}" if s["hands_traded"] else "")
                              + (f"; {plural(kept, 'correction')} kept" if kept else ""))
        if s["hands_warning"]:
            self.report({"WARNING"}, f"{request.take_name}: {s['hands_warning']}")
        if s["layout_doubt"]:
            self.report({"WARNING"}, f"{request.take_name}: {s['layout_doubt']}")
        from ..core.process import occlusion_note, work_limit_warning

        hurried = work_limit_warning(labeling)  # as the CLI and batch warn
        if hurried:
            self.report({"WARNING"}, f"{request.take_name}: {hurried}")
        occluded = occlusion_note(labeling)
        if occluded:
            self.report({"INFO"}, f"{request.take_name}: {occluded}")
        return {"FINISHED"}

    @staticmethod
    def _dropped_message(coll, request) -> str:
        from ..blender.takes import first_frame, trajectory_names
        from ..core.review import describe

        names, first = trajectory_names(coll), first_frame(coll)
        old = request.dropped_names
        said = "; ".join(describe(c, old, names, first) for c in request.dropped)
        n = len(request.dropped)
        lacks = f"{request.layout.name} lacks"
        if request.hands_changed:
            hands = "two hands" if request.hand_options.get("hand_count") == 2 else "one hand"
            lacks = f"{request.layout.name} with {hands} lacks"
        return (f"{request.take_name}: {n} {'correction names a marker' if n == 1 else 'corrections name markers'} "
                f"that {lacks}, and {'is' if n == 1 else 'are'} dropped ({said}); "
                f"undo (Ctrl+Z) brings {'it' if n == 1 else 'them'} back")

    def execute(self, context):
        coll_name = panel_take(context).name
        try:
            request = self._request(context)
            labeling = request.run(_printer() if bpy.app.background else None, check_layout=True)
        except Exception as exc:
            return self._fail(exc, coll_name)
        return self._finish(context, request, labeling)

    def invoke(self, context, event):
        from ..core.jobs import Job

        # Show the settings used in the redo panel: the panel's, where the caller gave none.
        for name, value in self._settings(context).items():
            setattr(self, name, value)
        coll_name = panel_take(context).name
        try:
            self._pending = self._request(context)
        except Exception as exc:
            return self._fail(exc, coll_name)
        return start_modal(self, context, Job(lambda say: self._pending.run(say, check_layout=True)))

    def _progress(self, job) -> tuple[str, float]:
        request = self._pending
        return f"Labeling {request.take_name}: {request.stage or job.message}", request.done

    def _job_failed(self, exc):
        return self._fail(exc, self._pending.take_name)

    def _job_done(self, context, labeling):
        return self._finish(context, self._pending, labeling)


def _printer():
    def say(message: str) -> None:
        print(f"mocap_autolabel: {message}", flush=True)

    return say


classes = (MOCAPAL_OT_label,)
