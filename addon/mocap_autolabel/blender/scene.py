"""Turn a Take into Blender data: one animated empty per point slot."""

from __future__ import annotations

import fnmatch
import os
from dataclasses import dataclass

import bpy
import numpy as np

from ..core.take import Take
from . import animio

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
    """

    scale: float = 1.0
    frame_offset: int = 0
    name_filter: str = "*"
    set_scene: bool = True


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


def free_name(wanted: str, datablocks, owner: str, current=None) -> str:
    """A name for a datablock of a take that clashes with no other: ``wanted`` while it is free in
    ``datablocks`` (``bpy.data.objects``, ``bpy.data.collections``...), else ``<owner>:<wanted>``.

    Blender names are unique per file and it would append ``.001`` to the second ``IndexTip`` or
    ``Labeled``: that hides which take an object belongs to, and a script looking for
    ``IndexTip`` finds the wrong one. The first take in a scene keeps the plain names; a later
    take whose names are taken gets its collection's name as a prefix (``take2:IndexTip``, the
    subject-prefix style capture software writes). ``current`` is the datablock being renamed,
    which may already hold the name.
    """
    held = datablocks.get(wanted)
    if held is None or held == current:
        return wanted
    return f"{owner}:{wanted}"


def take_collection_name(take: Take) -> str:
    """The new take collection's name: the file's name, or ``<file> 2``, ``<file> 3``... when a take
    of that name is already in the file (never Blender's ``.001``)."""
    base = os.path.splitext(os.path.basename(take.source))[0] if take.source else "take"
    name, n = base, 1
    while name in bpy.data.collections:
        n += 1
        name = f"{base} {n}"
    return name


def check_importable(take: Take, options: ImportOptions, label: str = "") -> np.ndarray:
    """The slots to import; raises :class:`MocapInputError` when there is nothing to import, so that
    nothing is created and the scene's rate and range stay as they were (an analog-only C3D, such as
    a force-plate recording, holds no marker point at all)."""
    from ..core.errors import MocapInputError

    label = label or take.source or "take"
    if take.n_points == 0 or take.n_frames == 0:
        raise MocapInputError(label, "the file holds no marker points (analog data only?); nothing imported")
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
    """Create a collection of animated empties for ``take`` in ``scene``.

    Each sample becomes a location key at Blender frame ``first_frame + index + frame_offset``.
    No key is written inside a gap: the last key before a gap holds (CONSTANT), and the
    empty's ``hide_viewport``/``hide_render`` are keyed on during the gap, so a missing
    marker is seen as missing rather than as an invented straight line.

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
    frames_all = np.arange(take.n_frames, dtype=np.float32) + first
    valid_all = take.valid
    for slot in slots:
        obj = new_marker(free_name(take.names[slot], bpy.data.objects, collection.name), collection, options.scale)
        obj["mocap_slot"] = int(slot)
        obj["mocap_point"] = take.names[slot]  # the object's name may carry the take's prefix
        valid = valid_all[:, slot]
        if not valid.any():
            obj.hide_viewport = obj.hide_render = True
            continue
        key_track(obj, frames_all, valid, take.positions[:, slot] * options.scale,
                  action=f"{collection.name}|{obj.name}")
    if options.set_scene and take.n_frames:
        set_scene_timing(scene, take.rate, first, first + take.n_frames - 1)
    return collection


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
              hold_type: str = "KEYFRAME") -> list:
    """Write (or rewrite) ``obj``'s location keys from one track, in bulk.

    A sample becomes a key at its frame. No key is written inside a gap: the last key before a
    gap holds (CONSTANT), and ``hide_viewport``/``hide_render`` are keyed on during the gap, so a
    missing marker is seen as missing rather than as an invented straight line.

    Args:
        frames_all: float ``(F,)``: the Blender frame of every sample index.
        valid: bool ``(F,)``: where the track has a sample.
        xyz: float ``(F, 3)``: positions in Blender units (ignored where not valid).
        key_types: int ``(valid.sum(),)``: keyframe type enum values of the keys, or None.
        group: channel group of new location F-curves.
        hold_type: keyframe type of the visibility keys.

    Returns:
        the three location F-curves.
    """
    animio.ensure_action(obj, action)
    idx = np.flatnonzero(valid)
    const = animio.interpolation_value("CONSTANT")
    interp = np.full(idx.shape[0], animio.interpolation_value("LINEAR"), dtype=np.int32)
    # The last key before each gap holds its value instead of interpolating across the gap.
    interp[:-1][np.diff(idx) > 1] = const
    curves = []
    for axis in range(3):
        fc = animio.find_fcurve(obj, "location", axis) or animio.new_fcurve(obj, "location", axis, group=group)
        animio.write_keys(fc, frames_all[idx], xyz[idx, axis], interp)
        if key_types is not None and len(idx):
            fc.keyframe_points.foreach_set("type", np.asarray(key_types, dtype=np.int32))
        curves.append(fc)
    if len(idx):
        obj.location = xyz[idx[0]]
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
        animio.write_keys(fc, frames[at], hidden, np.full(at.shape[0], const, dtype=np.int32))
        fc.keyframe_points.foreach_set("type", np.full(at.shape[0], key_type, dtype=np.int32))
    obj.hide_viewport = obj.hide_render = bool(hidden[0])
