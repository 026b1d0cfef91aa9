"""Solve Hand: fit the calibrated rig to the labeled take in the scene (or a labeled file).

From the panel it runs like Label Markers: the solve works on a worker thread while Blender stays
responsive, the status bar shows the stage and the share of frames done, Esc cancels and leaves
the scene as it was (nothing is built until the solve is complete). From a script it runs at once.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, StringProperty

from ..blender.properties import LAYOUT_DEFAULT, _layouts
from ..core.hands import SIDES
from .common import panel_take, reviewed_panel_take
from .modal import JobModal, in_background, start_modal


@dataclass
class SolveRequest:
    """Everything a solve needs, gathered on the main thread so that :meth:`run` touches no Blender data.

    ``take`` is in the scene's frames (``take.first_frame`` is the Blender frame of sample 0) and in
    metres; ``scale`` is the take's import Scale, which the rig gets.
    """

    take: object
    layout: object
    source: str  # the take collection's name, or the labeled file's path
    scale: float = 1.0
    calibration: object = None
    smooth_hz: float = 10.0
    share: float = 0.0  # of the work done, set as the solve goes
    naming: object = None  # the take's HandNaming (None: any built-in convention)
    cache: object = None  # the take's session cache: a calibration on the same labels is made once
    digests: dict | None = None  # per side, the frame digests of the markers solved (set by run)

    def run(self, say=None):
        """The :class:`~mocap_autolabel.core.solve.HandSolve` of a take labeled with plain names (one
        hand); for a take whose labels carry their side (two hands, ``L_ThumbTip`` ...), ``[(side,
        HandSolve)]``, each hand calibrated on its own (a given calibration serves the hand of its
        side). ``say(message)`` gets each stage (and may raise to stop, as a cancelled Job's does)."""
        from ..core.process import Outputs, process_take
        from ..core.settings import LabelSettings

        def progress(message: str, share: float) -> None:
            self.share = share
            if say is not None:
                say(message)

        cal = self.calibration
        calibrations = None if cal is None else {"": cal, cal.side: cal}
        outputs = Outputs(label=False, solve=True, calibrations=calibrations,
                          solve_options={"smooth_hz": self.smooth_hz})
        naming = None if self.naming is None else self.naming.template
        result = process_take(self.take, self.layout, LabelSettings(naming=naming), outputs, progress=progress,
                              cache=self.cache)
        from ..core.fill import solve_digests

        self.digests = solve_digests(self.take, self.layout, self.naming)
        return result.rig()


def _stage_printer():
    """Print each stage once (a headless Blender shows no status bar; the shares would be noise)."""
    said = set()

    def say(message: str) -> None:
        stage = message.split(" (")[0]
        if stage not in said:
            said.add(stage)
            print(f"mocap_autolabel: {stage}", flush=True)

    return say


class MOCAPAL_OT_solve_hand(JobModal, bpy.types.Operator):
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
    # Set by invoke (the panel's button): the dialog's OK then runs the solve in the background.
    in_background: BoolProperty(default=False, options={"HIDDEN", "SKIP_SAVE"})

    def _labeled(self, context):
        """``(take, layout, name, scale)`` to solve, or None: the file given; else the reviewed take of
        the active marker (or of the panel) with its current labels, corrections included, and the
        layout it was labeled with; else the active marker's take as imported (a labeled file). A take
        of the scene is read from its empties, so it is in the scene's frames, and the rig gets its
        import Scale."""
        from ..blender.review import current_take, load_state, state_layout
        from ..core.labeling import labeled_take
        from ..core.layout import load_layout
        from ..core.take import read_take

        def chosen_layout():
            return load_layout(bpy.path.abspath(self.layout_file) if self.layout_file else self.layout)

        if self.filepath:
            path = bpy.path.abspath(self.filepath)
            return read_take(path), chosen_layout(), path, 1.0
        coll = reviewed_panel_take(context)
        if coll is not None:
            state = load_state(coll)
            return (labeled_take(current_take(coll), state.labeling), state_layout(state), coll.name,
                    float(coll.get("mocap_scale", 1.0)))
        coll = panel_take(context)
        if coll is not None and coll.get("mocap_source"):
            return current_take(coll), chosen_layout(), coll.name, float(coll.get("mocap_scale", 1.0))
        return None

    def _request(self, context) -> SolveRequest | None:
        from ..core.hand.calibrate import Calibration

        found = self._labeled(context)
        if found is None:
            return None
        take, layout, source, scale = found
        calibration = Calibration.load(bpy.path.abspath(self.calibration)) if self.calibration else None
        from ..blender.session import session

        coll = bpy.data.collections.get(source)
        return SolveRequest(take, layout, source, scale, calibration, self.smooth_hz, naming=self._naming(context),
                            cache=session(coll).cache if coll is not None else None)

    def _naming(self, context):
        """The side naming of the reviewed take's labels (a custom pattern included), else None."""
        from ..blender.review import load_state
        from ..core.hands import HandNaming

        coll = None if self.filepath else reviewed_panel_take(context)
        if coll is None:
            return None
        pattern = load_state(coll).labeling.info.get("hands", {}).get("naming")
        return HandNaming(pattern) if pattern else None

    def _fail(self, exc: BaseException, source: str) -> set[str]:
        from ..core.errors import MocapInputError

        if isinstance(exc, MocapInputError):
            self.report({"ERROR"}, str(exc))
        else:  # never let a bad file take Blender down
            self.report({"ERROR"}, f"{source}: unexpected error while solving ({type(exc).__name__}: {exc})")
        return {"CANCELLED"}

    def _finish(self, context, request: SolveRequest, solved) -> set[str]:
        """Build the rig (replacing an earlier solve of the same take) and report."""
        from ..blender.armature import build_solved_hand, solved_hand_collection
        from ..blender.scene import free_name
        from ..core.hands import sided_path
        from ..core.solve import as_solves

        hands = as_solves(solved)
        try:
            if self.save_calibration:
                for side, one in hands:  # c.json, or c_left.json and c_right.json (as the command line)
                    one.calibration.save(sided_path(bpy.path.abspath(self.save_calibration), side))
        except Exception as exc:
            return self._fail(exc, self.save_calibration)
        base = os.path.splitext(os.path.basename(request.source))[0]
        # Every earlier solve of the take goes, one-hand or two-hand: solving again replaces.
        earlier = [request.source] + [f"{request.source}:{side}" for side in SIDES]
        said = []
        for i, (side, one) in enumerate(hands):
            collection = solved_hand_collection(context.scene, f"{request.source}:{side}" if side else request.source,
                                                f"{base} {side} hand" if side else f"{base} hand",
                                                replaces=earlier if i == 0 else ())
            # "Hand" for the first take's rig, "<take>:Hand" beside another take's (never "Hand.001");
            # "Hand_L" / "Hand_R" for the hands of a two-hand take, as the command line names them.
            name = free_name(f"Hand_{side[0].upper()}" if side else "Hand", bpy.data.objects, base)
            arm = build_solved_hand(one, collection, name=name, scale=request.scale,
                                    digests=(request.digests or {}).get(side), smooth_hz=request.smooth_hz)
            report = one.report()
            seconds = sum(one.seconds.values())
            said.append(f"{report['solved_frames']} of {report['frames']} frames in {seconds:.1f} s: marker RMS "
                        f"{report['marker_rms_mm']:.2f} mm, {report['frames_over_gate']} frames over the "
                        f"{report['gate_mm']:g} mm gate ({arm.name})")
        take_coll = bpy.data.collections.get(request.source)
        if take_coll is not None and take_coll.get("mocap_fill"):  # the fills follow the new solve
            from ..blender.fill import refill

            filled = refill(take_coll, hands)
            said.append(f"refilled {filled['filled']} gaps")
        self.report({"INFO"}, "Solved " + "; ".join(said))
        return {"FINISHED"}

    def invoke(self, context, event):
        self.in_background = True
        return context.window_manager.invoke_props_dialog(self)

    def execute(self, context):
        source = self.filepath or "the take"
        try:
            request = self._request(context)
        except Exception as exc:
            return self._fail(exc, source)
        if request is None:
            self.report({"ERROR"}, "No labeled take: label the imported take, select one of its markers, "
                                   "or give a labeled file")
            return {"CANCELLED"}
        if self.in_background and in_background(context):
            return self._start(context, request)
        try:
            solved = request.run(_stage_printer() if bpy.app.background else None)
        except Exception as exc:
            return self._fail(exc, request.source)
        return self._finish(context, request, solved)

    # --- running on a worker thread, like Label Markers ---------------------------------------

    def _start(self, context, request: SolveRequest) -> set[str]:
        from ..core.jobs import Job

        self._pending = request
        return start_modal(self, context, Job(request.run))

    def _progress(self, job) -> tuple[str, float]:
        return f"Solving the hand of {self._pending.source}: {job.message}", self._pending.share

    def _job_failed(self, exc: BaseException) -> set[str]:
        return self._fail(exc, self._pending.source)

    def _job_done(self, context, result) -> set[str]:
        return self._finish(context, self._pending, result)


classes = (MOCAPAL_OT_solve_hand,)
