"""Character armatures to retarget onto, built in the bpy module: one per rig convention, and variants.

Every builder returns a :class:`Character`: the armature object, the bone map a correct automatic map
must find (``{side: {our bone: their bone}}``), and, for the rigs built from our hand model, where our
hand frame lies in the character's armature space (what the tests compare in).

The Mixamo, UE5 and Unity rigs get their hands from OUR hand model's rest (``HandModel.rest``, both
sides, scaled into the rig's units): the same bone directions and joint places as our solved rig,
turned into the convention's arm pose, with the convention's bone names and a typical bone roll.
Variants change that rest: the fingers curled (flexion at every finger and thumb joint, so the rest
is ``HandModel.forward`` of a curled pose), every hand bone rolled about its own axis, or longer
fingers (``HandModel(bone_scale=...)``). The Rigify meta-rig's rest is Rigify's own.

bpy is imported inside the builders (as the other test helpers take it in): importing this module
needs no Blender.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from mocap_autolabel.core.hand.skeleton import BONE_NAMES, DOF_INDEX, FINGERS, PARENTS, HandModel
from mocap_autolabel.core.rotations import rot_y

SIDES = ("left", "right")

#: Our hand frame (x, y, z columns) in a T-pose armature: the fingers along the arm (+x on the left,
#: -x on the right), the back of the hand up (+z), so the thumb points forward (-y), as a character
#: facing -y holds it.
T_POSE = {"left": np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]]),
          "right": np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])}


@dataclass
class Character:
    """A test character: ``obj`` its armature object; ``bones`` ``{side: {our bone: their bone}}`` the
    map its convention implies; ``hand_frame`` ``{side: (3, 3)}`` our hand frame's axes in armature
    space at rest (None where the rest is not ours, as Rigify's); ``roll_deg`` the hand bones' roll
    about their own axes from ours; ``extra`` finger bones no bone of ours maps (end bones)."""

    obj: object
    convention: str
    bones: dict[str, dict[str, str]]
    hand_frame: dict[str, np.ndarray] | None = None
    roll_deg: float = 0.0
    extra: list[str] = field(default_factory=list)


# --- the conventions' bone names -------------------------------------------------------------------

def _mixamo(side: str) -> tuple[dict[str, str], dict[str, str], list[tuple[str, str]]]:
    """(our bone -> theirs, end bones ``{theirs: parent}``, body chain ``[(bone, parent)]``)."""
    s = "Left" if side == "left" else "Right"
    p = f"mixamorig:{s}"
    names = {"palm": f"{p}Hand", "thumb_meta": f"{p}HandThumb1", "thumb_prox": f"{p}HandThumb2",
             "thumb_dist": f"{p}HandThumb3"}
    ends = {f"{p}HandThumb4": f"{p}HandThumb3"}
    for f, theirs in zip(FINGERS, ("Index", "Middle", "Ring", "Pinky")):
        for k, seg in enumerate(("prox", "mid", "dist")):
            names[f"{f}_{seg}"] = f"{p}Hand{theirs}{k + 1}"
        ends[f"{p}Hand{theirs}4"] = f"{p}Hand{theirs}3"
    arm = [(f"{p}Shoulder", "mixamorig:Spine2"), (f"{p}Arm", f"{p}Shoulder"), (f"{p}ForeArm", f"{p}Arm")]
    return names, ends, arm


def _ue5(side: str):
    s = "l" if side == "left" else "r"
    names = {"palm": f"hand_{s}", "thumb_meta": f"thumb_01_{s}", "thumb_prox": f"thumb_02_{s}",
             "thumb_dist": f"thumb_03_{s}"}
    for f, theirs in zip(FINGERS, ("index", "middle", "ring", "pinky")):
        names[f"{f}_meta"] = f"{theirs}_metacarpal_{s}"
        for k, seg in enumerate(("prox", "mid", "dist")):
            names[f"{f}_{seg}"] = f"{theirs}_0{k + 1}_{s}"
    arm = [(f"clavicle_{s}", "spine_05"), (f"upperarm_{s}", f"clavicle_{s}"), (f"lowerarm_{s}", f"upperarm_{s}")]
    return names, {}, arm


def _unity(side: str):
    s = "Left" if side == "left" else "Right"
    names = {"palm": f"{s}Hand", "thumb_meta": f"{s}ThumbProximal", "thumb_prox": f"{s}ThumbIntermediate",
             "thumb_dist": f"{s}ThumbDistal"}
    for f, theirs in zip(FINGERS, ("Index", "Middle", "Ring", "Little")):
        for seg, part in zip(("prox", "mid", "dist"), ("Proximal", "Intermediate", "Distal")):
            names[f"{f}_{seg}"] = f"{s}{theirs}{part}"
    arm = [(f"{s}Shoulder", "UpperChest"), (f"{s}UpperArm", f"{s}Shoulder"), (f"{s}LowerArm", f"{s}UpperArm")]
    return names, {}, arm


#: Per convention: the bone namer, the body's spine ``[(bone, parent)]`` (head and tail in metres, at a
#: 1.8 m character), the armature unit in metres, the arm's angle below the horizontal (degrees), the
#: hand bones' roll from ours (degrees), and the object's rotation about z (degrees).
CONVENTIONS = {
    "mixamo": dict(names=_mixamo, unit=0.01, arm_drop=0.0, roll=0.0, turn=0.0,
                   spine=[("mixamorig:Hips", None, (0, 0, 1.0), (0, 0, 1.1)),
                          ("mixamorig:Spine", "mixamorig:Hips", (0, 0, 1.1), (0, 0, 1.22)),
                          ("mixamorig:Spine1", "mixamorig:Spine", (0, 0, 1.22), (0, 0, 1.34)),
                          ("mixamorig:Spine2", "mixamorig:Spine1", (0, 0, 1.34), (0, 0, 1.46)),
                          ("mixamorig:Neck", "mixamorig:Spine2", (0, 0, 1.46), (0, 0, 1.58)),
                          ("mixamorig:Head", "mixamorig:Neck", (0, 0, 1.58), (0, 0, 1.8))]),
    "ue5": dict(names=_ue5, unit=1.0, arm_drop=45.0, roll=90.0, turn=90.0,
                spine=[("root", None, (0, 0, 0), (0, 0.2, 0)), ("pelvis", "root", (0, 0, 1.0), (0, 0, 1.1)),
                       ("spine_01", "pelvis", (0, 0, 1.1), (0, 0, 1.2)),
                       ("spine_05", "spine_01", (0, 0, 1.2), (0, 0, 1.46)),
                       ("neck_01", "spine_05", (0, 0, 1.46), (0, 0, 1.58)),
                       ("head", "neck_01", (0, 0, 1.58), (0, 0, 1.8))]),
    "unity": dict(names=_unity, unit=1.0, arm_drop=0.0, roll=180.0, turn=0.0,
                  spine=[("Hips", None, (0, 0, 1.0), (0, 0, 1.1)), ("Spine", "Hips", (0, 0, 1.1), (0, 0, 1.22)),
                         ("Chest", "Spine", (0, 0, 1.22), (0, 0, 1.34)),
                         ("UpperChest", "Chest", (0, 0, 1.34), (0, 0, 1.46)),
                         ("Neck", "UpperChest", (0, 0, 1.46), (0, 0, 1.58)),
                         ("Head", "Neck", (0, 0, 1.58), (0, 0, 1.8))]),
}

#: The curled variant's flexion at every finger joint (MCP, PIP, DIP) and the thumb's MCP and IP.
CURL_DEG = 35.0
#: The longer-fingers variant: every phalanx (fingers and thumb) this much longer than ours.
LONGER = 1.2


def _hand_rest(side: str, curl_deg: float, finger_scale: float,
               size: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Our hand model's rest at ``size`` (length, breadth in metres), possibly curled or with longer
    phalanges: rotations ``(20, 3, 3)``, heads ``(20, 3)`` (hand frame, metres) and lengths ``(20,)``."""
    scale = np.ones(20)
    for b, name in enumerate(BONE_NAMES):
        if name.endswith(("_prox", "_mid", "_dist")):
            scale[b] = finger_scale
    hand = HandModel(length=size[0], breadth=size[1], side=side, bone_scale=tuple(scale))
    pose = np.zeros(26)
    for joint in [f"{f}_{j}" for f in FINGERS for j in ("mcp_flex", "pip", "dip")] + ["thumb_mcp", "thumb_ip"]:
        pose[DOF_INDEX[joint]] = np.radians(curl_deg)
    rot, pos = hand.forward(pose, world=False)
    return rot[0], pos[0], np.asarray(hand.bone_lengths)


def _arm_frame(side: str, drop_deg: float) -> np.ndarray:
    """Our hand frame in the armature for an arm ``drop_deg`` below the horizontal (a T-pose at 0)."""
    sign = 1.0 if side == "left" else -1.0
    a = np.radians(drop_deg) * sign  # about +y: the left arm's +x end goes down for a positive angle
    turn = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    return turn @ T_POSE[side]


def _edit_bone(arm, name: str, matrix: np.ndarray, length: float, parent: str | None):
    from mathutils import Matrix

    eb = arm.edit_bones.new(name)
    eb.head = (0.0, 0.0, 0.0)
    eb.tail = (0.0, float(length), 0.0)
    eb.matrix = Matrix(matrix.tolist())
    if parent is not None:
        eb.parent = arm.edit_bones[parent]
    return eb


def _segment(arm, name: str, head, tail, parent: str | None, unit: float) -> None:
    eb = arm.edit_bones.new(name)
    eb.head = tuple(np.asarray(head, float) / unit)
    eb.tail = tuple(np.asarray(tail, float) / unit)
    if parent is not None:
        eb.parent = arm.edit_bones[parent]


def build_character(bpy, convention: str, *, name: str | None = None, curl_deg: float = 0.0,
                    roll_deg: float = 0.0, finger_scale: float = 1.0,
                    hand_size: tuple[float, float] = (0.19, 0.082)) -> Character:
    """A character of ``convention`` (``mixamo``, ``ue5``, ``unity``): a spine, both arms and both hands,
    the hands' rest from our hand model of ``hand_size`` (length, breadth, metres: give the solved
    hand's for the bone directions of our rig; see the module's docstring) laid along the arms, in the
    convention's units; variants: ``curl_deg`` flexion at every finger joint, ``roll_deg`` more roll on
    every hand bone, ``finger_scale`` longer phalanges."""
    spec = CONVENTIONS[convention]
    unit = spec["unit"]
    name = name or f"{convention}_character"
    arm = bpy.data.armatures.new(name)
    obj = bpy.data.objects.new(name, arm)
    bpy.context.scene.collection.objects.link(obj)
    obj.scale = (unit, unit, unit)
    obj.rotation_euler = (0.0, 0.0, np.radians(spec["turn"]))
    view_layer = bpy.context.view_layer
    previous = view_layer.objects.active
    view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    for bone, parent, head, tail in spec["spine"]:
        _segment(arm, bone, head, tail, parent, unit)
    roll = spec["roll"] + roll_deg
    twist = rot_y(np.radians(roll))
    bones, frames, extra = {}, {}, []
    for side in SIDES:
        names, ends, chain = spec["names"](side)
        g = _arm_frame(side, spec["arm_drop"])
        along = g[:, 1]  # the arm's direction
        shoulder = np.array([0.03 * (1 if side == "left" else -1), 0.0, 1.44])
        joints = [shoulder, shoulder + 0.15 * along, shoulder + 0.43 * along, shoulder + 0.69 * along]
        for (bone, parent), head, tail in zip(chain, joints[:-1], joints[1:]):
            _segment(arm, bone, head, tail, parent, unit)
        wrist = joints[-1]
        rot, heads, lengths = _hand_rest(side, curl_deg, finger_scale, hand_size)
        for b, ours in enumerate(BONE_NAMES):
            if ours not in names:
                continue
            p = PARENTS[b]
            while p >= 0 and BONE_NAMES[p] not in names:  # a convention without metacarpals
                p = PARENTS[p]
            parent = names[BONE_NAMES[p]] if p >= 0 else chain[-1][0]
            m = np.eye(4)
            m[:3, :3] = g @ rot[b] @ twist
            m[:3, 3] = (wrist + g @ heads[b]) / unit
            _edit_bone(arm, names[ours], m, lengths[b] / unit, parent)
        for end, parent in ends.items():  # Mixamo's end bones: beyond the tip, a fifth of the last bone
            last = next(o for o, t in names.items() if t == parent)
            b = BONE_NAMES.index(last)
            m = np.eye(4)
            m[:3, :3] = g @ rot[b] @ twist
            m[:3, 3] = (wrist + g @ (heads[b] + rot[b][:, 1] * lengths[b])) / unit
            _edit_bone(arm, end, m, 0.2 * lengths[b] / unit, parent)
            extra.append(end)
        bones[side] = names
        frames[side] = g
    bpy.ops.object.mode_set(mode="OBJECT")
    view_layer.objects.active = previous
    for pb in obj.pose.bones:  # the importers' default; retargeting must cope with others too
        pb.rotation_mode = "XYZ" if convention == "unity" else "QUATERNION"
    return Character(obj, convention, bones, frames, roll_deg, extra)


def mixamo_character(bpy, **variant) -> Character:
    """A Mixamo character (``mixamorig:`` names, no finger metacarpals, ``*4`` end bones beyond the
    tips), in centimetres with object scale 0.01, T-pose; its hands' rest is our hand model's rest
    (see :func:`build_character` for the variants)."""
    return build_character(bpy, "mixamo", **variant)


def ue5_character(bpy, **variant) -> Character:
    """A UE5 Mannequin-named character (``hand_l``, ``index_metacarpal_l``, ``index_01_l`` ...), metres,
    arms 45 degrees down (A-pose), object turned 90 degrees about z, hand bones rolled 90 degrees from
    ours; its hands' rest is our hand model's rest."""
    return build_character(bpy, "ue5", **variant)


def unity_character(bpy, **variant) -> Character:
    """A Unity Humanoid-named character (``LeftHand``, ``LeftThumbProximal``, ``LeftIndexProximal`` ...,
    no finger metacarpals), metres, T-pose, hand bones rolled 180 degrees (z to the palm), pose bones in
    XYZ Euler; its hands' rest is our hand model's rest."""
    return build_character(bpy, "unity", **variant)


def rigify_character(bpy) -> Character:
    """Rigify's human meta-rig (``bpy.ops.object.armature_human_metarig_add``, the bundled rigify add-on
    enabled): its rest pose is Rigify's own (a relaxed A-pose hand, fingers slightly bent)."""
    import addon_utils

    addon_utils.enable("rigify", default_set=True)
    for o in bpy.context.selected_objects:
        o.select_set(False)
    bpy.ops.object.armature_human_metarig_add()
    obj = bpy.context.active_object
    obj.name = "rigify_character"
    _without_rigify(bpy, addon_utils)
    bones = {}
    for side, s in (("left", "L"), ("right", "R")):
        names = {"palm": f"hand.{s}", "thumb_meta": f"thumb.01.{s}", "thumb_prox": f"thumb.02.{s}",
                 "thumb_dist": f"thumb.03.{s}"}
        for k, (f, theirs) in enumerate(zip(FINGERS, ("index", "middle", "ring", "pinky"))):
            names[f"{f}_meta"] = f"palm.0{k + 1}.{s}"
            for n, seg in enumerate(("prox", "mid", "dist")):
                names[f"{f}_{seg}"] = f"f_{theirs}.0{n + 1}.{s}"
        bones[side] = names
    return Character(obj, "rigify", bones, None)


def _without_rigify(bpy, addon_utils) -> None:
    """Rigify off again once its meta-rig is made, with the file-load handlers it leaves behind: they
    raise on every later file load of the process (tests that load .blend files after this one)."""
    addon_utils.disable("rigify", default_set=True)
    for name in dir(bpy.app.handlers):
        handlers = getattr(bpy.app.handlers, name)
        if isinstance(handlers, list):
            for h in [h for h in handlers if getattr(h, "__module__", "").startswith("rigify")]:
                handlers.remove(h)


def rigify_generated_character(bpy) -> Character:
    """A rig generated by Rigify from its human meta-rig (``pose.rigify_generate``): the retarget keys its
    FK finger controls, and its ``bones`` are the deform bones (``DEF-``) that follow them through
    constraints: what the character's mesh shows."""
    import addon_utils

    meta = rigify_character(bpy)
    addon_utils.enable("rigify", default_set=True)
    view_layer = bpy.context.view_layer
    for o in bpy.context.selected_objects:
        o.select_set(False)
    meta.obj.select_set(True)
    view_layer.objects.active = meta.obj
    before = set(bpy.data.objects)
    bpy.ops.pose.rigify_generate()
    rig = next(o for o in bpy.data.objects if o not in before and o.type == "ARMATURE")
    _without_rigify(bpy, addon_utils)
    bones = {side: {ours: "DEF-" + theirs for ours, theirs in names.items()} for side, names in meta.bones.items()}
    return Character(rig, "rigify", bones, None)
