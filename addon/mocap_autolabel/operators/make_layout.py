"""Make Layout: a layout TOML fitted from the labeled take in the panel's Take field (each marker's bone and
place on the template hand), then put in the Layout File field, so that the next takes label with it."""

from __future__ import annotations

import bpy
from bpy.props import EnumProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from .common import beside_source, panel_take


class MOCAPAL_OT_make_layout(bpy.types.Operator, ExportHelper):
    """Fit a marker layout to the labeled markers of the take (a take you labeled, or a file labeled
    elsewhere) and use it: no TOML to write, no training"""

    bl_idname = "mocap_autolabel.make_layout"
    bl_label = "Make Layout"
    bl_options = {"REGISTER"}

    filename_ext = ".toml"
    filter_glob: StringProperty(default="*.toml", options={"HIDDEN"})
    side: EnumProperty(name="Hand", items=[("ANY", "All Labeled Points", "Every labeled point of the take, names "
                                                                          "as they are (one hand)"),
                                           ("left", "Left", "The points named for the left hand (L_ThumbTip)"),
                                           ("right", "Right", "The points named for the right hand (R_ThumbTip)")],
                       default="ANY")
    points: StringProperty(name="Points", default="",
                           description="Only the points whose names match these wildcards, comma-separated "
                                       "(e.g. to leave body markers out); empty: all")

    @classmethod
    def poll(cls, context):
        if panel_take(context) is None:
            cls.poll_message_set("Import a labeled take (or label one) first")
            return False
        return True

    def invoke(self, context, event):
        coll = panel_take(context)
        if not self.filepath and coll is not None:
            self.filepath = beside_source(coll, "_layout.toml")
        return ExportHelper.invoke(self, context, event)

    def execute(self, context):
        from ..blender.make_layout import make_layout
        from ..core.errors import MocapInputError

        path = bpy.path.abspath(self.filepath)
        wm = context.window_manager
        wm.progress_begin(0, 100)
        try:
            fit = make_layout(context.scene, panel_take(context), path, side=None if self.side == "ANY" else self.side,
                              points=[p.strip() for p in self.points.split(",") if p.strip()] or None,
                              progress=lambda share: wm.progress_update(int(100 * share)))
        except (MocapInputError, OSError, ValueError) as exc:
            self.report({"ERROR"}, f"{path}: {exc}")
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        self.report({"INFO"}, f"Wrote {path}: {len(fit.layout)} markers, {1000 * fit.rms:.1f} mm RMS; "
                              "it is now the Layout File")
        doubt = fit.doubt()
        if doubt:
            self.report({"WARNING"}, f"{path}: {doubt}")
        return {"FINISHED"}


classes = (MOCAPAL_OT_make_layout,)
