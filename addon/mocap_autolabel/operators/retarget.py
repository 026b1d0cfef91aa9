"""Retarget to Armature: key the solved hands onto the animator's own character, and the panel's bone
map (auto-map again, save it as a preset, load one).

The character and its editable map live in the scene (``scene.mocap_autolabel.retarget``, shown by
the Retarget panel); the operator's options are its own, and the panel passes its settings in.
"""

from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, StringProperty

from ..blender.properties import RetargetOptions


def _settings(context):
    return context.scene.mocap_autolabel.retarget


class MOCAPAL_OT_retarget(RetargetOptions, bpy.types.Operator):
    """Key the solved hands of the scene onto a character's armature (its finger and hand bones, through
    the bone map), as one action on the character's NLA track "Mocap hands\""""

    bl_idname = "mocap_autolabel.retarget"
    bl_label = "Retarget to Armature"
    bl_options = {"REGISTER", "UNDO"}

    armature: StringProperty(name="Armature",
                             description="The character's armature (empty: the Retarget panel's, else the active "
                                         "armature)")
    use_panel_map: BoolProperty(name="Panel's Bone Map", default=True,
                                description="Use the Retarget panel's bone map where it was made for this armature "
                                            "(else the bones are mapped automatically)")

    def execute(self, context):
        from ..blender.retarget import character, describe, panel_bone_map, retarget_character
        from ..core.errors import MocapInputError

        keywords = self.as_keywords(ignore=("reference_frame", "use_panel_map"))
        if self.reference == "frame":
            keywords["reference"] = self.reference_frame
        try:
            arm = character(context, self.armature or None)
            keywords["armature"] = arm
            keywords["bone_map"] = panel_bone_map(context.scene, arm) if self.use_panel_map else None
            facts = retarget_character(context, **keywords)
        except MocapInputError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except Exception as exc:  # never a traceback in the user's face
            self.report({"ERROR"}, f"Retarget failed ({type(exc).__name__}: {exc})")
            return {"CANCELLED"}
        self.report({"INFO"}, describe(facts))
        return {"FINISHED"}


class MOCAPAL_OT_retarget_auto_map(bpy.types.Operator):
    """Map the character's hand and finger bones automatically again (the list's edits are lost)"""

    bl_idname = "mocap_autolabel.retarget_auto_map"
    bl_label = "Auto-Map Bones"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from ..blender.retarget import character, fill_map
        from ..core.errors import MocapInputError

        settings = _settings(context)
        try:
            arm = character(context)
            if settings.armature != arm:
                settings.armature = arm  # its update maps it
            fill_map(settings, arm)
        except MocapInputError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        mapped = sum(1 for row in settings.bone_map if row.theirs)
        self.report({"INFO"}, f"{arm.name}: {mapped} bones mapped ({settings.convention or 'no convention found'})")
        return {"FINISHED"}


class MOCAPAL_OT_retarget_save_map(bpy.types.Operator):
    """Save the Retarget panel's bone map as a preset (in your Blender config folder)"""

    bl_idname = "mocap_autolabel.retarget_save_map"
    bl_label = "Save Bone Map"

    preset: StringProperty(name="Preset Name", description="The name to save the bone map under")

    def invoke(self, context, event):
        if not self.preset:
            self.preset = context.scene.mocap_autolabel.retarget.map_armature
        return context.window_manager.invoke_props_dialog(self)

    def execute(self, context):
        from ..blender.retarget import save_preset
        from ..core.errors import MocapInputError

        try:
            path = save_preset(_settings(context), self.preset)
        except MocapInputError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except OSError as exc:
            self.report({"ERROR"}, f"Cannot save the bone map: {exc}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Saved the bone map as {path}")
        return {"FINISHED"}


_PRESET_ITEMS: list[tuple] = []  # Blender needs the callback's strings kept alive


def _preset_items(_self, _context):
    from ..blender.retarget import presets

    _PRESET_ITEMS[:] = [(name, name, f"The bone-map preset {name}") for name in presets()]
    return _PRESET_ITEMS or [("", "(no presets saved)", "")]


class MOCAPAL_OT_retarget_load_map(bpy.types.Operator):
    """Load a saved bone-map preset into the Retarget panel's list, for its armature"""

    bl_idname = "mocap_autolabel.retarget_load_map"
    bl_label = "Load Bone Map"
    bl_options = {"REGISTER", "UNDO"}
    bl_property = "preset"

    preset: EnumProperty(name="Preset", items=_preset_items)

    def invoke(self, context, event):
        context.window_manager.invoke_search_popup(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        from ..blender.retarget import character, load_preset
        from ..core.errors import MocapInputError

        settings = _settings(context)
        if not self.preset:
            self.report({"ERROR"}, "No bone-map preset saved yet: Save Bone Map first")
            return {"CANCELLED"}
        try:
            arm = character(context)
            if settings.armature != arm:
                settings.armature = arm
            lacking = load_preset(settings, arm, self.preset)
        except MocapInputError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        if lacking:
            self.report({"WARNING"}, f"Preset {self.preset}: {arm.name} has no {', '.join(lacking)} (left unmapped)")
        else:
            self.report({"INFO"}, f"Loaded the bone map {self.preset} for {arm.name}")
        return {"FINISHED"}


classes = (MOCAPAL_OT_retarget, MOCAPAL_OT_retarget_auto_map, MOCAPAL_OT_retarget_save_map,
           MOCAPAL_OT_retarget_load_map)
