"""The Cleanup panel's settings (``scene.mocap_autolabel.cleanup``) and its fill preview's list.

Light on purpose (only bpy): it is imported when the add-on is enabled. Registering the settings
also registers :func:`forget_read_takes` after undo and redo. The defaults are the
core's (:mod:`..core.cleanup`); a test checks that they agree. The list of the fill preview
(:func:`.cleanup.preview_fill`) lives here so that the panel's UIList shows it and undo restores it.
"""

from __future__ import annotations

import bpy
from bpy.props import CollectionProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

#: The core's defaults (:data:`..core.cleanup.MAX_ACCEL`, ``MAX_SPEED``, ``FILTER_ORDER``,
#: :data:`..core.fill.MAX_GAP`), repeated here so that enabling the add-on does not import the core's
#: cleanup (scipy); a test checks that they agree.
MAX_ACCEL, MAX_SPEED, FILTER_ORDER, MAX_GAP = 20.0, 5.0, 2, 1.0
#: Hz: the low-pass filter's default cut-off (a hand solve's own smoothing is 10 Hz).
CUTOFF_HZ = 10.0
#: Frames: runs of a label shorter than this are deleted by Delete Short Fragments by default.
MIN_FRAMES = 10


@bpy.app.handlers.persistent
def forget_read_takes(*_args) -> None:
    """After an undo or a redo: every take is read again from the scene when next asked for. The
    session keeps each take as it read it from the raw keys (:func:`.takes.current_take`), which Smooth
    writes and undo restores (registered with :class:`MOCAPAL_PG_cleanup`)."""
    from .session import session

    for coll in bpy.data.collections:
        if "mocap_source" in coll:
            session(coll).take = None


class MOCAPAL_PG_fill_gap(bpy.types.PropertyGroup):
    """One gap of the fill preview: its frames, the method asked and the one that fills it, the markers
    it is computed from, its expected error, or why it stays open."""

    gap: IntProperty(name="Gap")  # its number in the preview (all of the hand's gaps)
    frame_start: IntProperty(name="Start")
    frame_end: IntProperty(name="End")
    asked: StringProperty(name="Asked")  # auto, or the method picked for this gap
    method: StringProperty(name="Method")  # the model that fills it ("" where none can)
    donors: StringProperty(name="Donors")
    error_mm: FloatProperty(name="Expected Error", description="Mean expected error of the fill (mm)")
    reason: StringProperty(name="Open Because")
    tried: StringProperty(name="Tried")


class MOCAPAL_PG_cleanup(bpy.types.PropertyGroup):
    max_accel: FloatProperty(name="Max Acceleration", default=MAX_ACCEL, min=0.1, soft_max=200.0,
                             description="Find Spikes: the acceleration (m/s²) a marker's course is taken to keep "
                                         "within around a spike; lower finds smaller spikes, higher spares faster "
                                         "motion")
    max_speed: FloatProperty(name="Max Speed", default=MAX_SPEED, min=0.01, soft_max=20.0,
                             description="Find Spikes: a step between two frames faster than this (m/s) is a jump")
    cutoff_hz: FloatProperty(name="Cut-off", default=CUTOFF_HZ, min=0.01, soft_max=30.0,
                             description="Smooth: the low-pass filter's cut-off frequency (Hz); below half the "
                                         "take's frame rate")
    order: IntProperty(name="Order", default=FILTER_ORDER, min=1, max=8,
                       description="Smooth: the Butterworth filter's order (run forwards and backwards: twice "
                                   "that, and no lag)")
    min_frames: IntProperty(name="Shorter Than", default=MIN_FRAMES, min=1, soft_max=240,
                            description="Delete Short Fragments: runs of a label's samples shorter than this "
                                        "many frames are taken off the label")
    quick_next: IntProperty(name="Next Label", default=0, min=0,
                            description="Quick Label: the layout's label (its number, from 0) the next point gets")
    max_gap: FloatProperty(name="Max Gap", default=MAX_GAP, min=0.01, soft_max=5.0, unit="TIME_ABSOLUTE",
                           description="Fill Preview: longer gaps are left open (seconds)")
    preview: CollectionProperty(type=MOCAPAL_PG_fill_gap)
    preview_index: IntProperty(name="Gap", default=-1)
    preview_take: PointerProperty(type=bpy.types.Collection, name="Previewed Take", options={"HIDDEN"})
    preview_label: IntProperty(default=-1, options={"HIDDEN"})
    preview_name: StringProperty(options={"HIDDEN"})  # the previewed marker's label
    preview_token: StringProperty(options={"HIDDEN"})  # the review state's token it was made from
    preview_id: StringProperty(options={"HIDDEN"})  # the session's preview it shows
    preview_max_gap: FloatProperty(default=MAX_GAP, options={"HIDDEN"})

    @classmethod
    def register(cls) -> None:
        for handlers in (bpy.app.handlers.undo_post, bpy.app.handlers.redo_post):
            if forget_read_takes not in handlers:
                handlers.append(forget_read_takes)

    @classmethod
    def unregister(cls) -> None:
        for handlers in (bpy.app.handlers.undo_post, bpy.app.handlers.redo_post):
            if forget_read_takes in handlers:
                handlers.remove(forget_read_takes)


classes = (MOCAPAL_PG_fill_gap, MOCAPAL_PG_cleanup)
