"""Fill Gaps and Clear Fill: the selected labeled markers' gaps (or every marker's), one undo step each."""

from __future__ import annotations

import bpy
from bpy.props import EnumProperty, FloatProperty

from .common import _not_a_take, _present, reviewed_panel_take

_METHODS = [
    ("auto", "Auto", "Per gap, the method with the lowest expected error: hand (where solved), pose or spline"),
    ("hand", "Hand", "The calibrated hand fitted again without the marker, its unseen joint angles following the "
                     "others as they did near the gap; blended to meet the samples at both ends (Solve Hand first)"),
    ("pose", "Pose", "Read off the hand's other markers: a linear model of it from them, in the hand's own frame, "
                     "learned within 5 s of the gap"),
    ("rigid", "Rigid", "Carried by the markers that move rigidly with it (its rigid partners and the palm)"),
    ("pca", "PCA", "Principal components of the hand's markers (Gløersen & Federolf 2016)"),
    ("spline", "Spline", "A cubic spline through the samples on both sides (short gaps)"),
]


def _chosen_labels(context, coll) -> list[int] | None:
    """The labels of the selected labeled markers of the take, None (all) when none is selected."""
    from ..blender.review import take_collection

    labels = [int(o["mocap_label"]) for o in context.selected_objects
              if "mocap_label" in o and take_collection(o) == coll]
    return labels or None


class _FillOperator:
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        why = _not_a_take(context) or "Label a take first (Mocap sidebar tab > Label)"
        return _present(cls, reviewed_panel_take(context), why)


class MOCAPAL_OT_fill_gaps(_FillOperator, bpy.types.Operator):
    """Fill the gaps of the selected labeled markers (all labeled markers when none is selected): the
    filled keys get the Generated keyframe type, and the marker shows in the gap"""

    bl_idname = "mocap_autolabel.fill_gaps"
    bl_label = "Fill Gaps"

    method: EnumProperty(name="Method", items=_METHODS, default="auto")
    max_gap: FloatProperty(name="Max Gap", description="Longer gaps are left open (seconds)", default=1.0,
                           min=0.01, soft_max=5.0, unit="TIME_ABSOLUTE")

    def execute(self, context):
        from ..blender.fill import fill_scene
        from ..core.errors import MocapInputError

        coll = reviewed_panel_take(context)
        labels = _chosen_labels(context, coll)
        try:
            report = fill_scene(coll, self.method, self.max_gap, labels)
        except MocapInputError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        methods = ", ".join(f"{n} {k}" for k, n in sorted(report["methods"].items())) or "none"
        reasons: dict[str, int] = {}
        for gap in report["gap_list"]:
            if gap["method"] is None:
                key = gap["open"].split(" (")[0]
                reasons[key] = reasons.get(key, 0) + 1
        left = "; ".join(f"{n} {why}" for why, n in sorted(reasons.items()))
        which = "all labeled markers" if labels is None else f"{len(labels)} selected marker{'s' * (len(labels) > 1)}"
        self.report({"INFO"}, f"Filled {report['filled']} of {report['gaps']} gaps of {which} ({methods})"
                              + (f"; left open: {left}" if left else ""))
        return {"FINISHED"}


class MOCAPAL_OT_clear_fill(_FillOperator, bpy.types.Operator):
    """Remove the filled keys of the selected labeled markers (all labeled markers when none is selected)"""

    bl_idname = "mocap_autolabel.clear_fill"
    bl_label = "Clear Fill"

    def execute(self, context):
        from ..blender.fill import clear_fill

        coll = reviewed_panel_take(context)
        gone = clear_fill(coll, _chosen_labels(context, coll))
        self.report({"INFO"}, f"Cleared {gone} filled samples")
        return {"FINISHED"}


classes = (MOCAPAL_OT_fill_gaps, MOCAPAL_OT_clear_fill)
