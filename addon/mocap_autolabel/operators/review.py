"""Label, review and correct a take in the scene.

Label, Re-solve, Previous / Next, the lists and Export work on the take in the panel's Take field
(an import puts the new take there); the corrections (Assign, Swap, Unlabel, Split, Lock,
Unlock) on the take of the selected markers. Each operator calls the core (``core.pipeline``,
``core.review``) and the scene layer (``blender.review``), and is one undo step. Corrections are
recorded as constraints on the take, so a re-solve keeps them.
"""

from __future__ import annotations

import os

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from ..blender.properties import HANDS_ITEMS, LAYOUT_DEFAULT, TEMPORAL_ITEMS, _layouts, _methods
from .modal import start_modal


def _is_take(coll) -> bool:
    return coll is not None and coll.name in bpy.data.collections and "mocap_source" in coll


def panel_take(context) -> bpy.types.Collection | None:
    """The take in the panel's Take field (what Label, Re-solve, Previous / Next and Export act on);
    where the field is empty, the active marker's take. A collection that is not an imported take
    is never returned."""
    from ..blender.review import take_collection

    settings = context.scene.mocap_autolabel
    if settings.take is not None:
        return settings.take if _is_take(settings.take) else None
    return take_collection(context.active_object) if context.active_object else None


def context_take(context) -> bpy.types.Collection | None:
    """The take of the active marker (what a correction acts on), else the panel's take."""
    from ..blender.review import take_collection

    found = take_collection(context.active_object) if context.active_object else None
    return found if _is_take(found) else panel_take(context)


def reviewed_take(context) -> bpy.types.Collection | None:
    """:func:`context_take` where it has been labeled (holds a review), else None."""
    from ..blender.review import has_review

    coll = context_take(context)
    return coll if has_review(coll) else None


def reviewed_panel_take(context) -> bpy.types.Collection | None:
    """:func:`panel_take` where it has been labeled, else None."""
    from ..blender.review import has_review

    coll = panel_take(context)
    return coll if has_review(coll) else None


def _present(cls, found, message: str) -> bool:
    """A poll result: whether ``found`` exists, with ``message`` shown where it does not."""
    if found is None:
        cls.poll_message_set(message)
        return False
    return True


def _not_a_take(context) -> str | None:
    """Why the panel's Take field cannot be worked on (it holds a collection that is not a take)."""
    take = context.scene.mocap_autolabel.take
    if take is not None and not _is_take(take):
        return f"'{take.name}' is not an imported take: choose a take in the Take field"
    return None


class _ReviewOperator:
    """Shared poll and error handling of the operators that work on a labeled take."""

    bl_options = {"REGISTER", "UNDO"}
    resolves = False  # the re-solve itself needs no re-solve after it
    from_panel = False  # acts on the panel's take (else on the selected marker's)

    @classmethod
    def _take(cls, context):
        return reviewed_panel_take(context) if cls.from_panel else reviewed_take(context)

    @classmethod
    def poll(cls, context):
        return _present(cls, cls._take(context),
                        _not_a_take(context) or "Label a take first (Mocap sidebar tab > Label)")

    def execute(self, context):
        from ..blender.review import load_state
        from ..core.errors import MocapInputError

        coll = self._take(context)
        state = load_state(coll)
        self._before = list(state.review.constraints)
        self._overridden = []
        try:
            message = self.apply(context, coll, state)
        except (MocapInputError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        if context.scene.mocap_autolabel.auto_resolve and not self.resolves:
            message += "; " + _resolve(context, coll)
        if self._overridden:
            self.report({"WARNING"}, self._overrides_message(coll, state))
        self.report({"INFO"}, message)
        return {"FINISHED"}

    def _overrides_message(self, coll, state) -> str:
        from ..blender.review import first_frame, trajectory_names
        from ..core.review import describe

        names, first = trajectory_names(coll), first_frame(coll)
        said = "; ".join(describe(c, state.labeling.names, names, first) for c in self._overridden)
        return f"this overrides your earlier {'correction' if len(self._overridden) == 1 else 'corrections'} ({said})"

    def apply(self, context, coll, state) -> str:
        raise NotImplementedError

    # What the reviewer points at: the active (or selected) marker at the current frame.
    def _picked(self, context, coll, selected: bool) -> list:
        """The take's markers the reviewer points at (the active one first), or an error naming why none."""
        from ..blender.review import take_collection

        objs = list(context.selected_objects) if selected else []
        if context.active_object is not None and context.active_object not in objs:
            objs.insert(0, context.active_object)
        objs = [o for o in objs if take_collection(o) == coll
                and any(k in o for k in ("mocap_label", "mocap_null", "mocap_slot"))]
        if not objs:
            raise ValueError("no marker selected: select a marker of the take (in the viewport or the Outliner)")
        return objs

    def _targets(self, context, coll, state, selected: bool = False) -> list[int]:
        from ..blender.review import sample_index, slot_of

        frame = context.scene.frame_current
        index = sample_index(coll, frame)
        objs = self._picked(context, coll, selected)
        slots = [slot_of(obj, state.labeling, index) for obj in objs]
        missing = [o.name for o, s in zip(objs, slots, strict=True) if s is None]
        slots = [s for s in slots if s is not None]
        if not slots:
            who = ", ".join(missing)
            raise ValueError(f"{who} {'has' if len(missing) == 1 else 'have'} no sample at frame {frame}")
        return list(dict.fromkeys(slots))

    def _each_selected(self, context, coll, state, correct, what: str) -> str:
        """Make one correction ``correct(labeling, slot, index)`` per selected marker at the current frame;
        ``what`` completes "IndexTip (*3) ..." (e.g. "unlabeled from frame 120")."""
        from ..blender.review import sample_index, trajectory_names

        index = sample_index(coll, context.scene.frame_current)
        slots = self._targets(context, coll, state, True)
        before = state.labeling
        made = [correct(before, s, index) for s in slots]
        names = trajectory_names(coll)
        who = ", ".join(_shown_as(before, s, index, names) for s in slots)
        return f"{who} {what}: " + self._edit(context, coll, state, made)

    def _edit(self, context, coll, state, constraints) -> str:
        from ..blender.review import edit
        from ..core.review import Review, apply_constraints, plural

        earlier = Review(self._before)
        for c in constraints:
            self._overridden += [o for o in earlier.overridden_by(c) if o not in self._overridden]
        edit(context.scene, coll, state, apply_constraints(state.labeling, constraints))
        return f"{plural(len(state.review.constraints), 'correction')} on the take"


def _shown_as(labeling, slot: int, index: int, names: list[str]) -> str:
    """How the reviewer sees the trajectory in ``slot`` at sample ``index``: ``"IndexTip (*3)"``, or
    ``"*3"`` where it is unlabeled."""
    label = int(labeling.per_sample()[index, slot]) if 0 <= index < labeling.n_frames else -1
    return f"{labeling.names[label]} ({names[slot]})" if label >= 0 else names[slot]


def _resolve(context, coll, review=None) -> str:
    """Label the take again with its corrections (or with ``review`` instead, e.g. one less)."""
    from ..blender.review import finish_label, prepare_label
    from ..core.review import plural

    request = prepare_label(coll)
    if review is not None:
        request.review = review
    counts = finish_label(context.scene, coll, request, request.run())
    n = counts["labeled"] + counts["unlabeled"]
    return f"re-solved: {plural(n, 'marker')} rewritten ({counts['labeled']} labeled, {counts['unlabeled']} unlabeled)"


class MOCAPAL_OT_label(bpy.types.Operator):
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
        from ..blender.review import has_review, prepare_label
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
        from ..blender.review import finish_label, first_frame, summary
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
        from ..core.pipeline import time_limit_warning

        hurried = time_limit_warning(labeling)  # as the CLI and batch warn
        if hurried:
            self.report({"WARNING"}, f"{request.take_name}: {hurried}")
        return {"FINISHED"}

    @staticmethod
    def _dropped_message(coll, request) -> str:
        from ..blender.review import first_frame, trajectory_names
        from ..core.review import describe

        names, first = trajectory_names(coll), first_frame(coll)
        old = request.dropped_names
        said = "; ".join(describe(c, old, names, first) for c in request.dropped)
        n = len(request.dropped)
        lacks = f"{request.layout.name} lacks"
        if request.hands_changed:
            hands = "two hands" if request.hand_options.get("hands") == 2 else "one hand"
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

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS":
            job.cancel()
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if not job.done:
            request = self._pending
            context.workspace.status_text_set(f"Labeling {request.take_name}: {request.stage or job.message}, "
                                              f"{request.done * 100:.0f} % done ({job.elapsed:.1f} s) - Esc to cancel")
            context.window_manager.progress_update(int(request.done * 100))
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
    from_panel = True

    def apply(self, context, coll, state) -> str:
        return _resolve(context, coll)


def _label_items(self, context):
    from ..blender.review import load_state

    coll = reviewed_take(context)
    names = load_state(coll).labeling.names if coll is not None else []
    items = [(str(i), name, f"Label {name}") for i, name in enumerate(names)]
    _label_items.cache = items  # Blender keeps no reference to dynamic enum strings
    return items


def _select_only(context, obj) -> None:
    """Make ``obj`` the only selected object and the active one (where it is in the view layer)."""
    if obj is None or obj.name not in context.view_layer.objects:
        return
    for other in context.selected_objects:
        other.select_set(False)
    obj.select_set(True)
    context.view_layer.objects.active = obj


class MOCAPAL_OT_assign_label(_ReviewOperator, bpy.types.Operator):
    """Give the active marker's trajectory a label from the current frame to the end of its segment
    (a label taken from another trajectory leaves that one unlabeled); the selection follows the
    trajectory to its new label"""

    bl_idname = "mocap_autolabel.assign_label"
    bl_label = "Assign Label"
    bl_property = "label"

    label: EnumProperty(name="Label", items=_label_items)

    def invoke(self, context, event):
        context.window_manager.invoke_search_popup(self)
        return {"RUNNING_MODAL"}

    def apply(self, context, coll, state) -> str:
        from ..blender.review import labeled_object, sample_index, trajectory_names

        frame = context.scene.frame_current
        slot = self._targets(context, coll, state)[0]
        index = sample_index(coll, frame)
        who = _shown_as(state.labeling, slot, index, trajectory_names(coll))
        c = state.review.assign(state.labeling, slot, index, int(self.label))
        message = f"{who} labeled {state.labeling.names[c.label]} from frame {frame}: " + \
            self._edit(context, coll, state, [c])
        _select_only(context, labeled_object(coll, c.label))  # the trajectory now shows under its new label
        return message


class MOCAPAL_OT_swap_labels(_ReviewOperator, bpy.types.Operator):
    """Swap the labels of the two selected markers from the current frame on"""

    bl_idname = "mocap_autolabel.swap_labels"
    bl_label = "Swap Labels"

    def apply(self, context, coll, state) -> str:
        from ..blender.review import sample_index, take_collection

        objs = [o for o in context.selected_objects if "mocap_label" in o and take_collection(o) == coll]
        if len(objs) != 2:
            raise ValueError(f"select exactly two labeled markers to swap ({len(objs)} selected)")
        a, b = (int(o["mocap_label"]) for o in objs)
        frame = context.scene.frame_current
        index = sample_index(coll, frame)
        per = state.labeling.per_sample()
        if not (0 <= index < state.labeling.n_frames) or not ((per[index] == a).any() or (per[index] == b).any()):
            raise ValueError(f"neither {objs[0].name} nor {objs[1].name} has a sample at frame {frame}")
        made = state.review.swap(state.labeling, a, b, index)
        names = state.labeling.names
        return f"swapped {names[a]} and {names[b]} from frame {frame}: " + self._edit(context, coll, state, made)


class MOCAPAL_OT_unlabel(_ReviewOperator, bpy.types.Operator):
    """Mark the selected markers' trajectories as ghosts (unlabeled) from the current frame to the end of
    their segments"""

    bl_idname = "mocap_autolabel.unlabel"
    bl_label = "Unlabel"

    def apply(self, context, coll, state) -> str:
        return self._each_selected(context, coll, state, state.review.unlabel,
                                   f"unlabeled from frame {context.scene.frame_current}")


class MOCAPAL_OT_lock(_ReviewOperator, bpy.types.Operator):
    """Lock the selected markers' segments under the current frame as they are: a re-solve keeps them"""

    bl_idname = "mocap_autolabel.lock"
    bl_label = "Lock"

    def apply(self, context, coll, state) -> str:
        return self._each_selected(context, coll, state, state.review.lock,
                                   f"locked on the segment under frame {context.scene.frame_current}")


class MOCAPAL_OT_unlock(_ReviewOperator, bpy.types.Operator):
    """Delete the corrections (locks, assigned labels, unlabels) of the selected markers under the current
    frame, and label the take again without them"""

    bl_idname = "mocap_autolabel.unlock"
    bl_label = "Unlock"
    resolves = True

    def apply(self, context, coll, state) -> str:
        from ..blender.review import first_frame, sample_index, trajectory_names
        from ..core.review import describe, plural

        frame = context.scene.frame_current
        index = sample_index(coll, frame)
        gone = []
        for slot in self._targets(context, coll, state, True):
            gone += state.review.remove_at(slot, index)
        if not gone:
            who = ", ".join(o.name for o in self._picked(context, coll, True))
            raise ValueError(f"{who}: no correction at frame {frame} to unlock")
        names, first = trajectory_names(coll), first_frame(coll)
        said = "; ".join(describe(c, state.labeling.names, names, first) for c in gone)
        return f"unlocked {plural(len(gone), 'correction')} ({said}); " + _resolve(context, coll, state.review)


class MOCAPAL_OT_delete_correction(_ReviewOperator, bpy.types.Operator):
    """Delete one correction of the take (the one chosen in the Corrections list) and label the take again
    without it"""

    bl_idname = "mocap_autolabel.delete_correction"
    bl_label = "Delete Correction"
    resolves = True
    from_panel = True

    index: IntProperty(name="Correction", default=-1, min=-1, options={"SKIP_SAVE"},
                       description="Place in the Corrections list (default: the list's active row)")

    def apply(self, context, coll, state) -> str:
        from ..blender.review import first_frame, trajectory_names
        from ..core.review import describe

        settings = context.scene.mocap_autolabel
        index = self.index if self.index >= 0 else settings.corrections_index
        n = len(state.review.constraints)
        if not 0 <= index < n + len(state.review.splits):
            raise ValueError("no correction chosen: click one in the Corrections list")
        names, first = trajectory_names(coll), first_frame(coll)
        if index < n:
            said = describe(state.review.remove(index), state.labeling.names, names, first)
        else:
            slot, frame = state.review.splits.pop(index - n)
            said = f"split {names[slot]} at frame {frame + first}"
        return f"deleted the correction {said}; " + _resolve(context, coll, state.review)


class MOCAPAL_OT_split(_ReviewOperator, bpy.types.Operator):
    """Cut the active marker's trajectory at the current frame: the two parts are labeled separately"""

    bl_idname = "mocap_autolabel.split"
    bl_label = "Split Trajectory"

    def apply(self, context, coll, state) -> str:
        from ..blender.review import edit, sample_index, trajectory_names
        from ..core.review import apply_split

        frame = context.scene.frame_current
        slot = self._targets(context, coll, state)[0]
        index = sample_index(coll, frame)
        lab = state.labeling
        who = _shown_as(lab, slot, index, trajectory_names(coll))
        if ((lab.slot == slot) & (lab.start == index)).any():
            raise ValueError(f"{who}: a new segment already starts at frame {frame}; nothing to split")
        state.review.split(lab, slot, index)
        edit(context.scene, coll, state, apply_split(state.labeling, slot, index))
        return f"split {who} at frame {frame}"


class MOCAPAL_OT_next_uncertain(bpy.types.Operator):
    """Jump to the next (or previous) uncertain segment in time order and select its marker; segments that
    start on one frame are visited one after the other"""

    bl_idname = "mocap_autolabel.next_uncertain"
    bl_label = "Next Uncertain"
    bl_options = {"REGISTER", "UNDO"}

    previous: BoolProperty(name="Previous", default=False, options={"SKIP_SAVE"})

    @classmethod
    def poll(cls, context):
        return _present(cls, reviewed_panel_take(context), _not_a_take(context) or "Label a take first")

    def execute(self, context):
        from ..blender.review import first_frame, load_state, sample_index
        from ..core.review import walk_uncertain

        coll = reviewed_panel_take(context)
        lab = load_state(coll).labeling
        settings = context.scene.mocap_autolabel
        first = first_frame(coll)
        now = sample_index(coll, context.scene.frame_current)
        # The walk stands on the segment it went to last, as long as the frame is still its start.
        current = (settings.walk_frame - first, settings.walk_slot) if settings.walk_slot >= 0 else None
        seg = walk_uncertain(lab, settings.sure, now, current, self.previous)
        if seg is None:
            self.report({"INFO"}, f"No uncertain segment {'before' if self.previous else 'after'} this one")
            return {"CANCELLED"}
        _show_segment(context, coll, lab, seg)
        self.report({"INFO"}, _segment_text(coll, lab, seg))
        return {"FINISHED"}


def _segment_text(coll, lab, seg: int) -> str:
    from ..blender.review import first_frame, trajectory_names

    first = first_frame(coll)
    name = lab.names[lab.label[seg]] if lab.label[seg] >= 0 else "unlabeled"
    return (f"{name} ({trajectory_names(coll)[lab.slot[seg]]}), frames {lab.start[seg] + first}-"
            f"{lab.stop[seg] - 1 + first}, {lab.confidence[seg] * 100:.1f} % confident")


def _show_segment(context, coll, lab, seg: int) -> None:
    from ..blender.review import first_frame, object_for

    settings = context.scene.mocap_autolabel
    frame = int(lab.start[seg]) + first_frame(coll)
    context.scene.frame_set(frame)
    settings.walk_slot, settings.walk_frame = int(lab.slot[seg]), frame
    _select_only(context, object_for(coll, lab, seg))


class MOCAPAL_OT_jump_to_segment(bpy.types.Operator):
    """Go to an uncertain segment of the list: set the frame to its start and select its marker"""

    bl_idname = "mocap_autolabel.jump_to_segment"
    bl_label = "Jump to Segment"
    bl_options = {"REGISTER", "UNDO", "INTERNAL"}

    index: IntProperty(name="List Index", default=0, min=0)

    @classmethod
    def poll(cls, context):
        return reviewed_panel_take(context) is not None

    def execute(self, context):
        import numpy as np

        from ..blender.review import first_frame, load_state

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
        return reviewed_panel_take(context) is not None

    def invoke(self, context, event):
        coll = reviewed_panel_take(context)
        if not self.filepath and coll is not None:
            src = coll.get("mocap_source") or coll.name
            self.filepath = os.path.splitext(bpy.path.abspath(src) if src else coll.name)[0] + "_labeled.c3d"
        return ExportHelper.invoke(self, context, event)

    def execute(self, context):
        from ..blender.export import export_labeled_c3d
        from ..core.errors import MocapInputError

        coll = reviewed_panel_take(context)
        path = bpy.path.abspath(self.filepath)
        try:
            export_labeled_c3d(coll, path)  # in the take's own frames and units
        except (MocapInputError, OSError, ValueError) as exc:
            self.report({"ERROR"}, f"{path}: {exc}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Wrote {path}")
        return {"FINISHED"}


classes = (MOCAPAL_OT_label, MOCAPAL_OT_resolve, MOCAPAL_OT_assign_label, MOCAPAL_OT_swap_labels,
           MOCAPAL_OT_unlabel, MOCAPAL_OT_lock, MOCAPAL_OT_unlock, MOCAPAL_OT_delete_correction, MOCAPAL_OT_split,
           MOCAPAL_OT_next_uncertain, MOCAPAL_OT_jump_to_segment, MOCAPAL_OT_export_labeled)
