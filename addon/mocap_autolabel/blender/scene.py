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


def build_take(take: Take, scene: bpy.types.Scene, options: ImportOptions | None = None,
               name: str | None = None) -> bpy.types.Collection:
    """Create a collection of animated empties for ``take`` in ``scene``.

    Each sample becomes a location key at Blender frame ``first_frame + index + frame_offset``.
    No key is written inside a gap: the last key before a gap holds (CONSTANT), and the
    empty's ``hide_viewport``/``hide_render`` are keyed on during the gap, so a missing
    marker is seen as missing rather than as an invented straight line.

    Returns:
        the new collection, named after the take's file (Blender adds .001 if taken).
    """
    options = options or ImportOptions()
    name = name or (os.path.splitext(os.path.basename(take.source))[0] if take.source else "take")
    collection = bpy.data.collections.new(name)
    scene.collection.children.link(collection)
    collection["mocap_source"] = take.source
    collection["mocap_rate"] = float(take.rate)

    collection["mocap_scale"] = float(options.scale)
    first = int(take.first_frame) + int(options.frame_offset)
    collection["mocap_first"] = first  # the Blender frame of positions[0]
    frames_all = np.arange(take.n_frames, dtype=np.float32) + first
    valid_all = take.valid
    for slot in selected_points(take, options.name_filter):
        obj = new_marker(take.names[slot], collection, options.scale)
        obj["mocap_slot"] = int(slot)
        obj["mocap_point"] = take.names[slot]  # the object's name may get a .001
        valid = valid_all[:, slot]
        if not valid.any():
            obj.hide_viewport = obj.hide_render = True
            continue
        key_track(obj, frames_all, valid, take.positions[:, slot] * options.scale,
                  action=f"{collection.name}|{obj.name}")
    if options.set_scene and take.n_frames:
        set_scene_timing(scene, take.rate, first, first + take.n_frames - 1)
    return collection


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
