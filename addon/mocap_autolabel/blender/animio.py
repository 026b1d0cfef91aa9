"""Bulk F-curve writing and reading that works on Blender 4.2 through 5.x.

Blender 4.4 introduced slotted (layered) actions and 5.0 removed ``action.fcurves``; this
module is the only place that knows. Keys are always written in bulk with ``foreach_set``:
per-key insertion takes minutes on a real take and grows quadratically.
"""

from __future__ import annotations

import bpy
import numpy as np

_INTERPOLATION = {item.identifier: item.value
                  for item in bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items}
_KEY_TYPE = {item.identifier: item.value for item in bpy.types.Keyframe.bl_rna.properties["type"].enum_items}

#: True on Blender 4.4+, where actions have slots, layers and channel bags.
SLOTTED = hasattr(bpy.types, "ActionSlot")


def key_type_value(name: str) -> int:
    """Enum value of a keyframe type ('KEYFRAME', 'EXTREME', ...); they are not in display order."""
    return _KEY_TYPE[name]


def ensure_action(obj: bpy.types.Object, name: str | None = None) -> bpy.types.Action:
    """The object's action, created (with a slot on 4.4+) if it has none."""
    ad = obj.animation_data or obj.animation_data_create()
    if ad.action is None:
        ad.action = bpy.data.actions.new(name or f"{obj.name}Action")
    if SLOTTED and ad.action_slot is None:
        action = ad.action
        slot = action.slots.new(id_type="OBJECT", name=obj.name)
        ad.action_slot = slot
    return ad.action


def _channelbag(obj: bpy.types.Object, create: bool):
    ad = obj.animation_data
    action = ad.action
    if not action.layers:
        if not create:
            return None
        action.layers.new("Layer")
    layer = action.layers[0]
    if not layer.strips:
        if not create:
            return None
        layer.strips.new(type="KEYFRAME")
    return layer.strips[0].channelbag(ad.action_slot, ensure=create)


def fcurves_of(obj: bpy.types.Object):
    """The F-curve collection animating ``obj`` (empty tuple if it has no animation)."""
    ad = obj.animation_data
    if ad is None or ad.action is None:
        return ()
    if SLOTTED:
        bag = _channelbag(obj, create=False)
        return bag.fcurves if bag is not None else ()
    return ad.action.fcurves


def new_fcurve(obj: bpy.types.Object, data_path: str, index: int = 0, group: str | None = None):
    """Create an F-curve on ``obj``'s action (which ``ensure_action`` must have made)."""
    if SLOTTED:
        bag = _channelbag(obj, create=True)
        fc = bag.fcurves.new(data_path, index=index)
        if group:
            grp = bag.groups.get(group) or bag.groups.new(group)
            fc.group = grp
        return fc
    return obj.animation_data.action.fcurves.new(data_path, index=index, action_group=group or "")


def find_fcurve(obj: bpy.types.Object, data_path: str, index: int = 0):
    """The F-curve of ``obj`` for ``data_path[index]``, or None."""
    for fc in fcurves_of(obj):
        if fc.data_path == data_path and fc.array_index == index:
            return fc
    return None


def write_keys(fcurve, frames: np.ndarray, values: np.ndarray, interpolation: np.ndarray | str = "LINEAR") -> None:
    """Replace the keys of ``fcurve`` with (frames, values) in one bulk write.

    ``fcurve.update()`` (sorting and handle recalculation, over half the cost) runs only when
    Bezier keys are written: the frames must be increasing, and LINEAR/CONSTANT keys are
    evaluated without their handles, which Blender recalculates when a user edits keys.

    Args:
        frames: float ``(n,)`` Blender frame numbers, strictly increasing.
        values: float ``(n,)``.
        interpolation: one name for all keys, or int ``(n,)`` enum values (``interpolation_value``).
    """
    co = np.empty((int(frames.shape[0]), 2), dtype=np.float32)
    co[:, 0] = frames
    co[:, 1] = values
    write_points(fcurve, co, interpolation)


def write_points(fcurve, co: np.ndarray, interpolation: np.ndarray | str = "LINEAR") -> None:
    """:func:`write_keys` from the keys' (frame, value) pairs: float32 ``(n, 2)``, C-contiguous.

    Where the time goes (bpy 5.0.1, per million keys): ``co`` about 30 ms (Blender sets it key by
    key through its RNA setter; float32 is the cheapest buffer), ``keyframe_points.add`` about 5 ms
    (more where the memory is new to the process), the interpolation 3 ms from a uint8 buffer
    (30 ms from int32: enum properties take Blender's fast copy path only from uint8).
    """
    n = int(co.shape[0])
    points = fcurve.keyframe_points
    if len(points):
        points.clear()
    if n == 0:
        return
    points.add(n)
    points.foreach_set("co", np.ascontiguousarray(co, dtype=np.float32).reshape(-1))
    if isinstance(interpolation, str):
        interp = np.full(n, _INTERPOLATION[interpolation], dtype=np.uint8)
    else:
        interp = np.asarray(interpolation, dtype=np.uint8)
    points.foreach_set("interpolation", interp)
    if (interp == _INTERPOLATION["BEZIER"]).any():
        fcurve.update()


def write_key_types(fcurve, types: np.ndarray | int) -> None:
    """Set the keyframe type of every key of ``fcurve`` in bulk (one enum value for all, or one a key)."""
    n = len(fcurve.keyframe_points)
    buf = np.full(n, types, dtype=np.uint8) if np.ndim(types) == 0 else np.asarray(types, dtype=np.uint8)
    fcurve.keyframe_points.foreach_set("type", buf)


def interpolation_value(name: str) -> int:
    """Enum value of an interpolation mode ('CONSTANT', 'LINEAR', 'BEZIER')."""
    return _INTERPOLATION[name]


def read_keys(fcurve) -> tuple[np.ndarray, np.ndarray]:
    """(frames, values) of all keys of ``fcurve`` as float32 arrays, read in bulk."""
    n = len(fcurve.keyframe_points)
    co = np.empty(2 * n, dtype=np.float32)
    fcurve.keyframe_points.foreach_get("co", co)
    return co[0::2].copy(), co[1::2].copy()


def read_key_types(fcurve) -> np.ndarray:
    """int ``(n,)``: the keyframe type enum value of every key, read in bulk."""
    n = len(fcurve.keyframe_points)
    types = np.empty(n, dtype=np.uint8)
    fcurve.keyframe_points.foreach_get("type", types)
    return types.astype(np.int32)
