"""Turn a Take into Blender data: one animated empty per point slot (or one point cloud)."""

from __future__ import annotations

import fnmatch
import os
from dataclasses import dataclass

import bpy
import numpy as np

from ..core.take import Take
from . import animio
from .names import free_name
from .pointcloud import build_cloud

#: Empty display size in metres: about a hand marker's diameter.
MARKER_DISPLAY_SIZE = 0.008


@dataclass
class ImportOptions:
    """How a take becomes a scene.

    Attributes:
        scale: factor applied to positions (metres) before they become Blender units.
        frame_offset: added to the file's frame numbers to get Blender frames.
        name_filter: glob pattern (``*``, ``?``, case-insensitive); only matching points import.
        set_scene: set the scene's frame rate and frame range from the take.
        as_point_cloud: show the raw markers as one point cloud driven by geometry nodes
            (:mod:`.pointcloud`: no keys, about a tenth of the time and memory) instead of one
            keyed empty per point slot; labeled markers are keyed empties either way.
    """

    scale: float = 1.0
    frame_offset: int = 0
    name_filter: str = "*"
    set_scene: bool = True
    as_point_cloud: bool = False


def selected_points(take: Take, pattern: str) -> np.ndarray:
    """int indices of the point slots whose name matches the glob ``pattern`` (case-insensitive)."""
    pat = (pattern or "*").lower()
    return np.array([i for i, n in enumerate(take.names) if fnmatch.fnmatchcase(n.lower(), pat)], dtype=np.int64)


def set_scene_timing(scene: bpy.types.Scene, rate: float, first: int, last: int) -> None:
    """Scene frame rate (fps / fps_base, so non-integer rates are exact) and frame range."""
    fps = max(1, round(rate))
    scene.render.fps = fps
    scene.render.fps_base = fps / rate
    scene.frame_start = first
    scene.frame_end = max(last, first)
    scene.frame_current = first


def take_collection_name(take: Take) -> str:
    """The new take collection's name: the file's name, or ``<file> 2``, ``<file> 3``... when a take
    of that name is already in the file (never Blender's ``.001``)."""
    base = os.path.splitext(os.path.basename(take.source))[0] if take.source else "take"
    name, n = base, 1
    while name in bpy.data.collections:
        n += 1
        name = f"{base} {n}"
    return name


def check_options(options: ImportOptions) -> None:
    """Raise :class:`MocapInputError` for options that cannot import a take: a Scale of 0 or below (or
    not a number) would collapse or mirror every marker, not scale it."""
    from ..core.errors import MocapInputError

    if not (np.isfinite(options.scale) and options.scale > 0):
        raise MocapInputError(None, f"Scale must be above 0 (got {options.scale:g}); nothing imported")


def blender_frames() -> tuple[int, int]:
    """The first and last frame a Blender scene's frame range can hold (0 and 1,048,574)."""
    prop = bpy.types.Scene.bl_rna.properties["frame_start"]
    return int(prop.hard_min), int(prop.hard_max)


def check_frames(take: Take, options: ImportOptions, label: str = "") -> None:
    """Raise :class:`MocapInputError` when the Frame Offset puts any of the take's frames outside the frames
    a scene's range can hold. Blender clamps the range (and, unless negative frames are allowed in the
    Preferences, the current frame) to 0 and up: keys before frame 0 would lie outside the timeline, and
    Previous / Next, which walk from the current frame, would skip every segment there."""
    from ..core.errors import MocapInputError

    lowest, highest = blender_frames()
    offset, file_first = int(options.frame_offset), int(take.first_frame)
    first = file_first + offset
    last = first + take.n_frames - 1
    if first < lowest or last > highest:
        raise MocapInputError(label or take.source or "take",
                              f"Frame Offset {offset} puts the take at frames {first} to {last}, outside the "
                              f"frames {lowest} to {highest} a Blender scene holds; use a Frame Offset from "
                              f"{lowest - file_first} to {highest - file_first - take.n_frames + 1}; nothing imported")


def check_importable(take: Take, options: ImportOptions, label: str = "") -> np.ndarray:
    """The slots to import; raises :class:`MocapInputError` when there is nothing to import, so that
    nothing is created and the scene's rate and range stay as they were (an analog-only C3D, such as
    a force-plate recording, holds no marker point at all)."""
    from ..core.errors import MocapInputError

    label = label or take.source or "take"
    check_options(options)
    if take.n_points == 0:
        raise MocapInputError(label, "the file holds no marker points (analog data only?); nothing imported")
    if take.n_frames == 0:
        raise MocapInputError(label, "the file holds no frames (no data rows or samples); nothing imported")
    check_frames(take, options, label)
    slots = selected_points(take, options.name_filter)
    if not len(slots):
        raise MocapInputError(label, f"no point matches the Point Names pattern {options.name_filter!r} "
                                     f"(the file has {take.n_points}: {', '.join(take.names[:5])}"
                                     f"{'...' if take.n_points > 5 else ''}); nothing imported")
    if not take.valid[:, slots].any():
        raise MocapInputError(label, "no imported point has a single valid sample; nothing imported")
    return slots


def build_take(take: Take, scene: bpy.types.Scene, options: ImportOptions | None = None,
               name: str | None = None) -> bpy.types.Collection:
    """Create a collection of animated empties (or one point cloud) for ``take`` in ``scene``.

    Each sample becomes a location key at Blender frame ``first_frame + index + frame_offset``.
    No key is written inside a gap: the last key before a gap holds (CONSTANT), and the
    empty's ``hide_viewport``/``hide_render`` are keyed on during the gap, so a missing
    marker is seen as missing rather than as an invented straight line. With
    ``options.as_point_cloud`` the collection holds one point-cloud object instead
    (:func:`.pointcloud.build_cloud`): the same samples, no keys, missing ones not shown.

    The collection keeps what everything built later for the take needs to stay in the take's
    own terms: ``mocap_scale`` (Blender units per metre), ``mocap_first`` (the Blender frame of
    sample 0), ``mocap_offset`` (the import's Frame Offset: exports take it off again),
    ``mocap_units`` (the file's units, which exports write), ``mocap_rate`` and ``mocap_source``.

    Raises:
        MocapInputError: nothing to import (see :func:`check_importable`); nothing is created.

    Returns:
        the new collection, named after the take's file (see :func:`take_collection_name`).
    """
    options = options or ImportOptions()
    slots = check_importable(take, options)
    name = name or take_collection_name(take)
    collection = bpy.data.collections.new(name)
    scene.collection.children.link(collection)
    collection["mocap_source"] = take.source
    collection["mocap_rate"] = float(take.rate)
    collection["mocap_units"] = take.source_units

    collection["mocap_scale"] = float(options.scale)
    first = int(take.first_frame) + int(options.frame_offset)
    collection["mocap_first"] = first  # the Blender frame of positions[0]
    collection["mocap_offset"] = int(options.frame_offset)
    if options.as_point_cloud:
        build_cloud(take, slots, collection, options.scale, first)
    else:
        _key_slots(take, slots, collection, options.scale, np.arange(take.n_frames, dtype=np.float32) + first)
    if options.set_scene and take.n_frames:
        set_scene_timing(scene, take.rate, first, first + take.n_frames - 1)
    return collection


#: Point slots transposed together when keying: a slot's column of the (frames, points, 3)
#: positions is strided, and copying 16 at once reads the take once per 16 slots, not per slot.
SLOT_BLOCK = 16


def _key_slots(take: Take, slots: np.ndarray, collection: bpy.types.Collection, scale: float,
               frames_all: np.ndarray) -> None:
    """One keyed empty per slot of ``slots`` in ``collection`` (see :func:`build_take`)."""
    for b0 in range(0, len(slots), SLOT_BLOCK):
        block = slots[b0:b0 + SLOT_BLOCK]
        run = int(block[-1]) - int(block[0]) + 1 == len(block)  # consecutive slots: a view, one copy
        cols = take.positions[:, int(block[0]):int(block[-1]) + 1] if run else take.positions[:, block]
        tracks = np.ascontiguousarray(cols.transpose(1, 2, 0))  # (slots, 3, frames): each axis contiguous
        valid = ~np.isnan(tracks[:, 0])
        for j, slot in enumerate(block):
            obj = new_marker(free_name(take.names[slot], bpy.data.objects, collection.name), collection, scale)
            obj["mocap_slot"] = int(slot)
            obj["mocap_point"] = take.names[slot]  # the object's name may carry the take's prefix
            if not valid[j].any():
                obj.hide_viewport = obj.hide_render = True
                continue
            key_track(obj, frames_all, valid[j], tracks[j].T, action=raw_action_name(collection.name, obj.name),
                      scale=scale)


#: How the raw (imported) empties' names end once a take is labeled (``*3 (raw)``, :func:`.review._hide_raw`),
#: and their actions' names always: the labeled and unlabeled empties take the plain names.
RAW_SUFFIX = " (raw)"


def raw_action_name(take_name: str, point: str) -> str:
    """The action of a raw empty: ``<take>|<point> (raw)``. The labeled and unlabeled empties' actions are
    ``<take>|<name>`` (``take|R_IndexTip``, ``take|*3``), so a take whose file already names its points
    (``glove|back_left``) or numbers them (``*3``) as the labeling will never gets a ``.001`` action."""
    return f"{take_name}|{point}{RAW_SUFFIX}"


def _free_action_name(name: str) -> None:
    """Make ``name`` free for a new action of a take's empty (``<take>|<point>``), where it is held by
    an orphan (an action no one uses: a marker deleted by hand; it goes) or, in a scene imported before
    the raw empties' actions had their own names, by a raw empty's action (it takes its raw name)."""
    held = bpy.data.actions.get(name)
    if held is None:
        return
    if held.users == 0:
        bpy.data.actions.remove(held)
        return
    take, _, point = name.partition("|")
    coll = bpy.data.collections.get(take)
    raw = coll.get("mocap_raw") if coll is not None else None
    for obj in list(raw.objects) if raw is not None else ():
        ad = obj.animation_data
        if ad is not None and ad.action == held and obj.get("mocap_point") == point:
            held.name = raw_action_name(take, point)
            return


def file_frames(take_coll: bpy.types.Collection, take: Take) -> Take:
    """``take`` read back from the scene (frames as Blender shows them) in the file's own frame
    numbers and units again, for writing out: the import's Frame Offset is taken off."""
    import dataclasses

    return dataclasses.replace(take, first_frame=int(take.first_frame) - int(take_coll.get("mocap_offset", 0)),
                               source_units=str(take_coll.get("mocap_units", take.source_units)))


def new_marker(name: str, collection: bpy.types.Collection, scale: float = 1.0) -> bpy.types.Object:
    """A marker-sized sphere empty linked to ``collection``."""
    obj = bpy.data.objects.new(name, None)
    obj.empty_display_type = "SPHERE"
    obj.empty_display_size = MARKER_DISPLAY_SIZE * scale
    collection.objects.link(obj)
    return obj


def key_track(obj: bpy.types.Object, frames_all: np.ndarray, valid: np.ndarray, xyz: np.ndarray,
              key_types: np.ndarray | None = None, group: str = "Location", action: str | None = None,
              hold_type: str = "KEYFRAME", scale: float = 1.0) -> list:
    """Write (or rewrite) ``obj``'s location keys from one track, in bulk.

    A sample becomes a key at its frame. No key is written inside a gap: the last key before a
    gap holds (CONSTANT), and ``hide_viewport``/``hide_render`` are keyed on during the gap, so a
    missing marker is seen as missing rather than as an invented straight line.

    Args:
        frames_all: float ``(F,)``: the Blender frame of every sample index.
        valid: bool ``(F,)``: where the track has a sample.
        xyz: float ``(F, 3)``: positions (ignored where not valid), in Blender units once
            multiplied by ``scale``.
        key_types: int ``(valid.sum(),)``: keyframe type enum values of the keys, or None.
        group: channel group of new location F-curves.
        hold_type: keyframe type of the visibility keys.
        action: the name of the object's action where it has none yet (``<take>|<name>``; a raw empty's
            :func:`raw_action_name`); an orphan action holding it goes, as does an old raw empty's
            action (it takes its raw name), so that the name carries no ``.001``.
        scale: factor applied to ``xyz`` (float32, as ``xyz * scale`` would give).

    Returns:
        the three location F-curves.
    """
    if action is not None and (obj.animation_data is None or obj.animation_data.action is None):
        _free_action_name(action)
    animio.ensure_action(obj, action)
    idx = np.flatnonzero(valid)
    n = int(idx.shape[0])
    const = animio.interpolation_value("CONSTANT")
    interp = np.full(n, animio.interpolation_value("LINEAR"), dtype=np.uint8)
    # The last key before each gap holds its value instead of interpolating across the gap.
    interp[:-1][np.diff(idx) > 1] = const
    co = np.empty((3, n, 2), dtype=np.float32)  # per axis, the keys' (frame, value) pairs
    co[:, :, 0] = frames_all[idx]
    for axis, values in enumerate(xyz.T):  # a contiguous gather where xyz is a transposed (3, F) array
        co[axis, :, 1] = values[idx]
    if scale != 1.0:
        co[:, :, 1] *= np.float32(scale)
    curves = []
    for axis in range(3):
        fc = animio.find_fcurve(obj, "location", axis) or animio.new_fcurve(obj, "location", axis, group=group)
        animio.write_points(fc, co[axis], interp)
        if key_types is not None and n:
            animio.write_key_types(fc, key_types)
        curves.append(fc)
    if n:
        obj.location = co[:, 0, 1]
    if not valid.all() or animio.find_fcurve(obj, "hide_viewport") is not None:
        _key_visibility(obj, valid, frames_all, const, animio.key_type_value(hold_type))
    return curves


def _key_visibility(obj: bpy.types.Object, valid: np.ndarray, frames: np.ndarray, const: int, key_type: int) -> None:
    """Key hide_viewport/hide_render: 1 from the first missing frame of a gap, 0 when it ends."""
    change = np.flatnonzero(np.diff(valid.astype(np.int8))) + 1
    at = np.concatenate([[0], change])
    hidden = (~valid[at]).astype(np.float32)
    for path in ("hide_viewport", "hide_render"):
        fc = animio.find_fcurve(obj, path) or animio.new_fcurve(obj, path, 0, group="Visibility")
        animio.write_keys(fc, frames[at], hidden, np.full(at.shape[0], const, dtype=np.uint8))
        if key_type != animio.key_type_value("KEYFRAME"):  # new keys are plain keyframes already
            animio.write_key_types(fc, key_type)
    obj.hide_viewport = obj.hide_render = bool(hidden[0])
