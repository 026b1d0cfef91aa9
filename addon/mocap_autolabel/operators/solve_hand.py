"""Solve Hand: fit the calibrated rig to the labeled take in the scene (or a labeled file)."""

from __future__ import annotations

import os

import bpy
from bpy.props import EnumProperty, FloatProperty, StringProperty

from ..blender.properties import LAYOUT_DEFAULT, _layouts
from .review import context_take, reviewed_take


class MOCAPAL_OT_solve_hand(bpy.types.Operator):
    """Fit the rigged hand to a labeled take: calibrate the performer (or reuse a calibration), solve every
    frame, and add the keyed armature with its markers to the scene"""

    bl_idname = "mocap_autolabel.solve_hand"
    bl_label = "Solve Hand"
    bl_options = {"REGISTER", "UNDO"}

    filepath: StringProperty(name="Labeled Take", subtype="FILE_PATH",
                             description="Labeled take to solve (default: the reviewed labels of the active "
                                         "marker's take, or its file when it was imported labeled)")
    layout: EnumProperty(name="Layout", items=_layouts, default=LAYOUT_DEFAULT,
                         description="Marker layout of a labeled file (a reviewed take keeps the layout it was "
                                     "labeled with)")
    layout_file: StringProperty(name="Layout File", subtype="FILE_PATH",
                                description="A layout .toml instead of a built-in layout")
    calibration: StringProperty(name="Calibration", subtype="FILE_PATH",
                                description="Reuse this performer calibration (.json); empty: calibrate on the take")
    save_calibration: StringProperty(name="Save Calibration", subtype="FILE_PATH",
                                     description="Write the calibration used to this .json file")
    smooth_hz: FloatProperty(name="Smoothing (Hz)", default=10.0, min=0.0, soft_max=30.0,
                             description="Low-pass cut-off of the pose track; 0 keeps every frame's own fit")

    def _labeled(self, context):
        """``(take, layout, name)`` to solve, or None: the file given; else the reviewed take of the
        active marker (or of the panel) with its current labels, corrections included, and the layout
        it was labeled with; else the file of the active marker's take (an imported labeled file)."""
        from ..blender.review import current_take, load_state, state_layout
        from ..core.labeling import labeled_take
        from ..core.layout import load_layout
        from ..core.take import read_take

        def chosen_layout():
            return load_layout(bpy.path.abspath(self.layout_file) if self.layout_file else self.layout)

        if self.filepath:
            path = bpy.path.abspath(self.filepath)
            return read_take(path), chosen_layout(), path
        coll = reviewed_take(context)
        if coll is not None:
            state = load_state(coll)
            return labeled_take(current_take(coll), state.labeling), state_layout(state), coll.name
        coll = context_take(context)
        if coll is not None and coll.get("mocap_source"):
            return read_take(coll["mocap_source"]), chosen_layout(), coll["mocap_source"]
        return None

    def invoke(self, context, event):
        return context.window_manager.invoke_props_dialog(self)

    def execute(self, context):
        from ..blender.armature import build_solved_hand, solved_hand_collection
        from ..core.errors import MocapInputError
        from ..core.hand.calibrate import Calibration
        from ..core.pipeline import solve_take

        source = self.filepath or "the take"
        try:
            found = self._labeled(context)
            if found is None:
                self.report({"ERROR"}, "No labeled take: label the imported take, select one of its markers, "
                                       "or give a labeled file")
                return {"CANCELLED"}
            take, layout, source = found
            calibration = Calibration.load(bpy.path.abspath(self.calibration)) if self.calibration else None
            solved = solve_take(take, layout, calibration=calibration, smooth_hz=self.smooth_hz)
            if self.save_calibration:
                solved.calibration.save(bpy.path.abspath(self.save_calibration))
        except MocapInputError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except Exception as exc:  # never let a bad file take Blender down
            self.report({"ERROR"}, f"{source}: unexpected error while solving ({type(exc).__name__}: {exc})")
            return {"CANCELLED"}
        collection = solved_hand_collection(context.scene, source,
                                            f"{os.path.splitext(os.path.basename(source))[0]} hand")
        arm = build_solved_hand(solved, collection)
        report = solved.report()
        self.report({"INFO"}, f"Solved {report['solved_frames']} of {report['frames']} frames: marker RMS "
                              f"{report['marker_rms_mm']:.2f} mm, {report['frames_over_gate']} frames over the "
                              f"{report['gate_mm']:g} mm gate ({arm.name})")
        return {"FINISHED"}
