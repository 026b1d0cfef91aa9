"""Solve Hand: fit the calibrated rig to the labeled take in the scene (or a labeled file)."""

from __future__ import annotations

import os

import bpy
from bpy.props import EnumProperty, FloatProperty, StringProperty


def _layouts(_self, _context):
    from ..core.layout import builtin_layouts

    return [(name, name, f"Built-in layout {name}") for name in builtin_layouts()]


class MOCAPAL_OT_solve_hand(bpy.types.Operator):
    """Fit the rigged hand to a labeled take: calibrate the performer (or reuse a calibration), solve every
    frame, and add the keyed armature with its markers to the scene"""

    bl_idname = "mocap_autolabel.solve_hand"
    bl_label = "Solve Hand"
    bl_options = {"REGISTER", "UNDO"}

    filepath: StringProperty(name="Labeled Take", subtype="FILE_PATH",
                             description="Labeled take to solve (default: the file of the active marker's take)")
    layout: EnumProperty(name="Layout", items=_layouts, description="Marker layout of the take")
    layout_file: StringProperty(name="Layout File", subtype="FILE_PATH",
                                description="A layout .toml instead of a built-in layout")
    calibration: StringProperty(name="Calibration", subtype="FILE_PATH",
                                description="Reuse this performer calibration (.json); empty: calibrate on the take")
    save_calibration: StringProperty(name="Save Calibration", subtype="FILE_PATH",
                                     description="Write the calibration used to this .json file")
    smooth_hz: FloatProperty(name="Smoothing (Hz)", default=10.0, min=0.0, soft_max=30.0,
                             description="Low-pass cut-off of the pose track; 0 keeps every frame's own fit")

    def _source(self, context) -> str:
        if self.filepath:
            return bpy.path.abspath(self.filepath)
        obj = context.active_object
        for coll in (obj.users_collection if obj else ()):
            if coll.get("mocap_source"):
                return coll["mocap_source"]
        return ""

    def invoke(self, context, event):
        return context.window_manager.invoke_props_dialog(self)

    def execute(self, context):
        from ..blender.armature import build_solved_hand
        from ..core.errors import MocapInputError
        from ..core.hand.calibrate import Calibration
        from ..core.layout import load_layout
        from ..core.pipeline import solve_take
        from ..core.take import read_take

        source = self._source(context)
        if not source:
            self.report({"ERROR"}, "No labeled take: give a file, or select a marker of an imported take")
            return {"CANCELLED"}
        try:
            layout = load_layout(bpy.path.abspath(self.layout_file) if self.layout_file else self.layout)
            calibration = Calibration.load(bpy.path.abspath(self.calibration)) if self.calibration else None
            solved = solve_take(read_take(source), layout, calibration=calibration, smooth_hz=self.smooth_hz)
            if self.save_calibration:
                solved.calibration.save(bpy.path.abspath(self.save_calibration))
        except MocapInputError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except Exception as exc:  # never let a bad file take Blender down
            self.report({"ERROR"}, f"{source}: unexpected error while solving ({type(exc).__name__}: {exc})")
            return {"CANCELLED"}
        collection = bpy.data.collections.new(f"{os.path.splitext(os.path.basename(source))[0]} hand")
        context.scene.collection.children.link(collection)
        arm = build_solved_hand(solved, collection)
        report = solved.report()
        self.report({"INFO"}, f"Solved {report['solved_frames']} of {report['frames']} frames: marker RMS "
                              f"{report['marker_rms_mm']:.2f} mm, {report['frames_over_gate']} frames over the "
                              f"{report['gate_mm']:g} mm gate ({arm.name})")
        return {"FINISHED"}
