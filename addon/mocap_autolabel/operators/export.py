"""Export Labeled C3D: the reviewed take in the panel's Take field, in its own frames and units; Export
Hand: the take's solved rig(s) alone, as FBX (one animation stack) or BVH."""

from __future__ import annotations

import os

import bpy
from bpy.props import EnumProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from .common import _labeled_take_present, _present, beside_source, panel_take, reviewed_panel_take


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
        return _labeled_take_present(cls, context)

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


_HAND_FORMATS = [("FBX", "FBX", "Autodesk FBX: the rig and one animation stack, in the engine's axes and units"),
                 ("BVH", "BVH", "Biovision hierarchy: the rig's joints and their rotations (Blender's Z up)")]
_BONE_NAMES = [("ours", "Ours", "Our rig's bone names (palm, index_prox ...); Y up, metres"),
               ("ue5", "Unreal (UE5)", "Unreal Engine 5 mannequin names (hand_l, index_01_l ...); Z up, centimetres"),
               ("unity", "Unity", "Unity humanoid names (LeftHand, LeftIndexProximal ...); Y up, metres"),
               ("mixamo", "Mixamo", "Mixamo names (mixamorig:LeftHand, mixamorig:LeftHandIndex1 ...); Y up, "
                                    "metres"),
               ("rigify", "Rigify", "Rigify names (hand.L, f_index.01.L ...); Y up, metres")]
_EXTENSIONS = {"FBX": ".fbx", "BVH": ".bvh"}


class MOCAPAL_OT_export_hand(bpy.types.Operator, ExportHelper):
    """Export the solved hand rig(s) of the take alone, with their animation: FBX (one animation stack) or
    BVH; a take of two hands writes one file per hand (name_left, name_right)"""

    bl_idname = "mocap_autolabel.export_hand"
    bl_label = "Export Hand"
    bl_options = {"REGISTER"}  # the scene is left as it was: nothing to undo

    filename_ext = ".fbx"
    filter_glob: StringProperty(default="*.fbx;*.bvh", options={"HIDDEN"})
    file_format: EnumProperty(name="Format", items=_HAND_FORMATS, default="FBX")
    bone_names: EnumProperty(name="Bone Names", items=_BONE_NAMES, default="ours",
                             description="The bones' names in the file, and (FBX) the engine's axes and units")

    @classmethod
    def poll(cls, context):
        from ..blender.export import has_hand_rigs

        found = has_hand_rigs(panel_take(context), context.scene) or None
        return _present(cls, found, "No solved hand: run Solve Hand on the labeled take first")

    def check(self, context):
        ext = _EXTENSIONS[self.file_format]
        stem, old = os.path.splitext(self.filepath)
        if not os.path.basename(self.filepath) or old.lower() == ext:
            return False
        self.filepath = (stem if old.lower() in _EXTENSIONS.values() else self.filepath) + ext
        return True

    def invoke(self, context, event):
        from ..blender.export import default_hand_path

        if not self.filepath:
            self.filepath = default_hand_path(panel_take(context), context.scene, _EXTENSIONS[self.file_format])
        return ExportHelper.invoke(self, context, event)

    def execute(self, context):
        from ..blender.export import export_hands
        from ..core.errors import MocapInputError

        keywords = self.as_keywords(ignore=("filter_glob", "check_existing"))
        keywords["filepath"] = bpy.path.abspath(self.filepath)
        try:
            paths = export_hands(panel_take(context), context.scene, **keywords)
        except (MocapInputError, OSError, ValueError) as exc:
            self.report({"ERROR"}, _one_line(exc, keywords["filepath"]))
            return {"CANCELLED"}
        self.report({"INFO"}, f"Wrote {', '.join(paths)}")
        return {"FINISHED"}


classes = (MOCAPAL_OT_export_labeled, MOCAPAL_OT_export_hand)
