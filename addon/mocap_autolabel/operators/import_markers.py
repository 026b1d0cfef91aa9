"""File > Import > C3D markers: a take file becomes a collection of animated empties (or one point cloud)."""

from __future__ import annotations

import os

import bpy
from bpy.props import BoolProperty, CollectionProperty, FloatProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ImportHelper


class MOCAPAL_OT_import_markers(bpy.types.Operator, ImportHelper):
    """Import unlabeled or labeled markers (C3D, TRC, Qualisys TSV) as animated empties"""

    bl_idname = "mocap_autolabel.import_markers"
    bl_label = "Import C3D Markers"
    bl_options = {"REGISTER", "UNDO", "PRESET"}

    filename_ext = ".c3d"
    filter_glob: StringProperty(default="*.c3d;*.trc;*.tsv", options={"HIDDEN"})
    files: CollectionProperty(type=bpy.types.OperatorFileListElement, options={"HIDDEN", "SKIP_SAVE"})
    directory: StringProperty(subtype="DIR_PATH", options={"HIDDEN", "SKIP_SAVE"})

    # No hard minimum: Blender would clamp 0 or -1 to it silently; execute refuses a Scale of 0 or below.
    scale: FloatProperty(name="Scale", description="Factor applied to positions (metres) on import",
                         default=1.0, soft_min=0.001, soft_max=100.0)
    # No minimum either: the lowest offset depends on the file's first frame; execute refuses one that puts
    # frames before 0, where Blender's scene range cannot go.
    frame_offset: IntProperty(name="Frame Offset",
                              description="Added to the file's frame numbers; the take must stay on frame 0 or "
                                          "later, where Blender's scene range starts",
                              default=0)
    name_filter: StringProperty(name="Point Names", default="*",
                                description="Import only points whose name matches this pattern "
                                            "(* and ? wildcards, case-insensitive)")
    set_scene: BoolProperty(name="Set Scene Frame Rate and Range", default=True)
    as_point_cloud: BoolProperty(
        name="As Point Cloud",
        description="Show the raw markers as one point cloud driven by geometry nodes instead of one keyed "
                    "empty per marker: no keys, about a tenth of the time and memory, for very long takes. "
                    "Missing samples are not shown; labeling and review work the same, and labeled markers "
                    "are keyed empties either way",
        default=False)

    def paths(self) -> list[str]:
        if self.files and self.directory:
            return [os.path.join(self.directory, f.name) for f in self.files if f.name]
        return [self.filepath] if self.filepath else []

    def invoke(self, context, event):
        # A drag-and-drop (FileHandler) arrives with the path set: import without a dialog.
        if self.filepath or (self.files and self.directory):
            return self.execute(context)
        return ImportHelper.invoke(self, context, event)

    def execute(self, context):
        from ..blender.scene import ImportOptions, build_take, check_importable, check_options
        from ..core.errors import MocapInputError
        from ..core.take import read_take

        options = ImportOptions(self.scale, self.frame_offset, self.name_filter, self.set_scene,
                                as_point_cloud=self.as_point_cloud)
        paths = self.paths()
        if not paths:
            self.report({"ERROR"}, "No file given")
            return {"CANCELLED"}
        try:
            check_options(options)  # once, not once per file
        except MocapInputError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        imported = 0
        for path in paths:
            try:
                take = read_take(path)
                markers = len(check_importable(take, options, os.path.basename(path)))  # before anything is made
            except MocapInputError as exc:
                self.report({"ERROR"}, str(exc))
                continue
            except Exception as exc:  # never let a bad file take Blender down
                self.report({"ERROR"}, f"{path}: unexpected error while reading ({type(exc).__name__}: {exc})")
                continue
            collection = build_take(take, context.scene, options)
            context.scene.mocap_autolabel.take = collection  # the take the Mocap panel works on
            _make_active(context, collection)
            picked = _pick_layout(context, collection, take)
            for warning in take.warnings:
                self.report({"WARNING"}, f"{os.path.basename(path)}: {warning}")
            self.report({"INFO"}, f"Imported {markers} markers x {take.n_frames} frames "
                                  f"from {os.path.basename(path)}"
                                  + (" as a point cloud" if options.as_point_cloud else "")
                                  + (f"; Layout set to {picked}: the file names every {picked} marker"
                                     if picked else "")
                                  + _suggestion(options, take.n_frames * markers))
            imported += 1
        return {"FINISHED"} if imported else {"CANCELLED"}


#: Above this many samples (frames x markers) the import suggests As Point Cloud: a 30-minute take of
#: two hands (38 markers) at 120 Hz is 8.2 million samples.
SUGGEST_POINT_CLOUD = 5_000_000
#: Peak memory growth of an import in Blender, bytes per sample, as benchmarks/import_speed.py measures
#: it (bpy 5.0.1): keyed, 3 keys of 72 bytes, Blender's evaluated copy of them and the undo step it
#: pushes after the import (about 640); as a point cloud, the mesh and the take read (about 45).
KEYED_BYTES_PER_SAMPLE = 640
CLOUD_BYTES_PER_SAMPLE = 45


def _suggestion(options, samples: int) -> str:
    """A hint to import a very long take as a point cloud (empty when it is one, or short)."""
    if options.as_point_cloud or samples < SUGGEST_POINT_CLOUD:
        return ""
    return (f"; {samples / 1e6:.1f} M samples take about {samples * KEYED_BYTES_PER_SAMPLE / 2**30:.1f} GB "
            f"of memory as keys: As Point Cloud imports them in about "
            f"{samples * CLOUD_BYTES_PER_SAMPLE / 2**20:.0f} MB")


def _pick_layout(context, collection, take) -> str | None:
    """Where the file's point names include every marker name of a built-in layout, put that layout in
    the panel's Layout field for the new take (unless a layout was chosen for this take already);
    returns it, or None. A take that names no layout's markers gets the layout the user chose last (not
    an earlier take's pick). Either way the take remembers the Layout the panel shows for it, which
    comes back when the Take field returns to it."""
    from ..blender.properties import LAYOUT_CHOICE, USER_LAYOUT, set_layout
    from ..core.layout import DEFAULT_LAYOUT, builtin_layouts
    from ..core.process import layout_from_names

    settings = context.scene.mocap_autolabel
    if LAYOUT_CHOICE in collection:
        return None
    picked = layout_from_names(take)
    if picked is None:
        if not settings.layout_file:
            # Not another take's pick: the layout the user chose last (han19 where they chose none).
            working = settings.get(USER_LAYOUT, DEFAULT_LAYOUT)
            set_layout(settings, working if working in builtin_layouts() else DEFAULT_LAYOUT)
            collection[LAYOUT_CHOICE] = settings.layout  # shown again when the Take field comes back to it
        return None
    set_layout(settings, picked)
    collection[LAYOUT_CHOICE] = picked
    return picked


def _make_active(context, collection) -> None:
    """Select the new take's first marker alone and make it the active object, so that nothing that
    follows the selection acts on a take imported before."""
    context.view_layer.update()  # the new objects get their view-layer bases only at the next sync
    objs = [o for o in collection.objects if o.name in context.view_layer.objects]
    if not objs:
        return
    for other in context.selected_objects:
        other.select_set(False)
    objs[0].select_set(True)
    context.view_layer.objects.active = objs[0]
