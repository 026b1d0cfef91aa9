"""Fill Gaps and Clear Fill: the selected labeled markers' gaps (or every marker's), one undo step each."""

from __future__ import annotations

import bpy
from bpy.props import EnumProperty, FloatProperty

from .common import _labeled_take_present, reviewed_panel_take
from .modal import JobModal, in_background, start_modal

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
        return _labeled_take_present(cls, context)


class MOCAPAL_OT_fill_gaps(JobModal, _FillOperator, bpy.types.Operator):
    """Fill the gaps of the selected labeled markers (all labeled markers when none is selected): the
    filled keys get the Generated keyframe type, and the marker shows in the gap"""

    bl_idname = "mocap_autolabel.fill_gaps"
    bl_label = "Fill Gaps"

    method: EnumProperty(name="Method", items=_METHODS, default="auto")
    max_gap: FloatProperty(name="Max Gap", description="Longer gaps are left open (seconds)", default=1.0,
                           min=0.01, soft_max=5.0, unit="TIME_ABSOLUTE")

    def execute(self, context):
        from ..blender.fill import fill_scene

        coll = reviewed_panel_take(context)
        self._selected = _chosen_labels(context, coll)
        try:
            report = fill_scene(coll, **self.as_keywords(), labels=self._selected)
        except Exception as exc:
            return self._job_failed(exc)
        return self._said(report)

    def invoke(self, context, event):
        """From the panel: the fill works on a worker thread while Blender stays responsive, the status
        bar shows its stage, Esc cancels and leaves the scene as it was; from a script, at once."""
        from ..blender.fill import prepare_fill
        from ..core.jobs import Job

        if not in_background(context):
            return self.execute(context)
        coll = reviewed_panel_take(context)
        self._selected = _chosen_labels(context, coll)
        try:
            self._pending = prepare_fill(coll, **self.as_keywords(), labels=self._selected)
        except Exception as exc:
            return self._job_failed(exc)
        return start_modal(self, context, Job(self._pending.run))

    def _progress(self, job) -> tuple[str, float]:
        request = self._pending
        return f"Filling the gaps of {request.take_name}: {request.stage}", request.share

    def _job_failed(self, exc: BaseException) -> set[str]:
        from ..core.errors import MocapInputError

        if isinstance(exc, MocapInputError):
            self.report({"ERROR"}, str(exc))
        else:  # never let an unexpected failure take Blender down
            self.report({"ERROR"}, f"filling gaps failed ({type(exc).__name__}: {exc})")
        return {"CANCELLED"}

    def _job_done(self, context, result) -> set[str]:
        from ..blender.fill import finish_fill

        coll = bpy.data.collections.get(self._pending.take_name)
        if coll is None:
            self.report({"ERROR"}, f"the take {self._pending.take_name!r} was removed while its gaps were filled")
            return {"CANCELLED"}
        try:
            report = finish_fill(coll, self._pending, result)
        except Exception as exc:
            return self._job_failed(exc)
        return self._said(report)

    def _said(self, report: dict) -> set[str]:
        """Report what was filled (and what was solved again of the hand) in one line."""
        methods = ", ".join(f"{n} {k}" for k, n in sorted(report["methods"].items())) or "none"
        reasons: dict[str, int] = {}
        for gap in report["gap_list"]:
            if gap["method"] is None:
                key = gap["open"].split(" (")[0]
                reasons[key] = reasons.get(key, 0) + 1
        left = "; ".join(f"{n} {why}" for why, n in sorted(reasons.items()))
        n = None if self._selected is None else len(self._selected)
        which = "all labeled markers" if n is None else f"{n} selected marker{'s' * (n > 1)}"
        solved = sum(f["solved_frames"] for f in report.get("hand_solve", {}).values())
        self.report({"INFO"}, f"Filled {report['filled']} of {report['gaps']} gaps of {which} ({methods})"
                              + (f"; left open: {left}" if left else "")
                              + (f"; the hand solved again on {solved} changed frames" if solved else ""))
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
