"""FBX and BVH of an animated armature through Blender's own exporters, headless; the solved scene,
also on an animator's own character (``--retarget``).

Both exporters write to a temporary file that is renamed into place only when the exporter succeeded.

Engine-ready FBX (``--bone-names``). An FBX holds ONE animation stack (named after the file) with
only the armature it exports: no marker empties, no other action (Blender's own *File > Export >
FBX* defaults to one stack per action, ``bake_anim_use_all_actions``, which wrote 54 stacks for a
solved scene). The exporter sees a temporary copy of the armature, with its own copy of the action,
alone in a temporary scene named after the file (:func:`export_copy`): our rig's bones are renamed
there through :func:`..core.retarget.bone_maps.export_names` (F-curves follow the renames), so the
scene, and any .blend saved from it, keep our names; the copy takes the original's object, armature
and action names, so the file holds no ``.001``. A character's armature (``--retarget``) keeps its
own bone names; the preset still picks its axes and units. The exporter's options per preset are
:data:`FBX_OPTIONS`; what they rest on:

- Every preset: ``add_leaf_bones=False`` (the ``_end`` bones Blender adds otherwise are extra joints
  an engine skeleton does not have), ``primary_bone_axis="Y"``, ``secondary_bone_axis="X"`` (the
  exporter's defaults: Blender's bone frames are written unchanged, so every rotation is the one
  keyed; engines retarget by name and rest pose, not by a bone axis), ``bake_anim_simplify_factor=0``
  (every frame kept), ``bake_space_transform=False`` (the exporter calls its *Apply Transform*
  "known to be broken with armatures/animations"), ``object_types={"ARMATURE"}``.
- ``unity``, ``mixamo``, ``rigify`` and ``ours``: Y up, forward -Z (``axis_forward="-Z"``,
  ``axis_up="Y"``, FBX's own axes and the exporter's defaults) and ``apply_scale_options=
  "FBX_SCALE_ALL"`` with ``apply_unit_scale=True``: the file's unit scale says metres and no object
  carries a scale of 100 (the default ``FBX_SCALE_NONE`` puts 100 on the armature's node). These
  are the settings of Unity's own ``Unity-BlenderToFBX.py`` (the script Unity runs to import a
  .blend: ``apply_scale_options='FBX_SCALE_ALL'``, ``bake_anim_use_all_actions=False``,
  ``bake_anim_use_nla_strips=False``, default axes); Unity's importer reads the unit scale
  (*Convert Units*) and the file's axes. Mixamo rigs are mostly used in Unity.
- ``ue5``: Z up, forward Y (``axis_forward="Y"``, ``axis_up="Z"``: Blender's own axes, no
  conversion, Unreal being Z-up too) and centimetres, Unreal's unit, with the armature's node at
  scale 1: as Epic's *Send to Unreal* add-on (EpicGamesExt/BlenderTools, send2ue default template:
  ``axis_forward "Y"``, ``axis_up "Z"``, ``add_leaf_bones false``, ``primary_bone_axis "Y"``,
  ``secondary_bone_axis "X"``, ``bake_anim_simplify_factor 0.0``, and its *Automatically scale bones*,
  which scales the armature and its location keys by 100 before export). The copy's bones, its
  location keys and its place are scaled to centimetres, and ``global_scale`` keeps the file's
  unit scale at 1 (cm) under ``FBX_SCALE_ALL``: the numbers in the file are Unreal's centimetres, with
  or without its importer's *Convert Scene Unit*.

Blender's importer reads every preset back with the same bone rotations (tests/blender/
test_retarget_headless.py; a second reader, ufbx, where installed).
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
from collections.abc import Iterator

import bpy
import numpy as np
from mathutils import Matrix

from ..core.atomic import atomic_output
from ..core.errors import MocapInputError
from ..core.solve import as_solves
from . import animio

#: ``--bone-names``: our bone names, or those of a rig convention (:func:`..core.retarget.bone_maps.export_names`).
BONE_NAME_PRESETS = ("ours", "ue5", "unity", "mixamo", "rigify")

_EVERY = {"add_leaf_bones": False, "primary_bone_axis": "Y", "secondary_bone_axis": "X", "apply_unit_scale": True,
          "apply_scale_options": "FBX_SCALE_ALL", "bake_space_transform": False}
_Y_UP = _EVERY | {"axis_forward": "-Z", "axis_up": "Y"}
#: Blender's FBX exporter options per ``--bone-names`` preset (the module's docstring says why).
FBX_OPTIONS: dict[str, dict] = {"ours": _Y_UP, "rigify": _Y_UP, "unity": _Y_UP, "mixamo": _Y_UP,
                                "ue5": _EVERY | {"axis_forward": "Y", "axis_up": "Z"}}
#: Presets whose FBX is in centimetres with the armature's node at scale 1 (Unreal's unit).
CENTIMETRES = frozenset({"ue5"})


def _run(path: str, export) -> None:
    with atomic_output(path) as tmp:
        result = export(tmp)
        if "FINISHED" not in result or not os.path.isfile(tmp):
            raise MocapInputError(path, f"Blender's exporter did not finish ({', '.join(result)})")


def bone_names_for(preset: str, side: str) -> dict[str, str] | None:
    """Our bone -> its name in ``preset`` for a hand of ``side`` (None for ``ours``: nothing renamed)."""
    if preset not in BONE_NAME_PRESETS:
        raise MocapInputError(None, f"unknown bone names {preset!r}; give one of {', '.join(BONE_NAME_PRESETS)}")
    if preset == "ours":
        return None
    from ..core.retarget.bone_maps import export_names

    return {ours: name for ours, name in export_names(preset, side or "left").items() if name}


def _aside(name: str, datablocks) -> str:
    """A name no datablock of ``datablocks`` holds, to move ``name`` out of the way for a while."""
    while True:
        free = f"{name[:40]}~{secrets.token_hex(3)}"
        if datablocks.get(free) is None:
            return free


def _action_fcurves(action: bpy.types.Action) -> list:
    """Every F-curve of ``action``, whatever its slots (Blender 4.4+ keeps them in layers)."""
    if not animio.SLOTTED:
        return list(action.fcurves)
    return [fc for layer in action.layers for strip in layer.strips for bag in strip.channelbags for fc in bag.fcurves]


def _scale_locations(action: bpy.types.Action, factor: float) -> None:
    """Location keys of ``action`` (an object's and its pose bones') times ``factor``, handles too."""
    for fc in _action_fcurves(action):
        if fc.data_path != "location" and not fc.data_path.endswith(".location"):
            continue
        n = len(fc.keyframe_points)
        for prop in ("co", "handle_left", "handle_right"):
            buf = np.empty(2 * n, dtype=np.float32)
            fc.keyframe_points.foreach_get(prop, buf)
            buf[1::2] *= factor
            fc.keyframe_points.foreach_set(prop, buf)
        fc.update()


@contextlib.contextmanager
def export_copy(arm_obj: bpy.types.Object, scene_name: str, names: dict[str, str] | None = None,
                scale: float = 1.0) -> Iterator[tuple[bpy.types.Object, bpy.types.Scene]]:
    """A temporary copy of ``arm_obj`` (object, armature and action) alone in a temporary scene
    ``scene_name``, to export: ``(copy, scene)``, the copy selected and active there; both gone
    afterwards. The copy has the original's names (the originals, and a scene named ``scene_name``, are
    renamed aside meanwhile), so the file holds no ``.001``; the scene has the current scene's frame
    rate and units. Alone, it is all the exporter's frame-by-frame bake evaluates (with a solved scene's
    marker empties and deformed skin, 10,000 frames took 15 s instead of 9 s).

    ``names``: our bone -> the name it gets on the copy (its F-curves follow). ``scale``: the copy's
    bones, location keys and place times this (centimetres for Unreal).
    """
    source = bpy.context.scene
    ad = arm_obj.animation_data
    action = ad.action if ad is not None else None
    kept = [(arm_obj, bpy.data.objects), (arm_obj.data, bpy.data.armatures)]
    kept += [(action, bpy.data.actions)] if action is not None else []
    taken = bpy.data.scenes.get(scene_name)
    kept += [(taken, bpy.data.scenes)] if taken is not None else []
    original = [(idb, idb.name) for idb, _ in kept]
    made = []
    try:
        for idb, datablocks in kept:
            idb.name = _aside(idb.name, datablocks)
        scene = bpy.data.scenes.new(scene_name)
        made.append(scene)
        scene.render.fps, scene.render.fps_base = source.render.fps, source.render.fps_base
        scene.unit_settings.system = source.unit_settings.system
        scene.unit_settings.scale_length = source.unit_settings.scale_length
        copy = arm_obj.copy()
        made.append(copy)
        copy.data = arm_obj.data.copy()
        made.append(copy.data)
        copy.name, copy.data.name = original[0][1], original[1][1]
        if action is not None:
            new = action.copy()
            made.append(new)
            new.name = original[2][1]
            slot = ad.action_slot if animio.SLOTTED else None
            copy.animation_data.action = new
            if slot is not None and copy.animation_data.action_slot is None:
                copy.animation_data.action_slot = new.slots.get(slot.identifier) or new.slots[0]
        scene.collection.objects.link(copy)
        copy.hide_viewport = False
        view_layer = scene.view_layers[0]
        copy.hide_set(False, view_layer=view_layer)
        copy.select_set(True, view_layer=view_layer)
        view_layer.objects.active = copy
        if names:  # through names no bone holds, so that no rename meets a name still in use
            bones = [b for b in copy.data.bones if b.name in names]
            wanted = [names[b.name] for b in bones]
            for i, b in enumerate(bones):
                b.name = f"~mocap{i}~"
            for b, name in zip(bones, wanted):
                b.name = name
        if scale != 1.0:
            copy.data.transform(Matrix.Scale(scale, 4))
            copy.location = copy.location * scale
            if action is not None:
                _scale_locations(copy.animation_data.action, scale)
            for track in copy.animation_data.nla_tracks if copy.animation_data else ():
                for strip in track.strips:  # the strips' actions are shared with the original: scale copies
                    if strip.action is None:
                        continue
                    slot = getattr(strip, "action_slot", None)
                    new = strip.action.copy()
                    made.append(new)
                    strip.action = new
                    if slot is not None and getattr(strip, "action_slot", None) is None:
                        strip.action_slot = new.slots.get(slot.identifier) or new.slots[0]
                    _scale_locations(new, scale)
        view_layer.update()
        yield copy, scene
    finally:
        bpy.data.batch_remove(made)
        for idb, name in original:
            idb.name = name


def _in(scene: bpy.types.Scene, obj: bpy.types.Object):
    """Operators run on ``scene`` with ``obj`` active (a context override: the window keeps its scene)."""
    return bpy.context.temp_override(scene=scene, view_layer=scene.view_layers[0], object=obj, active_object=obj,
                                     selected_objects=[obj])


def export_fbx(arm_obj: bpy.types.Object, path: str, frame_start: int, frame_end: int, *, preset: str = "ours",
               side: str = "", rename: bool = True) -> None:
    """The armature and its animation (every frame baked, no simplification) as FBX: one animation stack
    named after the file, holding only this armature.

    ``preset`` (:data:`BONE_NAME_PRESETS`) picks the bone names (with ``rename``: our rig's, for a hand
    of ``side``) and the engine's axes and units (:data:`FBX_OPTIONS`); ``rename=False`` keeps the
    armature's own bone names (a character's)."""
    names = bone_names_for(preset, side)
    units = bpy.context.scene.unit_settings
    per_unit = 100.0 if units.system == "NONE" else 100.0 * units.scale_length  # centimetres per Blender unit
    cm = preset in CENTIMETRES and abs(per_unit - 1.0) > 1e-9  # a scene in centimetres already stays
    stem = os.path.splitext(os.path.basename(path))[0]
    scale = per_unit if cm else 1.0
    with export_copy(arm_obj, stem, names if rename else None, scale) as (copy, scene), _in(scene, copy):
        scene.frame_start, scene.frame_end = frame_start, frame_end
        # use_selection=False: the temporary scene's view layer holds the copy alone
        _run(path, lambda tmp: bpy.ops.export_scene.fbx(
            filepath=tmp, use_selection=False, object_types={"ARMATURE"}, use_armature_deform_only=False,
            global_scale=1.0 / per_unit if cm else 1.0, bake_anim=True, bake_anim_use_all_bones=True,
            bake_anim_use_all_actions=False, bake_anim_use_nla_strips=False, bake_anim_simplify_factor=0.0,
            bake_anim_force_startend_keying=True, use_custom_props=False, **FBX_OPTIONS[preset]))


def export_bvh(arm_obj: bpy.types.Object, path: str, frame_start: int, frame_end: int, *, preset: str = "ours",
               side: str = "", rename: bool = True) -> None:
    """The armature's animation as BVH (Euler rotations in each bone's native order), its bones named by
    ``preset`` (``rename=False``: the armature's own names). BVH has no axes to choose: Blender's Z up."""
    names = bone_names_for(preset, side)
    stem = os.path.splitext(os.path.basename(path))[0]
    with export_copy(arm_obj, stem, names if rename else None) as (copy, scene), _in(scene, copy):
        _run(path, lambda tmp: bpy.ops.export_anim.bvh(filepath=tmp, frame_start=frame_start, frame_end=frame_end,
                                                       rotate_mode="NATIVE", global_scale=1.0))


#: Export Hand's file formats: the exporter of each, and its file ending.
HAND_FORMATS = {"FBX": (export_fbx, ".fbx"), "BVH": (export_bvh, ".bvh")}


def _rig_side(arm_obj: bpy.types.Object) -> str:
    """The side of a solved rig's hand (its calibration's), ``""`` where it names none."""
    import json

    try:
        return str(json.loads(arm_obj["mocap_calibration"]).get("side") or "")
    except (ValueError, AttributeError):
        raise MocapInputError(None, f"{arm_obj.name!r}: its calibration is not readable") from None


def _solved_rigs_of(take_coll: bpy.types.Collection | None, scene: bpy.types.Scene) -> list[bpy.types.Object]:
    if take_coll is None:
        return [o for o in scene.objects if o.type == "ARMATURE" and "mocap_calibration" in o]
    sources = {take_coll.name} | {f"{take_coll.name}:{side}" for side in ("left", "right")}
    return [o for c in bpy.data.collections if c.get("mocap_solved_from") in sources for o in c.all_objects
            if o.type == "ARMATURE" and "mocap_calibration" in o]


def has_hand_rigs(take_coll: bpy.types.Collection | None, scene: bpy.types.Scene) -> bool:
    """Whether :func:`take_hand_rigs` finds a rig to export (Export Hand's poll)."""
    return bool(_solved_rigs_of(take_coll, scene))


def take_hand_rigs(take_coll: bpy.types.Collection | None, scene: bpy.types.Scene) -> list[bpy.types.Object]:
    """The solved hand rigs (armatures keeping a calibration, ``mocap_calibration``) to export: those
    solved from ``take_coll`` (its collection, or ``<take>:left`` / ``<take>:right``); with no take,
    those of ``scene``, where it holds one rig per side at most (a scene opened from ``solve --blend``).
    Sorted by side, left first.

    Raises:
        MocapInputError: the take (or scene) has no solved hand, or two of one side.
    """
    where = "the scene" if take_coll is None else f"take {take_coll.name!r}"
    sides: dict[str, list] = {}
    for rig in _solved_rigs_of(take_coll, scene):
        sides.setdefault(_rig_side(rig), []).append(rig)
    if not sides:
        raise MocapInputError(None, f"No solved hand in {where}: run Solve Hand on the labeled take first")
    for objs in sides.values():
        if len(objs) > 1:
            raise MocapInputError(None, f"{len(objs)} solved hands of one side in {where} "
                                        f"({', '.join(sorted(o.name for o in objs))}): choose their take in the "
                                        "Take field")
    return [sides[side][0] for side in sorted(sides)]


def default_hand_path(take_coll: bpy.types.Collection | None, scene: bpy.types.Scene, ext: str) -> str:
    """Export Hand's default file: beside the take's source file (``take_hand.fbx``); with no take, beside
    the file or take the scene's rig was solved from, else beside the .blend (``<blend>_hand.fbx``)."""
    ending = f"_hand{ext}"
    if take_coll is None:
        rigs = _solved_rigs_of(None, scene)
        source = ""
        for coll in (rigs[0].users_collection if rigs else ()):
            source = str(coll.get("mocap_solved_from") or "")
            if source:
                break
        take_name = source.rsplit(":", 1)[0] if source.endswith((":left", ":right")) else source
        take_coll = bpy.data.collections.get(take_name) if take_name else None
        if take_coll is None and os.path.splitext(source)[1]:  # solved from a labeled file
            return os.path.splitext(bpy.path.abspath(source))[0] + ending
    if take_coll is not None and "mocap_source" in take_coll:
        src = str(take_coll.get("mocap_source") or "")
        return os.path.splitext(bpy.path.abspath(src) if src else take_coll.name)[0] + ending
    blend = bpy.data.filepath
    return (os.path.splitext(blend)[0] if blend else "hand") + ending


def export_hands(take_coll: bpy.types.Collection | None, scene: bpy.types.Scene, *, filepath: str,
                 file_format: str = "FBX", bone_names: str = "ours") -> list[str]:
    """Export Hand: each solved rig of the take (:func:`take_hand_rigs`) alone, with its animation over
    the frames it was solved on, as FBX (one animation stack named after the file, the rig only, the
    preset's axes and units: :func:`export_fbx`) or BVH (:func:`export_bvh`), its bones named by
    ``bone_names`` (:data:`BONE_NAME_PRESETS`).

    One file per hand: a take of one hand writes ``filepath``; of two, one file per hand with the side
    before the extension (``take_hand_left.fbx``, ``take_hand_right.fbx``), as ``solve --fbx`` does
    (an engine imports one skeleton per file, and each file's one stack is its hand's). The extension
    is the format's. Each file is written atomically; the scene is left as it was (the exporter sees a
    temporary copy in a temporary scene: :func:`export_copy`). Returns the paths written.

    Raises:
        MocapInputError: an unknown format or preset, no solved hand (or two of one side).
        OSError: naming a file that cannot be written.
    """
    import errno

    from ..core.hands import sided_path

    if file_format not in HAND_FORMATS:
        raise MocapInputError(None, f"unknown format {file_format!r}; give one of {', '.join(HAND_FORMATS)}")
    bone_names_for(bone_names, "left")  # an unknown preset fails before anything is written
    rigs = take_hand_rigs(take_coll, scene)
    export, ext = HAND_FORMATS[file_format]
    if not filepath:
        raise MocapInputError(None, "No file to export to: give a file name")
    stem, given = os.path.splitext(filepath)
    if not os.path.basename(stem):
        raise IsADirectoryError(errno.EISDIR, "is a folder; give a file name", filepath)
    path = filepath if given.lower() == ext else stem + ext
    jobs = [(rig, _rig_side(rig), solved_frames(rig)) for rig in rigs]
    paths = []
    for rig, side, (first, last) in jobs:
        out = sided_path(path, side) if len(rigs) > 1 else path
        export(rig, out, first, last, preset=bone_names, side=side)
        paths.append(out)
    return paths


def solved_frames(arm_obj: bpy.types.Object) -> tuple[int, int]:
    """The first and last frame a solved rig covers: those of its kept solve (every frame of the take),
    else its keys'."""
    from .armature import SOLVE_RECORD

    record = arm_obj.get(SOLVE_RECORD)
    if record is not None and "first_frame" in record and int(record.get("frames", 0)) > 0:
        first = int(record["first_frame"])
        return first, first + int(record["frames"]) - 1
    ad = arm_obj.animation_data
    if ad is None or ad.action is None:
        raise MocapInputError(None, f"{arm_obj.name!r} has no animation to export: solve the hand again")
    start, end = ad.action.frame_range
    return int(round(start)), int(round(end))


def save_blend(path: str) -> None:
    """Save the open scene to ``path``, complete or not at all."""
    with atomic_output(path) as tmp:
        bpy.ops.wm.save_as_mainfile(filepath=tmp, check_existing=False, copy=True)


def export_labeled_c3d(take_coll: bpy.types.Collection, path: str) -> None:
    """Write a reviewed take of the scene as a labeled C3D (``core.labeling.labeled_take``): the
    layout's markers by name, then one point per trajectory left unlabeled, named as its empty in
    the scene (the file's own name, or ``*<slot>``).

    The file is in the take's own terms, not the scene's: positions in the file's units (the
    import's Scale taken off), frames numbered as the file numbered them (the import's Frame
    Offset taken off), so a round trip gives the original first frame. Filled samples (the
    ``GENERATED`` keys of *Fill Gaps*) are written as computed: residual 0, no camera bits.
    """
    import numpy as np

    from ..core.formats.c3d import write_c3d
    from ..core.labeling import labeled_take
    from ..core.take import UNIT_SCALE
    from .fill import filled_keys
    from .scene import file_frames
    from .takes import current_take, load_state

    take = file_frames(take_coll, current_take(take_coll))
    units = take.source_units if take.source_units in UNIT_SCALE else "mm"
    labeling = load_state(take_coll).labeling
    out = labeled_take(take, labeling)
    idx, labels, xyz = filled_keys(take_coll, len(labeling.names))
    if len(idx):  # the fills (Fill Gaps), written as computed samples
        out.filled = np.zeros(out.valid.shape, dtype=bool)
        out.positions[idx, labels] = xyz
        out.filled[idx, labels] = True
    write_c3d(out, path, units=units)


def _solved_rigs(take, solved, scene: bpy.types.Scene) -> list:
    """The take's markers and one keyed rig per solved hand in ``scene``: ``[(side, HandSolve, armature)]``
    (armatures ``Hand`` or ``Hand_L`` / ``Hand_R``, prefixed by the take where a name is taken)."""
    from .armature import build_solved_hand, solved_hand_collection
    from .names import free_name
    from .scene import ImportOptions, build_take

    coll = build_take(take, scene, ImportOptions())
    rigs = []
    for side, one in as_solves(solved):
        name = free_name(f"Hand_{side[0].upper()}" if side else "Hand", bpy.data.objects, coll.name)
        folder = solved_hand_collection(scene, f"{coll.name}:{side}" if side else coll.name,
                                        free_name(f"{side} hand" if side else "Hand", bpy.data.collections, coll.name))
        rigs.append((side, one, build_solved_hand(one, folder, name=name)))
    return rigs


def write_solved_scene(take, solved, blend: str | None = None, fbx: str | None = None,
                       bvh: str | None = None, *, bone_names: str = "ours") -> dict[str, str]:
    """A fresh scene with the labeled markers beside the solved, keyed rig; then the asked-for files.

    ``solved`` is one HandSolve, or ``[(side, HandSolve), ...]`` for a take of two hands: one rig
    per hand in the one .blend (armatures ``Hand_L`` / ``Hand_R``, collections ``left hand`` /
    ``right hand``), and one FBX / BVH per hand with the side before the extension
    (``take_left.fbx``). ``bone_names`` (:data:`BONE_NAME_PRESETS`) names the bones in the FBX and
    BVH and picks the FBX's engine axes and units; the .blend keeps our names.

    Returns ``{"blend" | "fbx" | "bvh" (+ "_left" / "_right"): path}`` of what was written.
    """
    from ..core.hands import sided_path

    bone_names_for(bone_names, "left")  # an unknown preset fails before anything is written
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rigs = _solved_rigs(take, solved, bpy.context.scene)
    out = {}
    if blend:
        save_blend(blend)
        out["blend"] = blend
    for side, one, arm in rigs:
        first, last = one.first_frame, one.first_frame + take.n_frames - 1
        key = f"_{side}" if side else ""
        for kind, path, export in (("fbx", fbx, export_fbx), ("bvh", bvh, export_bvh)):
            if path:
                export(arm, sided_path(path, side), first, last, preset=bone_names, side=one.calibration.side)
                out[kind + key] = sided_path(path, side)
    return out


def load_bone_map(value: str):
    """``--bone-map VALUE``: the name of a preset saved from Blender's Retarget panel
    (``<user config>/mocap_autolabel/bone_maps/<name>.json``, :func:`.retarget.preset_path`) or a bone
    map .json (:class:`..core.retarget.bone_maps.BoneMap`).

    Raises:
        MocapInputError: no such preset or file (the presets saved are listed), or not a bone map.
    """
    from ..core.retarget.bone_maps import BoneMap
    from .retarget import preset_folder, preset_path, presets

    path = value
    if not (value.lower().endswith(".json") or "/" in value or os.sep in value):
        path = preset_path(value)
        if not os.path.isfile(path):
            raise MocapInputError(value, f"no bone map preset of that name in {preset_folder()} (saved: "
                                         f"{', '.join(presets()) or 'none'}); give a preset's name or a .json file")
    if not os.path.isfile(path):
        raise MocapInputError(path, "no such bone map file")
    try:
        return BoneMap.load(path)
    except MocapInputError:
        raise
    except (ValueError, KeyError, TypeError, AttributeError) as exc:  # json.JSONDecodeError is a ValueError
        raise MocapInputError(path, f"is not a bone map ({exc})") from None


def _hand_sides(arm_obj: bpy.types.Object, bone_map=None) -> list[str]:
    """The sides of ``arm_obj``'s hands: those ``bone_map`` maps onto bones it has, else those the
    automatic map finds (a hand bone and at least one finger bone)."""
    names = [b.name for b in arm_obj.data.bones]
    if bone_map is not None:
        return [side for side, bones in bone_map.sides.items() if bones and set(bones.values()) <= set(names)]
    from ..core.retarget.bone_maps import auto_map

    parents = [names.index(b.parent.name) if b.parent else -1 for b in arm_obj.data.bones]
    found = auto_map(names, parents)
    return [side for side, bones in found.sides.items() if "palm" in bones and len(bones) > 1]


def pick_armature(character: str, name: str | None = None, bone_map=None) -> bpy.types.Object:
    """The armature of the open character .blend to retarget onto: ``name``, or the one armature of
    its scene with hand bones (:func:`_hand_sides`).

    Raises:
        MocapInputError: naming ``character``: no such armature, none with hand bones, or several
            (each listed, to be named as ``CHARACTER.blend:ARMATURE``).
    """
    arms = sorted((o for o in bpy.context.scene.objects if o.type == "ARMATURE"), key=lambda o: o.name)
    listed = ", ".join(repr(o.name) for o in arms) or "none"
    if name:
        obj = bpy.data.objects.get(name)
        if obj is None or obj.type != "ARMATURE":
            raise MocapInputError(character, f"has no armature {name!r} (its armatures: {listed})")
        if not _hand_sides(obj, bone_map):
            what = ("the bone map's bones" if bone_map is not None
                    else "hand bones the automatic map knows; give --bone-map")
            raise MocapInputError(character, f"armature {name!r} lacks {what}")
        return obj
    if not arms:
        raise MocapInputError(character, "holds no armature to retarget onto")
    hands = [o for o in arms if _hand_sides(o, bone_map)]
    if len(hands) == 1:
        return hands[0]
    if not hands and bone_map is not None:
        raise MocapInputError(character, f"holds no armature with the bone map's bones (its armatures: {listed})")
    if not hands:
        raise MocapInputError(character, f"holds no armature with hand bones (its armatures: {listed}); name one as "
                                         f"{os.path.basename(character)}:ARMATURE with a --bone-map")
    raise MocapInputError(character, f"holds {len(hands)} armatures with hand bones "
                                     f"({', '.join(repr(o.name) for o in hands)}): name one as "
                                     f"{os.path.basename(character)}:ARMATURE")


def open_character(character: str) -> None:
    """Open the character .blend (the scene the solved hands are added to).

    Raises:
        MocapInputError: the file is missing or is not a .blend Blender can read.
    """
    if not os.path.isfile(character):
        raise MocapInputError(character, "no such file (the character .blend to retarget onto)")
    try:
        bpy.ops.wm.open_mainfile(filepath=character, load_ui=False)
    except RuntimeError as exc:
        reason = str(exc).strip().splitlines()[-1] if str(exc).strip() else "unreadable"
        reason = re.sub(r'\s*in file ".*"$', "", re.sub(r"^Error:\s*", "", reason))
        raise MocapInputError(character, f"cannot be opened as a .blend ({reason})") from None


def check_character(character: str, armature: str | None = None, bone_map=None) -> str:
    """Open the character .blend and pick its armature (:func:`pick_armature`), as the retarget will: a bad
    character fails in a second, before the solve. Returns the armature's name; the open scene is left
    as the .blend is (a later :func:`write_retargeted_scene` opens it again).

    Raises:
        MocapInputError: as :func:`open_character` and :func:`pick_armature`.
    """
    if isinstance(bone_map, str):
        bone_map = load_bone_map(bone_map)
    open_character(character)
    return pick_armature(character, armature, bone_map).name


def write_retargeted_scene(take, solved, character: str, *, armature: str | None = None, bone_map=None,
                           wrist: str = "fingers", pinch: bool = False, blend: str | None = None,
                           fbx: str | None = None, bvh: str | None = None,
                           bone_names: str = "ours") -> tuple[dict[str, str], dict]:
    """The solved hand(s) retargeted onto a character: its .blend opened, the take's markers and our keyed
    rig(s) added, the character's armature (``armature``, else the one with hand bones: :func:`pick_armature`)
    keyed through ``bone_map`` (a :class:`..core.retarget.bone_maps.BoneMap`, a preset's name or a .json;
    None: the automatic map) by :func:`.retarget.retarget_character`; then ``blend`` (the whole scene),
    ``fbx`` and ``bvh`` (the character's armature alone, with its own bone names; ``bone_names`` picks
    the FBX's engine axes and units), one file each whatever the number of hands.

    Returns ``({"blend" | "fbx" | "bvh": path}, facts)``, facts those of :func:`.retarget.retarget_character`.

    Raises:
        MocapInputError: naming the character .blend or the bone map (see :func:`open_character`,
            :func:`pick_armature`, :func:`load_bone_map`).
    """
    from .retarget import retarget_character

    bone_names_for(bone_names, "left")
    if isinstance(bone_map, str):
        bone_map = load_bone_map(bone_map)
    open_character(character)
    arm = pick_armature(character, armature, bone_map)
    rigs = _solved_rigs(take, solved, bpy.context.scene)
    try:
        facts = retarget_character(bpy.context, armature=arm, bone_map=bone_map, reference="rest", wrist=wrist,
                                   pinch=pinch, sources=[rig for _, _, rig in rigs])
    except MocapInputError as exc:  # its line names no file: this one is the character's
        raise MocapInputError(exc.path or character, exc.problem) from None
    except (ValueError, KeyError) as exc:  # a map naming bones the armature lacks, a hand it cannot carry
        raise MocapInputError(character, f"cannot retarget onto {arm.name!r}: {exc}") from None
    first = min(one.first_frame for _, one, _ in rigs)
    last = first + take.n_frames - 1
    out = {}
    if blend:
        save_blend(blend)
        out["blend"] = blend
    for kind, path, export in (("fbx", fbx, export_fbx), ("bvh", bvh, export_bvh)):
        if path:
            export(arm, path, first, last, preset=bone_names, rename=False)
            out[kind] = path
    return out, facts


def write_review_scene(take, layout_ref: str, labeling, blend: str, method: str = "set", temporal: str = "vote",
                       solved=None) -> str:
    """A fresh scene for review: the raw take, its labeled and unlabeled markers keyed by confidence,
    the review state (so the add-on's panel picks it up), and the solved hand if given; saved to ``blend``.

    ``solved`` is one HandSolve, or ``[(side, HandSolve), ...]`` for a take of two hands (rigs
    ``Hand_L`` / ``Hand_R``, which the panel's Solve Hand replaces when it solves the take again)."""
    from ..core.layout import load_layout
    from ..core.review import Review
    from .armature import build_solved_hand, solved_hand_collection
    from .review import commit, write_labeling
    from .scene import ImportOptions, build_take
    from .takes import ReviewState

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    coll = build_take(take, scene, ImportOptions())
    write_labeling(coll, take, load_layout(layout_ref), labeling)
    commit(scene, coll, ReviewState(labeling, Review(), layout_ref, method, temporal))
    hands = as_solves(solved)
    digests = _scene_digests(coll, load_layout(layout_ref), labeling) if hands else {}
    for side, one in hands:
        if side:  # sources as Solve Hand names them, so that solving the take again replaces these rigs
            build_solved_hand(one, solved_hand_collection(scene, f"{coll.name}:{side}", f"{coll.name} {side} hand"),
                              name=f"Hand_{side[0].upper()}", digests=digests.get(side))
        else:
            build_solved_hand(one, solved_hand_collection(scene, coll.name, "Hand"), digests=digests.get(side))
    save_blend(blend)
    return blend


def _scene_digests(coll, layout, labeling) -> dict:
    """What each hand's solve saw, as Fill Gaps reads the scene's take back (``core.fill.solve_digests``):
    the rigs keep it, so a first Fill Gaps in the review scene reuses the solve."""
    from ..core.fill import solve_digests
    from ..core.hands import HandNaming
    from ..core.labeling import labeled_take
    from .takes import current_take

    naming = labeling.info.get("hands", {}).get("naming")
    return solve_digests(labeled_take(current_take(coll), labeling), layout,
                         HandNaming(naming) if naming else None)
