"""File > Import entry, the Mocap menu (3D View Object menu and Dope Sheet Key menu, so F3 finds
every operator), and drag-and-drop of take files onto the 3D viewport."""

from __future__ import annotations

import bpy


def menu_import(self, context):
    self.layout.operator("mocap_autolabel.import_markers", text="C3D Markers (.c3d, .trc, .tsv)")


class MOCAPAL_MT_mocap(bpy.types.Menu):
    bl_idname = "MOCAPAL_MT_mocap"
    bl_label = "Mocap Labels"

    def draw(self, context):
        layout = self.layout
        layout.operator("mocap_autolabel.label", icon="SORTALPHA")
        layout.operator("mocap_autolabel.resolve", icon="FILE_REFRESH")
        layout.separator()
        layout.operator("mocap_autolabel.next_uncertain", text="Previous Uncertain", icon="TRIA_LEFT").previous = True
        layout.operator("mocap_autolabel.next_uncertain", text="Next Uncertain", icon="TRIA_RIGHT").previous = False
        layout.operator("mocap_autolabel.jump_to_worst", icon="ERROR")
        layout.separator()
        layout.operator("mocap_autolabel.assign_label")
        layout.operator("mocap_autolabel.swap_labels")
        layout.operator("mocap_autolabel.unlabel")
        layout.operator("mocap_autolabel.split")
        layout.operator("mocap_autolabel.lock")
        layout.separator()
        layout.operator("mocap_autolabel.export_labeled", icon="EXPORT")
        layout.operator("mocap_autolabel.solve_hand", icon="VIEW_PAN")
        layout.operator("mocap_autolabel.export_hand", icon="EXPORT")


def menu_mocap(self, context):
    self.layout.menu(MOCAPAL_MT_mocap.bl_idname)


#: Menus the Mocap menu is appended to.
MENU_PARENTS = ("VIEW3D_MT_object", "DOPESHEET_MT_key")


class MOCAPAL_FH_markers(bpy.types.FileHandler):
    bl_idname = "MOCAPAL_FH_markers"
    bl_label = "C3D markers"
    bl_import_operator = "mocap_autolabel.import_markers"
    bl_file_extensions = ".c3d;.trc;.tsv"

    @classmethod
    def poll_drop(cls, context):
        return context.area is not None and context.area.type == "VIEW_3D"
