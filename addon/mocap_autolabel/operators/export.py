"""Export Labeled C3D: the reviewed take in the panel's Take field, in its own frames and units."""

from __future__ import annotations

import bpy
from bpy.props import StringProperty
from bpy_extras.io_utils import ExportHelper

from .common import beside_source, reviewed_panel_take


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
            self.filepath = beside_source(coll, "_labeled.c3d")
        return ExportHelper.invoke(self, context, event)

    def execute(self, context):
        from ..blender.export import export_labeled_c3d
        from ..core.errors import MocapInputError

        coll = reviewed_panel_take(context)
        path = bpy.path.abspath(self.filepath)
        try:
            export_labeled_c3d(coll, path)  # in the take's own frames and units
        except (MocapInputError, OSError, ValueError) as exc:
            self.report({"ERROR"}, _one_line(exc, path))
            return {"CANCELLED"}
        self.report({"INFO"}, f"Wrote {path}")
        return {"FINISHED"}


def _one_line(exc: Exception, path: str) -> str:
    """The report of a failed export: the file it names and what is wrong, once (an input error names
    its file itself; an OSError's text repeats its errno and file)."""
    from ..core.errors import MocapInputError

    if isinstance(exc, MocapInputError):
        return str(exc)
    if isinstance(exc, OSError) and exc.strerror:
        return f"{exc.filename or path}: {exc.strerror}"
    return f"{path}: {exc}"


classes = (MOCAPAL_OT_export_labeled,)
