"""File > Import entry and drag-and-drop of take files onto the 3D viewport."""

from __future__ import annotations

import bpy


def menu_import(self, context):
    self.layout.operator("mocap_autolabel.import_markers", text="C3D Markers (.c3d, .trc, .tsv)")


class MOCAPAL_FH_markers(bpy.types.FileHandler):
    bl_idname = "MOCAPAL_FH_markers"
    bl_label = "C3D markers"
    bl_import_operator = "mocap_autolabel.import_markers"
    bl_file_extensions = ".c3d;.trc;.tsv"

    @classmethod
    def poll_drop(cls, context):
        return context.area is not None and context.area.type == "VIEW_3D"
