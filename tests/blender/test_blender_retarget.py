"""Retarget to Armature (issue 49) in the bpy module: the demo take's solved hand keyed onto characters
of each rig convention (tests/blender/rigs.py), checked on Blender's own evaluated pose."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import rigs
from mocap_autolabel.core.hand.skeleton import BONE_NAMES

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "samples" / "demo_take.c3d"
#: Scene frames the checks evaluate (the demo take is on frames 1-1200).
FRAMES = tuple(int(f) for f in np.linspace(1, 1200, 24).round())


@pytest.fixture(scope="module")
def solved_blend(tmp_path_factory, bpy_module):
    """The demo take imported, labeled and solved with the add-on's operators, saved once."""
    bpy = bpy_module
    folder = tmp_path_factory.mktemp("retarget")
    bpy.ops.wm.read_homefile(use_empty=True)
    src = shutil.copy(DEMO, folder / DEMO.name)
    ops = bpy.ops.mocap_autolabel
    assert ops.import_markers(filepath=str(src)) == {"FINISHED"}
    assert ops.label() == {"FINISHED"}
    assert ops.solve_hand() == {"FINISHED"}
    path = folder / "solved.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


@pytest.fixture
def scene(bpy_module, solved_blend, tmp_path, monkeypatch):
    """The solved scene, freshly opened; presets go to a config folder of the test's own."""
    monkeypatch.setenv("BLENDER_USER_CONFIG", str(tmp_path / "config"))
    bpy_module.ops.wm.open_mainfile(filepath=str(solved_blend))
    return bpy_module.context.scene


def _hand(bpy):
    return bpy.data.objects["Hand"]


def _size(bpy) -> tuple[float, float]:
    cal = json.loads(_hand(bpy)["mocap_calibration"])
    return cal["hand_length_mm"] / 1000, cal["hand_breadth_mm"] / 1000


def _character(bpy, convention: str, **variant) -> rigs.Character:
    if convention == "rigify":
        return rigs.rigify_character(bpy)
    return rigs.build_character(bpy, convention, hand_size=_size(bpy), **variant)


def _retarget(bpy, ch: rigs.Character, **options) -> None:
    assert bpy.ops.mocap_autolabel.retarget(armature=ch.obj.name, **options) == {"FINISHED"}


def _posed(bpy, objects: list[tuple[object, list[str]]], frames=FRAMES) -> list[np.ndarray]:
    """Blender's evaluated pose: per object ``(frames, bones, 4, 4)`` armature-space ``pose_bone.matrix``."""
    scene = bpy.context.scene
    out = [np.empty((len(frames), len(names), 4, 4)) for _, names in objects]
    for i, f in enumerate(frames):
        scene.frame_set(f)
        for k, (obj, names) in enumerate(objects):
            out[k][i] = [np.array(obj.pose.bones[n].matrix) for n in names]
    return out


def _rest(obj, names) -> np.ndarray:
    return np.array([np.array(obj.data.bones[n].matrix_local) for n in names])


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Degrees between rotations ``(..., 3, 3)``."""
    rel = np.swapaxes(a, -1, -2) @ b
    cos = (np.trace(rel, axis1=-2, axis2=-1) - 1) / 2
    sin = np.linalg.norm(np.stack([rel[..., 2, 1] - rel[..., 1, 2], rel[..., 0, 2] - rel[..., 2, 0],
                                   rel[..., 1, 0] - rel[..., 0, 1]], axis=-1), axis=-1) / 2
    return np.degrees(np.arctan2(sin, cos))  # exact near 0 (arccos of float32 matrices is not)


def _joint_turns(posed: np.ndarray, rest: np.ndarray, bone: int, parent: int) -> np.ndarray:
    """``(F, 3, 3)``: the joint's turn from rest (bone relative to parent), in armature rest axes."""
    p0, b0 = rest[parent, :3, :3], rest[bone, :3, :3]
    p, b = posed[:, parent, :3, :3], posed[:, bone, :3, :3]
    now = np.swapaxes(p, -1, -2) @ b
    return p0 @ now @ (p0.T @ b0).T @ p0.T


def _pairs(ch: rigs.Character, side: str) -> list[tuple[str, str, str, str]]:
    """``(our bone, our parent, their bone, their parent)`` for every mapped bone but the hand, the
    parent being their bone's parent in their armature and ours the bone mapped to it."""
    mapping = ch.bones[side]
    back = {t: o for o, t in mapping.items()}
    out = []
    for ours, theirs in mapping.items():
        if ours == "palm":
            continue
        parent = ch.obj.data.bones[theirs].parent.name
        out.append((ours, back[parent], theirs, parent))
    return out


def _joint_errors(bpy, ch: rigs.Character, side: str = "right") -> dict[str, np.ndarray]:
    """Per mapped bone ``(F,)`` degrees between the character's joint turn from its rest (Blender's pose)
    and our solved hand's matching joint turn from ours, both in our hand frame's axes."""
    pairs = _pairs(ch, side)
    theirs = [ch.bones[side]["palm"]] + [t for _, _, t, _ in pairs]
    ours_posed, their_posed = _posed(bpy, [(_hand(bpy), list(BONE_NAMES)), (ch.obj, theirs)])
    ours_rest, their_rest = _rest(_hand(bpy), BONE_NAMES), _rest(ch.obj, theirs)
    g = ch.hand_frame[side]
    out = {}
    for ours, our_parent, bone, parent in pairs:
        mine = _joint_turns(ours_posed, ours_rest, BONE_NAMES.index(ours), BONE_NAMES.index(our_parent))
        got = _joint_turns(their_posed, their_rest, theirs.index(bone), theirs.index(parent))
        out[bone] = _angle(g.T @ got @ g, mine)
    return out


def _directions(bpy, ch: rigs.Character, side: str = "right") -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Per mapped finger bone ``(F,)`` degrees between its direction in the character's hand bone frame
    and our bone's in our palm frame, after the one rotation (all frames, all bones) that fits them
    best; and that rotation (our palm axes -> their hand bone's)."""
    mapping = {o: t for o, t in ch.bones[side].items() if o != "palm"}
    ours_posed, their_posed = _posed(bpy, [(_hand(bpy), ["palm"] + list(mapping)),
                                           (ch.obj, [ch.bones[side]["palm"]] + list(mapping.values()))])
    mine = np.swapaxes(ours_posed[:, :1, :3, :3], -1, -2) @ ours_posed[:, 1:, :3, 1:2]  # (F, n, 3, 1)
    got = np.swapaxes(their_posed[:, :1, :3, :3], -1, -2) @ their_posed[:, 1:, :3, 1:2]
    mine, got = mine[..., 0].reshape(-1, 3), got[..., 0].reshape(-1, 3)
    u, _, vt = np.linalg.svd(got.T @ mine)
    k = u @ np.diag([1, 1, np.linalg.det(u @ vt)]) @ vt  # Kabsch: got ~ k @ mine
    cos = np.sum((mine @ k.T) * got, axis=1) / np.linalg.norm(got, axis=1)
    err = np.degrees(np.arccos(np.clip(cos, -1, 1))).reshape(len(FRAMES), -1)
    return {t: err[:, i] for i, t in enumerate(mapping.values())}, k


def _channels(obj) -> set[str]:
    from mocap_autolabel.blender import animio

    strips = obj.animation_data.nla_tracks["Mocap hands"].strips
    assert len(strips) == 1
    action = strips[0].action
    if animio.SLOTTED:
        bag = action.layers[0].strips[0].channelbag(strips[0].action_slot)
        curves = bag.fcurves
    else:
        curves = action.fcurves
    return {fc.data_path.split('"')[1] for fc in curves}


# --- reading Blender --------------------------------------------------------------------------------

def test_target_rig_reads_the_bones_parents_first(scene, bpy_module):
    from mocap_autolabel.blender.retarget import target_rig

    ch = _character(bpy_module, "mixamo")
    rig = target_rig(ch.obj)
    bones = ch.obj.data.bones
    assert set(rig.names) == {b.name for b in bones} and len(rig.names) == len(bones)
    for i, name in enumerate(rig.names):
        parent = bones[name].parent
        assert (rig.parents[i] < 0) == (parent is None)
        if parent is not None:
            assert rig.names[rig.parents[i]] == parent.name and rig.parents[i] < i
        np.testing.assert_allclose(rig.rest[i], np.array(bones[name].matrix_local), atol=1e-5)
        assert rig.lengths[i] == pytest.approx(bones[name].length, rel=1e-6)
    np.testing.assert_allclose(rig.world, np.array(ch.obj.matrix_world), atol=1e-7)
    assert rig.unit_scale == pytest.approx(0.01)


def test_source_hands_read_the_solved_rig_as_blender_poses_it(scene, bpy_module):
    from mocap_autolabel.blender.retarget import source_hands

    bpy = bpy_module
    hands = source_hands(scene)
    assert [(side, src.frames, first) for side, src, first in hands] == [("right", 1200, 1)]
    _, src, first = hands[0]
    hand = _hand(bpy)
    (posed,) = _posed(bpy, [(hand, list(BONE_NAMES))])
    world = np.array(hand.matrix_world)
    at = np.array(FRAMES) - first
    want = world[:3, :3] @ posed[..., :3, :3]
    assert _angle(src.rotations[at], want).max() < 0.01
    heads = (posed[..., :3, 3] @ world[:3, :3].T + world[:3, 3]) / src.scale
    assert np.abs(src.heads[at] - heads).max() < 1e-5  # metres


# --- the conventions ------------------------------------------------------------------------------

@pytest.mark.parametrize("convention", ["mixamo", "ue5", "unity", "rigify"])
def test_auto_map_finds_each_conventions_hand_bones(scene, bpy_module, convention):
    from mocap_autolabel.blender.retarget import target_rig
    from mocap_autolabel.core.retarget.bone_maps import auto_map

    ch = _character(bpy_module, convention)
    rig = target_rig(ch.obj)
    found = auto_map(list(rig.names), list(rig.parents))
    assert found.convention == convention
    for side in rigs.SIDES:
        assert dict(found.sides[side]) == ch.bones[side], side


@pytest.mark.parametrize("convention", ["mixamo", "ue5", "unity"])
def test_each_finger_joint_turns_as_ours(scene, bpy_module, convention):
    """Every mapped bone turns from its rest, relative to its parent, as our bone turns relative to the
    bone mapped to that parent (Blender's evaluated pose; the characters' rest is our hand's)."""
    bpy = bpy_module
    ch = _character(bpy, convention)
    _retarget(bpy, ch)
    errors = _joint_errors(bpy, ch)
    assert len(errors) == len(ch.bones["right"]) - 1
    worst = {b: (round(float(np.median(e)), 3), round(float(np.percentile(e, 99)), 3)) for b, e in errors.items()}
    assert all(m < 1.0 and p < 3.0 for m, p in worst.values()), worst
    assert _channels(ch.obj) == set(ch.bones["right"].values()) - {ch.bones["right"]["palm"]}
    if convention == "mixamo":  # the check sees a wrong map: the index and middle fingers swapped
        from mocap_autolabel.blender.retarget import retarget_character

        swapped = {o: t for o, t in ch.bones["right"].items()}
        for seg in ("prox", "mid", "dist"):
            swapped[f"index_{seg}"], swapped[f"middle_{seg}"] = swapped[f"middle_{seg}"], swapped[f"index_{seg}"]
        retarget_character(bpy.context, armature=ch.obj, bone_map={"right": swapped})
        errors = _joint_errors(bpy, ch)
        assert float(np.percentile(errors["mixamorig:RightHandIndex1"], 99)) > 5.0


def test_rigify_meta_rig_turns_as_ours_from_a_reference_frame(scene, bpy_module):
    """Rigify's own rest: with a solved frame as the reference, every joint turns from its rest by the
    angle ours turns from that frame; with the rest reference, the fingers point as ours do."""
    bpy = bpy_module
    ch = _character(bpy, "rigify")
    reference = 600
    _retarget(bpy, ch, reference="frame", reference_frame=reference)
    pairs = _pairs(ch, "right")
    theirs = [t for _, _, t, _ in pairs] + sorted({p for _, _, _, p in pairs})
    ours = [o for o, _, _, _ in pairs] + sorted({o for _, o, _, _ in pairs})
    ours_posed, their_posed = _posed(bpy, [(_hand(bpy), list(BONE_NAMES)), (ch.obj, theirs)])
    (ref,) = _posed(bpy, [(_hand(bpy), list(BONE_NAMES))], frames=(reference,))
    their_rest = _rest(ch.obj, theirs)
    for ours_bone, our_parent, bone, parent in pairs:
        b, p = BONE_NAMES.index(ours_bone), BONE_NAMES.index(our_parent)
        rel = np.swapaxes(ours_posed[:, p, :3, :3], -1, -2) @ ours_posed[:, b, :3, :3]
        rel0 = ref[0, p, :3, :3].T @ ref[0, b, :3, :3]
        want = _angle(rel, np.broadcast_to(rel0, rel.shape))
        got = _angle(_joint_turns(their_posed, their_rest, theirs.index(bone), theirs.index(parent)), np.eye(3))
        err = np.abs(got - want)
        assert np.median(err) < 1.0 and np.percentile(err, 99) < 3.0, (bone, err.max())
    assert len(ours) == len(theirs)
    _retarget(bpy, ch)
    errors, _ = _directions(bpy, ch)
    assert max(float(e.max()) for e in errors.values()) < 2.0, {b: float(e.max()) for b, e in errors.items()}


def test_a_generated_rigify_rig_follows_through_its_controls(scene, bpy_module):
    """A rig generated by Rigify: the automatic map keys its FK controls (which hang below helper bones,
    not below the hand); its deform bones, which follow them through constraints, point as ours do."""
    bpy = bpy_module
    ch = rigs.rigify_generated_character(bpy)
    assert bpy.ops.mocap_autolabel.retarget(armature=ch.obj.name, use_panel_map=False) == {"FINISHED"}
    keyed = _channels(ch.obj)
    assert {"f_index.02.R", "thumb.03.R"} <= keyed and not any(b.startswith("DEF-") for b in keyed)
    # Its metacarpals have no control of their own (one palm control spreads them): they stay as rigged.
    ch.bones["right"] = {o: t for o, t in ch.bones["right"].items() if not o.endswith("_meta") or o == "thumb_meta"}
    errors, _ = _directions(bpy, ch)
    assert max(float(e.max()) for e in errors.values()) < 2.0, {b: round(float(e.max()), 2) for b, e in errors.items()}


@pytest.mark.parametrize("variant", [{"curl_deg": rigs.CURL_DEG}, {"roll_deg": 90.0}],
                         ids=["curled", "rolled"])
def test_curled_or_rolled_rest_fingers_point_as_ours(scene, bpy_module, variant):
    bpy = bpy_module
    ch = _character(bpy, "ue5", **variant)
    _retarget(bpy, ch)
    errors, k = _directions(bpy, ch)
    assert max(float(e.max()) for e in errors.values()) < 2.0, {b: float(e.max()) for b, e in errors.items()}
    # ...in the right frame: the fit's rotation is our palm laid on their hand bone at rest.
    hand = _rest(ch.obj, [ch.bones["right"]["palm"]])[0, :3, :3]
    assert _angle(k, hand.T @ ch.hand_frame["right"]) < 1.0
    if "roll_deg" in variant:  # our hand's rest with rolled bones: the joints turn exactly as ours too
        assert max(float(np.percentile(e, 99)) for e in _joint_errors(bpy, ch).values()) < 3.0


def test_longer_fingers_turn_as_ours_and_pinch_keeps_contacts(scene, bpy_module):
    bpy = bpy_module
    ch = _character(bpy, "mixamo", finger_scale=rigs.LONGER)
    _retarget(bpy, ch)
    errors = _joint_errors(bpy, ch)
    assert max(float(np.median(e)) for e in errors.values()) < 1.0
    assert max(float(np.percentile(e, 99)) for e in errors.values()) < 3.0
    # Keep Pinches: where our thumb touches a finger, the character's tips are as far apart as ours.
    from mocap_autolabel.blender.retarget import source_hands
    from mocap_autolabel.core.hand.skeleton import BONE_INDEX, FINGERS

    _, src, first = source_hands(scene)[0]
    tips = src.tips()
    gaps = np.stack([np.linalg.norm(tips[:, BONE_INDEX[f"{f}_dist"]] - tips[:, BONE_INDEX["thumb_dist"]], axis=1)
                     for f in FINGERS], axis=1)
    closest = np.argsort(gaps.min(axis=1))[:6]
    frames = tuple(int(i) + first for i in closest)
    fingers = [FINGERS[k] for k in gaps[closest].argmin(axis=1)]
    theirs = ch.bones["right"]

    def their_gaps():
        out = []
        for f, finger in zip(frames, fingers):
            scene.frame_set(f)
            a, b = (ch.obj.matrix_world @ ch.obj.pose.bones[theirs[n]].tail for n in ("thumb_dist", f"{finger}_dist"))
            out.append((a - b).length)
        return np.array(out)

    want = gaps[closest].min(axis=1)
    plain = np.abs(their_gaps() - want)
    _retarget(bpy, ch, pinch=True)
    kept = np.abs(their_gaps() - want)
    assert kept.max() < 0.001 and plain.max() > 0.002, (kept, plain)  # metres


def test_wrist_world_puts_the_hand_bone_on_our_wrist(scene, bpy_module):
    """``wrist="world"``: the character's hand bone turns and moves with our palm in the world (the UE5
    character is turned 90 degrees and rolled; the check is in the world)."""
    bpy = bpy_module
    ch = _character(bpy, "ue5")
    _retarget(bpy, ch, wrist="world")
    name = ch.bones["right"]["palm"]
    ours, theirs = _posed(bpy, [(_hand(bpy), ["palm"]), (ch.obj, [name])])
    to_world = [np.array(o.matrix_world) for o in (_hand(bpy), ch.obj)]
    ours_w, theirs_w = (w @ m[:, 0] for w, m in zip(to_world, (ours, theirs)))
    assert np.abs(ours_w[:, :3, 3] - theirs_w[:, :3, 3]).max() < 1e-3  # metres
    unit = [m[:, :3, :3] / np.linalg.norm(m[:, :3, :3], axis=1, keepdims=True) for m in (ours_w, theirs_w)]
    roll = rigs.CONVENTIONS["ue5"]["roll"]
    from mocap_autolabel.core.rotations import rot_y

    assert _angle(unit[0] @ rot_y(np.radians(roll)), unit[1]).max() < 1.0
    assert name in _channels(ch.obj)


# --- what the character keeps ---------------------------------------------------------------------

def test_unmapped_bones_and_the_body_action_stay_and_retargeting_again_replaces(scene, bpy_module):
    from mocap_autolabel.blender import animio

    bpy = bpy_module
    ch = _character(bpy, "mixamo")
    obj = ch.obj
    spine = obj.pose.bones["mixamorig:Spine"]
    spine.rotation_mode = "XYZ"
    spine.rotation_euler = (0.1, 0.0, 0.0)
    spine.keyframe_insert("rotation_euler", frame=1)
    body = obj.animation_data.action
    slot = getattr(obj.animation_data, "action_slot", None)
    _retarget(bpy, ch)
    _retarget(bpy, ch)
    ad = obj.animation_data
    assert ad.action == body and getattr(ad, "action_slot", None) == slot
    assert [fc.data_path for fc in animio.fcurves_of(obj)] == ['pose.bones["mixamorig:Spine"].rotation_euler'] * 3
    assert [t.name for t in ad.nla_tracks] == ["Mocap hands"] and len(ad.nla_tracks[0].strips) == 1
    names = sorted(a.name for a in bpy.data.actions if a.name.startswith(obj.name))
    assert names == sorted([body.name, f"{obj.name}_hands"]), names  # no second action, no .001
    keyed = _channels(obj)
    assert keyed == set(ch.bones["right"].values()) - {"mixamorig:RightHand"}
    untouched = [b.name for b in obj.data.bones if b.name not in keyed and b.name != "mixamorig:Spine"]
    (posed,) = _posed(bpy, [(obj, untouched)], frames=FRAMES[::6])
    for name in untouched:
        assert np.allclose(np.array(obj.pose.bones[name].matrix_basis), np.eye(4)), name
    still = [i for i, n in enumerate(untouched) if n not in ch.extra]  # the end bones ride on the fingers
    assert len(still) > 20 and np.allclose(posed[:, still], posed[:1, still], atol=1e-3)
    moving = _posed(bpy, [(obj, ["mixamorig:RightHandIndex2"])], frames=FRAMES[::6])[0]
    assert _angle(moving[:, 0, :3, :3], moving[:1, 0, :3, :3]).max() > 5.0  # the NLA strip plays


def test_the_panels_map_edits_retarget_and_presets_keep_them(scene, bpy_module, tmp_path):
    bpy = bpy_module
    from mocap_autolabel.core.retarget.bone_maps import BoneMap

    ch = _character(bpy, "mixamo")
    settings = scene.mocap_autolabel.retarget
    settings.armature = ch.obj  # picking it maps it
    rows = {(r.side, r.ours): r for r in settings.bone_map}
    assert len(rows) == 2 * len(BONE_NAMES) and settings.convention == "mixamo"
    assert rows["right", "index_dist"].theirs == "mixamorig:RightHandIndex3"
    assert rows["right", "index_meta"].theirs == ""  # Mixamo has none
    rows["right", "index_dist"].theirs = "mixamorig:RightHandIndex4"
    rows["right", "middle_mid"].theirs = ""
    assert bpy.ops.mocap_autolabel.retarget() == {"FINISHED"}  # the panel's armature and map
    keyed = _channels(ch.obj)
    assert "mixamorig:RightHandIndex4" in keyed and "mixamorig:RightHandIndex3" not in keyed
    assert "mixamorig:RightHandMiddle2" not in keyed and "mixamorig:RightHandMiddle3" in keyed
    (tip,) = _posed(bpy, [(ch.obj, ["mixamorig:RightHandIndex4"])], frames=FRAMES[::4])
    assert _angle(tip[:, 0, :3, :3], tip[:1, 0, :3, :3]).max() > 5.0

    assert bpy.ops.mocap_autolabel.retarget_save_map(preset="My Rig") == {"FINISHED"}
    path = Path(os.environ["BLENDER_USER_CONFIG"]) / "mocap_autolabel" / "bone_maps" / "My Rig.json"
    assert path.exists()
    saved = BoneMap.load(path)
    assert saved.sides["right"]["index_dist"] == "mixamorig:RightHandIndex4"
    assert "middle_mid" not in saved.sides["right"]
    assert bpy.ops.mocap_autolabel.retarget_auto_map() == {"FINISHED"}
    rows = {(r.side, r.ours): r.theirs for r in settings.bone_map}
    assert rows["right", "index_dist"] == "mixamorig:RightHandIndex3"
    assert bpy.ops.mocap_autolabel.retarget_load_map(preset="My Rig") == {"FINISHED"}
    rows = {(r.side, r.ours): r.theirs for r in settings.bone_map}
    assert rows["right", "index_dist"] == "mixamorig:RightHandIndex4" and rows["right", "middle_mid"] == ""


def test_two_takes_in_a_scene_are_never_mixed(scene, bpy_module):
    """A second take's solved hand in the scene: the retarget takes the hands of the panel's take (or the
    selected rigs), never both takes' hands onto one character."""
    bpy = bpy_module
    hand = _hand(bpy)
    other = hand.copy()
    other.data = hand.data.copy()
    other.animation_data.action = hand.animation_data.action.copy()
    folder = bpy.data.collections.new("other take hand")
    folder["mocap_solved_from"] = "other take"
    scene.collection.children.link(folder)
    folder.objects.link(other)
    for o in bpy.context.selected_objects:
        o.select_set(False)
    ch = _character(bpy, "ue5")
    settings = scene.mocap_autolabel
    assert settings.take is not None and settings.take.name != "other take"
    _retarget(bpy, ch)  # the panel's take: its one hand, no "2 solved right hands"
    with pytest.raises(RuntimeError, match="2 solved right hands"):  # no take, no selection: which one?
        settings.take = None
        bpy.ops.mocap_autolabel.retarget(armature=ch.obj.name)
    other.select_set(True)  # the selected rig wins
    assert bpy.ops.mocap_autolabel.retarget(armature=ch.obj.name) == {"FINISHED"}


def test_the_operator_undoes_and_its_errors_are_one_line(scene, bpy_module):
    bpy = bpy_module
    ops = bpy.ops.mocap_autolabel
    for o in bpy.context.selected_objects:
        o.select_set(False)
    bpy.context.view_layer.objects.active = None
    with pytest.raises(RuntimeError, match="No character armature: pick one in the Retarget panel"):
        ops.retarget()
    bpy.context.view_layer.objects.active = _hand(bpy)
    with pytest.raises(RuntimeError, match="'Hand' is a solved hand: pick the character's armature"):
        ops.retarget()

    ch = _character(bpy, "unity")
    name = ch.obj.name
    bpy.ops.ed.undo_push(message="before")
    _retarget(bpy, ch)
    bpy.ops.ed.undo_push(message="Retarget to Armature")
    assert bpy.data.objects[name].animation_data.nla_tracks["Mocap hands"].strips
    bpy.ops.ed.undo()
    ad = bpy.data.objects[name].animation_data
    assert ad is None or not ad.nla_tracks
    assert f"{name}_hands" not in bpy.data.actions

    settings = bpy.context.scene.mocap_autolabel.retarget
    settings.armature = bpy.data.objects[name]
    for row in settings.bone_map:
        if row.side == "right":
            row.theirs = ""
    with pytest.raises(RuntimeError, match="The right hand is not mapped on 'unity_character'"):
        ops.retarget()
    for obj in [o for o in bpy.data.objects if "mocap_calibration" in o]:
        bpy.data.objects.remove(obj)
    with pytest.raises(RuntimeError, match="No solved hand in the scene: run Solve Hand"):
        ops.retarget(armature=name, use_panel_map=False)


def test_the_retarget_panel_and_its_list_are_registered(bpy_module):
    """The Mocap tab's Retarget sub-panel draws the character, the bone map (their bone picked among
    the armature's bones) and the operators (checked on the source: a headless Blender draws no panels)."""
    import inspect

    from mocap_autolabel.ui.panels import MOCAPAL_PT_retarget, MOCAPAL_UL_bone_map

    bpy = bpy_module
    assert hasattr(bpy.types, "MOCAPAL_PT_retarget") and hasattr(bpy.types, "MOCAPAL_UL_bone_map")
    assert MOCAPAL_PT_retarget.bl_category == "Mocap" and MOCAPAL_PT_retarget.bl_parent_id == "MOCAPAL_PT_label"
    source = inspect.getsource(MOCAPAL_PT_retarget.draw)
    for op in ("retarget", "retarget_auto_map", "retarget_save_map", "retarget_load_map"):
        assert f'"mocap_autolabel.{op}"' in source and hasattr(bpy.ops.mocap_autolabel, op)
    assert '"MOCAPAL_UL_bone_map"' in source
    assert 'prop_search(item, "theirs", arm.data, "bones"' in inspect.getsource(MOCAPAL_UL_bone_map.draw_item)
    from mocap_autolabel.operators.retarget import MOCAPAL_OT_retarget

    assert {"REGISTER", "UNDO"} <= set(MOCAPAL_OT_retarget.bl_options)
    assert bpy.ops.mocap_autolabel.retarget.get_rna_type().name == "Retarget to Armature"
