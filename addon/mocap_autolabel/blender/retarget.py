"""Retargeting in Blender: our solved rigs and a character's armature as the core's arrays, and the
core's rotations keyed onto the character.

Conversion only (the algorithm is :mod:`..core.retarget`). The character gets ONE action,
``<character>_hands``, holding the mapped bones' channels of both hands, pushed as a strip on the NLA
track :data:`TRACK`, so that an animator blends it with their body animation; their active action,
if any, stays as it was. Retargeting again replaces the action and the strip.

:func:`retarget_character` is the one entry (the operator's execute calls it, as Blender's BVH
importer calls ``load``); it raises :class:`..core.errors.MocapInputError` with a one-line message.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping, Sequence

import bpy
import numpy as np

from ..core.errors import MocapInputError
from ..core.hand.skeleton import BONE_NAMES
from ..core.retarget.source import SourceHand
from ..core.retarget.target import TargetRig
from . import animio

#: The NLA track of the character that holds the retargeted hands.
TRACK = "Mocap hands"
#: Custom property of the actions this module makes: the character's name (what replacing looks for).
ACTION_TAG = "mocap_retarget_of"
#: The panel's list holds one row per side and bone of ours.
SIDES = ("left", "right")


# --- reading Blender --------------------------------------------------------------------------------

def _matrices(collection, prop: str) -> np.ndarray:
    """``(n, 4, 4)`` float64 from a 4x4 matrix property of every item, read in bulk (Blender keeps
    matrices column by column: transposed here)."""
    n = len(collection)
    buf = np.empty(n * 16, dtype=np.float32)
    collection.foreach_get(prop, buf)
    return buf.reshape(n, 4, 4).transpose(0, 2, 1).astype(np.float64)


def target_rig(arm_obj: bpy.types.Object) -> TargetRig:
    """The character armature ``arm_obj`` at rest (``bone.matrix_local``, armature units) and its world
    matrix; bones ordered parents first (Blender's own order, kept where it already is)."""
    if arm_obj is None or arm_obj.type != "ARMATURE":
        raise MocapInputError(None, f"{getattr(arm_obj, 'name', None)!r} is not an armature")
    bones = arm_obj.data.bones
    names = [b.name for b in bones]
    parent_names = [b.parent.name if b.parent else None for b in bones]
    rest = _matrices(bones, "matrix_local")
    lengths = np.empty(len(bones), dtype=np.float32)
    bones.foreach_get("length", lengths)
    order: list[int] = []  # parents first, stable
    placed: set[str] = set()
    pending = list(range(len(names)))
    while pending:
        left = []
        for i in pending:
            if parent_names[i] is None or parent_names[i] in placed:
                order.append(i)
                placed.add(names[i])
            else:
                left.append(i)
        if len(left) == len(pending):  # cannot happen in Blender; never loop forever
            raise MocapInputError(arm_obj.name, "the armature's bone hierarchy has a cycle")
        pending = left
    index = {names[i]: k for k, i in enumerate(order)}
    return TargetRig(tuple(names[i] for i in order),
                     tuple(-1 if parent_names[i] is None else index[parent_names[i]] for i in order),
                     rest[order], lengths[order].astype(np.float64), np.array(arm_obj.matrix_world, dtype=np.float64))


def solved_rigs(scene_or_objects) -> list[bpy.types.Object]:
    """Our solved hand rigs (armatures carrying a calibration) among a scene's objects or the objects given."""
    objs = scene_or_objects.objects if isinstance(scene_or_objects, bpy.types.Scene) else scene_or_objects
    return [o for o in objs if o is not None and o.type == "ARMATURE" and "mocap_calibration" in o]


def _channels(obj: bpy.types.Object, path: str, count: int) -> list:
    return [animio.find_fcurve(obj, path, i) for i in range(count)]


def source_hand(arm_obj: bpy.types.Object) -> tuple[str, SourceHand, int] | None:
    """``(side, SourceHand, first_frame)`` of one solved rig, read from its keys in bulk (every frame
    from its first key to its last; frames no channel keys are unsolved, NaN); None without keys."""
    from ..core.hand.calibrate import Calibration

    try:
        cal = Calibration.from_dict(json.loads(arm_obj["mocap_calibration"]), arm_obj.name)
    except ValueError as exc:  # not JSON
        raise MocapInputError(arm_obj.name, f"its calibration is not readable ({exc})") from None
    hand = cal.hand()
    bones = arm_obj.data.bones
    missing = [b for b in BONE_NAMES if b not in bones]
    if missing:
        raise MocapInputError(arm_obj.name, f"not one of our solved rigs (bones {missing} are missing)")
    rest = np.array([np.array(bones[b].matrix_local, dtype=np.float64) for b in BONE_NAMES])
    curves = [_channels(arm_obj, f'pose.bones["{b}"].rotation_quaternion', 4) for b in BONE_NAMES]
    root = _channels(arm_obj, f'pose.bones["{BONE_NAMES[0]}"].location', 3)
    keys = {}
    for fc in [c for bone in curves for c in bone] + root:
        if fc is not None and len(fc.keyframe_points):
            keys[id(fc)] = animio.read_keys(fc)
    if not keys:
        return None
    first = int(np.floor(min(f[0] for f, _ in keys.values())))
    last = int(np.ceil(max(f[-1] for f, _ in keys.values())))
    frames = np.arange(first, last + 1, dtype=np.float64)
    keyed = np.zeros(len(frames), dtype=bool)
    for f, _ in keys.values():
        keyed[np.clip(np.round(f).astype(int) - first, 0, len(frames) - 1)] = True

    def channel(fc, default: float) -> np.ndarray:
        if fc is None or id(fc) not in keys:
            return np.full(len(frames), default)
        f, v = keys[id(fc)]
        return np.interp(frames, f.astype(np.float64), v.astype(np.float64))  # the keys are LINEAR

    quats = np.stack([np.stack([channel(fc, 1.0 if i == 0 else 0.0) for i, fc in enumerate(bone)], axis=-1)
                      for bone in curves], axis=1)  # (F, 20, 4)
    loc = np.stack([channel(fc, 0.0) for fc in root], axis=-1)  # (F, 3)
    quats[~keyed] = np.nan
    loc[~keyed] = np.nan
    radii = np.asarray(hand.bone_radii, dtype=np.float64)
    if radii.ndim == 2:  # the model's (proximal, distal) skin radii: SourceHand takes the distal ones
        radii = radii[:, 1]
    source = SourceHand.from_bases(cal.side, rest, quats, loc, np.asarray(hand.bone_lengths, float), radii,
                                   np.array(arm_obj.matrix_world, dtype=np.float64))
    return cal.side, source, first


def source_hands(scene_or_objects) -> list[tuple[str, SourceHand, int]]:
    """``[(side, SourceHand, first_frame)]`` of every solved rig among a scene's objects (or the objects
    given) that has keys."""
    out = []
    for obj in solved_rigs(scene_or_objects):
        found = source_hand(obj)
        if found is not None:
            out.append(found)
    return out


# --- writing Blender --------------------------------------------------------------------------------

def action_name(target_obj: bpy.types.Object) -> str:
    """The name of the character's retargeted hands' action."""
    return f"{target_obj.name}_hands"


def clear_retargeted(target_obj: bpy.types.Object) -> None:
    """Take away what an earlier retarget put on ``target_obj``: the strips of its :data:`TRACK` (the
    track stays) and the actions this module made for it that nothing else uses."""
    ad = target_obj.animation_data
    old = {a for a in bpy.data.actions if a.get(ACTION_TAG) == target_obj.name}
    if ad is not None:
        if ad.action is not None and ACTION_TAG in ad.action:  # ours made active by hand: not the body's
            ad.action = None
        track = ad.nla_tracks.get(TRACK)
        if track is not None:
            for strip in list(track.strips):
                if strip.action is not None and ACTION_TAG in strip.action:  # even of the object's old name
                    old.add(strip.action)
                track.strips.remove(strip)
    for action in old:
        if action.users == 0:
            bpy.data.actions.remove(action)


def key_retargeted(target_obj: bpy.types.Object, results: Sequence[tuple[int, object]], *,
                   name: str | None = None) -> bpy.types.Action:
    """Key every :class:`~..core.retarget.transfer.Retargeted` of ``results`` (``[(first_frame,
    Retargeted)]``, one per hand: its frame ``i`` lands on scene frame ``first_frame + i``) into ONE new
    action ``name`` (default ``<character>_hands``) holding only the mapped bones' channels, written in
    bulk, and push it as the strip of the NLA track :data:`TRACK`. An earlier retarget's action and
    strip go first (replaced, not duplicated); the character's active action and its slot stay as they
    were; bones not in ``results`` get no channel. Keyed bones are set to quaternion rotation.

    Returns the new action.
    """
    name = name or action_name(target_obj)
    ad = target_obj.animation_data or target_obj.animation_data_create()
    if ad.use_tweak_mode:
        raise MocapInputError(None, f"{target_obj.name!r} is in NLA tweak mode: leave it (Tab in the NLA editor) "
                                    "first")
    clear_retargeted(target_obj)
    action = bpy.data.actions.new(name)
    action[ACTION_TAG] = target_obj.name
    # animio writes the object's active action: make the new one active while it is written, then give
    # the body its own action (and slot) back.
    before = ad.action
    before_slot = getattr(ad, "action_slot", None) if before is not None else None
    ad.action = action
    try:
        animio.ensure_action(target_obj)
        for first, result in results:
            _write(target_obj, first, result)
    finally:
        ad.action = before
        if before is not None and before_slot is not None and getattr(ad, "action_slot", None) != before_slot:
            ad.action_slot = before_slot
    track = ad.nla_tracks.get(TRACK)
    if track is None:
        track = ad.nla_tracks.new()
        track.name = TRACK
    start = float(action.frame_range[0])
    strip = track.strips.new(name, int(np.floor(start)), action)
    if animio.SLOTTED and strip.action_slot is None:  # Blender 5.0 takes the action's one slot itself
        strip.action_slot = action.slots[0]
    strip.name = name
    strip.blend_type = "REPLACE"
    return action


def _write(target_obj: bpy.types.Object, first: int, result) -> None:
    solved = np.asarray(result.solved, dtype=bool)
    frames = (first + np.arange(len(solved), dtype=np.float64))[solved]
    if not len(frames):
        return
    rotations = np.asarray(result.rotations, dtype=np.float64)[solved]
    for i, bone in enumerate(result.bones):
        pb = target_obj.pose.bones[bone]
        pb.rotation_mode = "QUATERNION"
        path = f'pose.bones["{bpy.utils.escape_identifier(bone)}"]'
        for k in range(4):
            animio.write_keys(animio.new_fcurve(target_obj, f"{path}.rotation_quaternion", k, group=bone),
                              frames, rotations[:, i, k])
    if result.location_bone is not None and result.locations is not None:
        bone = result.location_bone
        path = f'pose.bones["{bpy.utils.escape_identifier(bone)}"]'
        locations = np.asarray(result.locations, dtype=np.float64)[solved]
        for k in range(3):
            animio.write_keys(animio.new_fcurve(target_obj, f"{path}.location", k, group=bone), frames,
                              locations[:, k])


# --- the one entry ----------------------------------------------------------------------------------

def character(context, armature=None) -> bpy.types.Object:
    """The character armature: ``armature`` (an object or its name); else the Retarget panel's; else
    the active object where it is an armature. One of our solved hands is refused."""
    if isinstance(armature, str) and armature:
        obj = bpy.data.objects.get(armature)
        if obj is None:
            raise MocapInputError(None, f"No armature named {armature!r} in the file")
        armature = obj
    if not armature:
        settings = getattr(context.scene, "mocap_autolabel", None)
        armature = settings.retarget.armature if settings is not None else None
    if not armature:
        active = context.active_object
        if active is not None and active.type == "ARMATURE":
            armature = active  # our own solved hand is refused below, by name
    if not armature:
        raise MocapInputError(None, "No character armature: pick one in the Retarget panel or make it the active "
                                    "object")
    if armature.type != "ARMATURE":
        raise MocapInputError(None, f"{armature.name!r} is not an armature: pick the character's armature")
    if "mocap_calibration" in armature:
        raise MocapInputError(None, f"{armature.name!r} is a solved hand: pick the character's armature")
    return armature


def _sources(context, sources) -> list[tuple[str, SourceHand, int]]:
    """The hands to retarget: ``sources`` (our rigs, or ``(side, SourceHand, first_frame)``), else the
    solved rigs selected, else those of the take in the panel's Take field, else every solved rig of
    the scene; where a side has several, the selected ones."""
    if sources is None:
        rigs = _rigs_in_view(context)
        by_side: dict[str, list] = {}
        for obj in rigs:
            by_side.setdefault(json.loads(obj["mocap_calibration"]).get("side"), []).append(obj)
        chosen = []
        for side, objs in by_side.items():
            if len(objs) > 1:
                picked = [o for o in objs if o.select_get()]
                if len(picked) != 1:
                    names = ", ".join(o.name for o in objs)
                    raise MocapInputError(None, f"{len(objs)} solved {side} hands in the scene ({names}): select "
                                                "the one to retarget")
                objs = picked
            chosen += objs
        hands = source_hands(chosen)
    else:
        items = list(sources)
        hands = [s for s in items if isinstance(s, tuple)]
        hands += source_hands([o for o in items if not isinstance(o, tuple)])
    if not hands:
        raise MocapInputError(None, "No solved hand in the scene: run Solve Hand on a labeled take first")
    sides = [side for side, _, _ in hands]
    if len(set(sides)) != len(sides):
        raise MocapInputError(None, f"two solved hands of one side ({', '.join(sorted(sides))}): give one a side")
    return hands


def _rigs_in_view(context) -> list:
    """The solved rigs a retarget means: the selected ones, else the panel's take's (two takes in a
    scene are never mixed onto one character), else the scene's."""
    rigs = solved_rigs(context.scene)
    picked = [o for o in rigs if o.select_get()]
    if picked:
        return picked
    settings = getattr(context.scene, "mocap_autolabel", None)
    take = getattr(settings, "take", None)
    if take is not None:
        own = {take.name, f"{take.name}:left", f"{take.name}:right"}
        mine = [o for o in rigs if any(c.get("mocap_solved_from") in own for c in o.users_collection)]
        if mine:
            return mine
    return rigs


def _as_bone_map(bone_map, rig: TargetRig):
    if hasattr(bone_map, "sides"):  # a BoneMap
        return bone_map
    from ..core.retarget.bone_maps import BoneMap, auto_map

    if bone_map is None:
        return auto_map(list(rig.names), list(rig.parents))
    if isinstance(bone_map, Mapping):  # {side: {ours: theirs}}
        return BoneMap("custom", {side: dict(m) for side, m in bone_map.items()})
    raise TypeError(f"bone_map must be a BoneMap, a dict or None, not {type(bone_map).__name__}")


def retarget_character(context, *, armature=None, bone_map=None, reference: str | int = "rest",
                       wrist: str = "fingers", pinch: bool = False, sources=None) -> dict:
    """Key the scene's solved hands onto the character ``armature`` (see :func:`character`).

    Args:
        bone_map: a :class:`~..core.retarget.bone_maps.BoneMap` (or ``{side: {our bone: theirs}}``);
            None: :func:`~..core.retarget.bone_maps.auto_map` of the armature's bones.
        reference: ``"rest"`` (our hand posed like the character's rest), or a scene frame whose solved
            pose is the character's rest pose.
        wrist, pinch: as :func:`~..core.retarget.transfer.retarget`.
        sources: our solved rigs (objects) or ``(side, SourceHand, first_frame)``; None: the scene's.

    Returns:
        facts for the report: the armature, the action and track, the map's convention, and per side
        the bones keyed, the frames, and the core's facts.

    Raises:
        MocapInputError: one line for the user (no armature, no solved hand, a side not mapped...).
    """
    from ..core.retarget.transfer import WRIST_MODES, retarget

    if wrist not in WRIST_MODES:
        raise MocapInputError(None, f"wrist must be one of {', '.join(WRIST_MODES)}, not {wrist!r}")
    arm = character(context, armature)
    hands = _sources(context, sources)
    rig = target_rig(arm)
    bmap = _as_bone_map(bone_map, rig)
    results, facts = [], {}
    for side, source, first in sorted(hands, key=lambda h: h[0]):
        mapped = {ours: theirs for ours, theirs in (bmap.sides.get(side) or {}).items() if theirs}
        if "palm" not in mapped or len(mapped) < 2:
            raise MocapInputError(None, f"The {side} hand is not mapped on {arm.name!r}: map its hand bone and "
                                        "fingers in the Retarget panel (Auto-Map, or pick them)")
        ref = reference
        if not isinstance(reference, str):
            ref = int(reference) - first
            if not (0 <= ref < source.frames):
                raise MocapInputError(None, f"Reference frame {int(reference)} is outside the solved {side} hand "
                                            f"(frames {first}-{first + source.frames - 1})")
        try:
            result = retarget(source, rig, mapped, reference=ref, wrist=wrist, pinch=pinch)
        except MocapInputError as exc:
            raise MocapInputError(None, f"{side} hand onto {arm.name!r}: {exc}") from None
        results.append((first, result))
        facts[side] = {"bones": list(result.bones), "frames": int(np.count_nonzero(result.solved)),
                       "first_frame": first, **result.facts}
    action = key_retargeted(arm, results)
    return {"armature": arm.name, "action": action.name, "track": TRACK, "convention": bmap.convention,
            "hands": facts}


# --- the panel's editable map and its presets --------------------------------------------------------

def fill_map(settings, arm_obj: bpy.types.Object | None, bone_map=None) -> None:
    """The panel's list (``settings``: the scene's Retarget settings) from ``bone_map`` (None: the
    automatic map of ``arm_obj``): one row per side and bone of ours, their bone empty where unmapped."""
    rows = settings.bone_map
    rows.clear()
    settings.map_armature = arm_obj.name if arm_obj is not None else ""
    if arm_obj is None or arm_obj.type != "ARMATURE":
        settings.convention = ""
        return
    if bone_map is None:
        bone_map = _as_bone_map(None, target_rig(arm_obj))
    settings.convention = bone_map.convention
    for side in SIDES:
        mapped = bone_map.sides.get(side) or {}
        for ours in BONE_NAMES:
            row = rows.add()
            row.side, row.ours = side, ours
            theirs = mapped.get(ours) or ""
            row.theirs = theirs if theirs in arm_obj.data.bones else ""
    settings.bone_map_index = -1


def list_map(settings):
    """The panel's list as a :class:`~..core.retarget.bone_maps.BoneMap` (rows with their bone set)."""
    from ..core.retarget.bone_maps import BoneMap

    sides: dict[str, dict[str, str]] = {}
    for row in settings.bone_map:
        if row.theirs:
            sides.setdefault(row.side, {})[row.ours] = row.theirs
    return BoneMap(settings.convention or "custom", sides)


def panel_bone_map(scene: bpy.types.Scene, arm_obj: bpy.types.Object):
    """The panel's edited map where it was made for ``arm_obj``, else None (the automatic one then)."""
    settings = scene.mocap_autolabel.retarget
    if arm_obj is None or not settings.bone_map or settings.map_armature != arm_obj.name:
        return None
    return list_map(settings)


def preset_folder() -> str:
    """The folder of the bone-map presets (JSON) in the user's Blender config folder."""
    return bpy.utils.user_resource("CONFIG", path=os.path.join("mocap_autolabel", "bone_maps"), create=True)


def preset_path(name: str) -> str:
    """The file of the preset ``name`` (characters a file name cannot hold become ``_``)."""
    clean = re.sub(r"[^\w \-.]", "_", name.strip()).strip(". ")
    if not clean:
        raise MocapInputError(None, "Give the preset a name")
    return os.path.join(preset_folder(), f"{clean}.json")


def presets() -> list[str]:
    """The names of the saved bone-map presets, sorted."""
    folder = preset_folder()
    return sorted(f[:-5] for f in os.listdir(folder) if f.endswith(".json")) if os.path.isdir(folder) else []


def save_preset(settings, name: str) -> str:
    """Save the panel's list as the preset ``name``; its path."""
    bone_map = list_map(settings)
    if not any(bone_map.sides.values()):
        raise MocapInputError(None, "The bone map is empty: pick an armature and map its bones first")
    path = preset_path(name)
    bone_map.save(path)
    return path


def load_preset(settings, arm_obj: bpy.types.Object, name: str) -> list[str]:
    """Put the preset ``name`` in the panel's list for ``arm_obj``; the preset's bones the armature lacks
    (left unmapped)."""
    from ..core.retarget.bone_maps import BoneMap

    path = preset_path(name)
    if not os.path.exists(path):
        raise MocapInputError(path, "no such bone-map preset")
    try:
        bone_map = BoneMap.load(path)
    except MocapInputError:
        raise
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise MocapInputError(path, f"not a readable bone map ({exc})") from None
    fill_map(settings, arm_obj, bone_map)
    return sorted({t for m in bone_map.sides.values() for t in m.values() if t and t not in arm_obj.data.bones})


def describe(facts: Mapping) -> str:
    """One line for the report of :func:`retarget_character`'s facts."""
    parts = []
    for side, f in facts["hands"].items():
        text = f"{side} hand: {len(f['bones'])} bones x {f['frames']} frames"
        pinch = f.get("pinch")
        if isinstance(pinch, Mapping) and pinch.get("frames"):
            text += f", {pinch['frames']} pinch frames kept"
        parts.append(text)
    return (f"Retargeted onto {facts['armature']} ({facts['convention']}): " + "; ".join(parts)
            + f" - action {facts['action']} on NLA track '{facts['track']}'")

