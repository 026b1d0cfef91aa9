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

    first = int(take.first_frame) + int(options.frame_offset)
    frames_all = np.arange(take.n_frames, dtype=np.float32) + first
    const, linear = animio.interpolation_value("CONSTANT"), animio.interpolation_value("LINEAR")
    valid_all = take.valid
    for slot in selected_points(take, options.name_filter):
        obj = bpy.data.objects.new(take.names[slot], None)
        obj.empty_display_type = "SPHERE"
        obj.empty_display_size = MARKER_DISPLAY_SIZE * options.scale
        obj["mocap_slot"] = int(slot)
        collection.objects.link(obj)
        valid = valid_all[:, slot]
        if not valid.any():
            obj.hide_viewport = obj.hide_render = True
            continue
        animio.ensure_action(obj, f"{collection.name}|{obj.name}")
        frames = frames_all[valid]
        # The last key before each gap holds its value instead of interpolating across the gap.
        idx = np.flatnonzero(valid)
        interp = np.full(idx.shape[0], linear, dtype=np.int32)
        interp[:-1][np.diff(idx) > 1] = const
        xyz = take.positions[valid, slot] * options.scale
        for axis in range(3):
            fc = animio.new_fcurve(obj, "location", axis, group="Location")
            animio.write_keys(fc, frames, xyz[:, axis], interp)
        obj.location = xyz[0]
        if not valid.all():
            _key_visibility(obj, valid, frames_all, const)
    if options.set_scene and take.n_frames:
        set_scene_timing(scene, take.rate, first, first + take.n_frames - 1)
    return collection


def _key_visibility(obj: bpy.types.Object, valid: np.ndarray, frames: np.ndarray, const: int) -> None:
    """Key hide_viewport/hide_render: 1 from the first missing frame of a gap, 0 when it ends."""
    change = np.flatnonzero(np.diff(valid.astype(np.int8))) + 1
    at = np.concatenate([[0], change])
    hidden = (~valid[at]).astype(np.float32)
    for path in ("hide_viewport", "hide_render"):
        fc = animio.new_fcurve(obj, path, 0, group="Visibility")
        animio.write_keys(fc, frames[at], hidden, np.full(at.shape[0], const, dtype=np.int32))
