"""Corrections of a labeled take: Assign Label, Swap Labels, Unlabel, Lock, Unlock, Split Trajectory
and Delete Correction, and Re-solve Labels, which labels the take again honouring them.

The corrections act on the take of the selected markers (Re-solve and Delete Correction on the
panel's take). Each calls the core (``core.review``) and the scene layer (``blender.review``), and
is one undo step. Corrections are recorded as constraints on the take, so a re-solve keeps them;
with the panel's Re-solve After Each Edit, every correction is followed by a re-solve.
"""

from __future__ import annotations

import bpy
from bpy.props import EnumProperty, IntProperty

from .common import _not_a_take, _present, _select_only, reviewed_panel_take, reviewed_take


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
        from ..blender.takes import load_state
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
        from ..blender.takes import first_frame, trajectory_names
        from ..core.review import describe

        names, first = trajectory_names(coll), first_frame(coll)
        said = "; ".join(describe(c, state.labeling.names, names, first) for c in self._overridden)
        return f"this overrides your earlier {'correction' if len(self._overridden) == 1 else 'corrections'} ({said})"

    def apply(self, context, coll, state) -> str:
        raise NotImplementedError

    # What the reviewer points at: the active (or selected) marker at the current frame.
    def _picked(self, context, coll, selected: bool) -> list:
        """The take's markers the reviewer points at (the active one first), or an error naming why none."""
        from ..blender.takes import take_collection

        objs = list(context.selected_objects) if selected else []
        if context.active_object is not None and context.active_object not in objs:
            objs.insert(0, context.active_object)
        objs = [o for o in objs if take_collection(o) == coll
                and any(k in o for k in ("mocap_label", "mocap_null", "mocap_slot"))]
        if not objs:
            raise ValueError("no marker selected: select a marker of the take (in the viewport or the Outliner)")
        return objs

    def _targets(self, context, coll, state, selected: bool = False) -> list[int]:
        from ..blender.markers import slot_of
        from ..blender.takes import sample_index

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
        from ..blender.takes import sample_index, trajectory_names

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


class MOCAPAL_OT_resolve(_ReviewOperator, bpy.types.Operator):
    """Label the take again honouring every correction; only markers whose decision changes are rewritten"""

    bl_idname = "mocap_autolabel.resolve"
    bl_label = "Re-solve Labels"
    resolves = True
    from_panel = True

    def apply(self, context, coll, state) -> str:
        return _resolve(context, coll)


def _label_items(self, context):
    from ..blender.takes import load_state

    coll = reviewed_take(context)
    names = load_state(coll).labeling.names if coll is not None else []
    items = [(str(i), name, f"Label {name}") for i, name in enumerate(names)]
    _label_items.cache = items  # Blender keeps no reference to dynamic enum strings
    return items


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
        from ..blender.markers import labeled_object
        from ..blender.takes import sample_index, trajectory_names

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
        from ..blender.takes import sample_index, take_collection

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
        from ..blender.takes import first_frame, sample_index, trajectory_names
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
        from ..blender.takes import first_frame, trajectory_names
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
        from ..blender.review import edit
        from ..blender.takes import sample_index, trajectory_names
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


classes = (MOCAPAL_OT_resolve, MOCAPAL_OT_assign_label, MOCAPAL_OT_swap_labels, MOCAPAL_OT_unlabel, MOCAPAL_OT_lock,
           MOCAPAL_OT_unlock, MOCAPAL_OT_delete_correction, MOCAPAL_OT_split)
