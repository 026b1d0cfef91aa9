"""Export Hand (issue 48): the solved rig(s) of the take alone, as FBX (ONE animation stack, read back by
Blender's importer in a fresh scene) or BVH, bone names by engine preset, one file per hand of a two-hand
take, one-line errors, the scene the user keeps left exactly as it was."""

from __future__ import annotations

import os

import numpy as np
import pytest
from mocap_autolabel.core.formats.c3d import write_c3d
from mocap_autolabel.core.hand.skeleton import BONE_NAMES
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.synth.generate import clean_config, synthesize
from mocap_autolabel.core.synth.two_hands import TwoHandConfig, two_hand_take
from mocap_autolabel.core.take import Take

FRAMES = 120


def _fbx_names(path, kind: bytes) -> list[str]:
    """Names of the FBX's objects of one kind (``AnimationStack``, ``Model``), read by Blender's own parser."""
    from io_scene_fbx import parse_fbx

    root, _ = parse_fbx.parse(str(path))
    objects = next(e for e in root.elems if e.id == b"Objects")
    return [e.props[1].split(b"\x00\x01")[0].decode() for e in objects.elems if e.id == kind]


def _state(bpy) -> dict:
    """Everything Export Hand must leave as it was: the datablocks' names, the rigs' bone names, their
    actions, the window's scene and its frame."""
    out = {kind: sorted(d.name for d in getattr(bpy.data, kind))
           for kind in ("objects", "actions", "armatures", "scenes", "collections", "meshes")}
    out["bones"] = {o.name: [b.name for b in o.data.bones] for o in bpy.data.objects if o.type == "ARMATURE"}
    out["rig_actions"] = {o.name: o.animation_data.action.name for o in bpy.data.objects
                          if o.type == "ARMATURE" and o.animation_data and o.animation_data.action}
    out["scene"] = bpy.context.scene.name
    out["frame"] = bpy.context.scene.frame_current
    return out


def _no_partials(folder) -> None:
    left = [f for f in os.listdir(folder) if ".partial" in f]
    assert not left, left


@pytest.fixture(scope="module")
def takes(tmp_path_factory):
    """Labeled synthetic takes: one right hand (han19 names) and two hands (L_ / R_ names)."""
    folder = tmp_path_factory.mktemp("export_hand")
    layout = load_layout("han19")
    one = synthesize(layout, FRAMES, seed=8, config=clean_config())
    markers = one.markers + np.random.default_rng(8).normal(0, 0.0005, one.markers.shape)
    write_c3d(Take(positions=markers.astype(np.float32), names=layout.names, rate=120.0, first_frame=1,
                   source="one.c3d"), folder / "one.c3d")
    two = two_hand_take(layout, FRAMES, seed=3, config=TwoHandConfig(close_share=0.0))
    names = [f"L_{n}" for n in layout.names] + [f"R_{n}" for n in layout.names]
    write_c3d(Take(positions=two.markers.astype(np.float32), names=names, rate=120.0, first_frame=1,
                   source="two.c3d"), folder / "two.c3d")
    return folder


def _solved(bpy, folder, name: str):
    """The labeled take ``name`` imported and solved with the panel's operators; its take collection."""
    assert bpy.ops.mocap_autolabel.import_markers(filepath=str(folder / f"{name}.c3d")) == {"FINISHED"}
    coll = bpy.context.scene.mocap_autolabel.take
    assert bpy.ops.mocap_autolabel.solve_hand(layout="han19") == {"FINISHED"}
    return coll


def _import_fbx(bpy, path):
    """The FBX in a fresh scene (Blender's importer): its objects and actions."""
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.import_scene.fbx(filepath=str(path), anim_offset=0.0)
    return list(bpy.context.scene.objects), list(bpy.data.actions)


def test_the_options_spell_the_presets(bpy_module):
    from mocap_autolabel.blender.export import BONE_NAME_PRESETS, HAND_FORMATS

    props = bpy_module.ops.mocap_autolabel.export_hand.get_rna_type().properties
    assert {i.identifier for i in props["bone_names"].enum_items} == set(BONE_NAME_PRESETS)
    assert {i.identifier for i in props["file_format"].enum_items} == set(HAND_FORMATS)


def test_one_hand_fbx_holds_the_rig_alone_in_one_stack(empty_scene, bpy_module, takes, tmp_path):
    bpy = bpy_module
    coll = _solved(bpy, takes, "one")
    rig = bpy.data.objects["Hand"]
    # The scene also holds the take's empties (each with its action) and the rig's skin and markers.
    assert len(bpy.data.actions) > 1 and len(bpy.context.scene.objects) > 3
    before = _state(bpy)
    # The default file: beside the take's source.
    from mocap_autolabel.blender.export import default_hand_path

    assert default_hand_path(coll, bpy.context.scene, ".fbx") == str(takes / "one_hand.fbx")
    path = tmp_path / "out" / "hand.fbx"
    assert bpy.ops.mocap_autolabel.export_hand(filepath=str(path)) == {"FINISHED"}
    assert _state(bpy) == before  # no renamed bone, no leftover object, action or scene
    assert os.listdir(tmp_path / "out") == ["hand.fbx"]
    # ONE animation stack, named after the file; the rig is the file's only armature, no marker empties.
    assert _fbx_names(path, b"AnimationStack") == ["hand"]
    models = _fbx_names(path, b"Model")
    assert "Hand" in models and not [m for m in models if m.startswith("*") or m in load_layout("han19").names]
    # Rotations keyed on the rig at a frame, as Blender's importer reads them back in a fresh scene.
    bpy.context.scene.frame_set(60)
    want = {b: np.array(rig.pose.bones[b].matrix) for b in BONE_NAMES}
    world = np.array(rig.matrix_world)
    objs, actions = _import_fbx(bpy, path)
    arms = [o for o in objs if o.type == "ARMATURE"]
    assert len(arms) == 1 and [o.type for o in objs] == ["ARMATURE"]
    assert len(actions) == 1  # one stack: one action
    arm = arms[0]
    assert {b.name for b in arm.data.bones} == set(BONE_NAMES)
    assert tuple(int(f) for f in actions[0].frame_range) == (1, FRAMES)
    bpy.context.scene.frame_set(60)
    for b in BONE_NAMES:  # same world rotation (the importer turns the file's Y up back to Blender's Z up)
        got = np.array(arm.matrix_world) @ np.array(arm.pose.bones[b].matrix)
        ref = world @ want[b]
        r_got = got[:3, :3] / np.linalg.norm(got[:3, :3], axis=0)
        r_ref = ref[:3, :3] / np.linalg.norm(ref[:3, :3], axis=0)
        assert np.abs(r_got - r_ref).max() < 2e-3, b
        assert np.abs(got[:3, 3] - ref[:3, 3]).max() < 1e-4, b


def test_a_preset_names_the_bones_in_the_file_only(empty_scene, bpy_module, takes, tmp_path):
    from mocap_autolabel.core.retarget.bone_maps import export_names

    bpy = bpy_module
    _solved(bpy, takes, "one")
    before = _state(bpy)
    path = tmp_path / "ue.fbx"
    assert bpy.ops.mocap_autolabel.export_hand(filepath=str(path), bone_names="ue5") == {"FINISHED"}
    assert _state(bpy) == before  # our names stay in the scene
    assert _fbx_names(path, b"AnimationStack") == ["ue"]
    objs, actions = _import_fbx(bpy, path)
    arm = next(o for o in objs if o.type == "ARMATURE")
    side = "right"  # the synthetic hand of seed 8
    assert {b.name for b in arm.data.bones} == set(export_names("ue5", side).values())
    assert len(actions) == 1


def test_two_hands_write_one_file_per_hand(empty_scene, bpy_module, takes, tmp_path):
    bpy = bpy_module
    _solved(bpy, takes, "two")
    assert {"Hand_L", "Hand_R"} <= set(bpy.data.objects.keys())
    before = _state(bpy)
    path = tmp_path / "both.fbx"
    assert bpy.ops.mocap_autolabel.export_hand(filepath=str(path)) == {"FINISHED"}
    assert _state(bpy) == before
    assert sorted(os.listdir(tmp_path)) == ["both_left.fbx", "both_right.fbx"]
    for side, rig in (("left", "Hand_L"), ("right", "Hand_R")):
        one = tmp_path / f"both_{side}.fbx"
        assert _fbx_names(one, b"AnimationStack") == [f"both_{side}"]
        assert rig in _fbx_names(one, b"Model") and ({"Hand_L", "Hand_R"} - {rig}).isdisjoint(_fbx_names(one, b"Model"))
    objs, actions = _import_fbx(bpy, tmp_path / "both_right.fbx")
    assert [o.type for o in objs] == ["ARMATURE"] and len(actions) == 1


def test_bvh_of_each_hand(empty_scene, bpy_module, takes, tmp_path):
    bpy = bpy_module
    _solved(bpy, takes, "two")
    before = _state(bpy)
    # The format's extension replaces another one given.
    assert bpy.ops.mocap_autolabel.export_hand(filepath=str(tmp_path / "h.fbx"), file_format="BVH",
                                               bone_names="mixamo") == {"FINISHED"}
    assert _state(bpy) == before
    assert sorted(os.listdir(tmp_path)) == ["h_left.bvh", "h_right.bvh"]
    for side, prefix in (("left", "Left"), ("right", "Right")):
        text = (tmp_path / f"h_{side}.bvh").read_text()
        assert text.startswith("HIERARCHY") and f"ROOT mixamorig:{prefix}Hand" in text
        frames = int(text.split("Frames:")[1].split()[0])
        assert frames == FRAMES
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.import_anim.bvh(filepath=str(tmp_path / "h_left.bvh"))
    arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
    assert len(arm.data.bones) == len(BONE_NAMES)


def test_errors_are_one_line_and_write_nothing(empty_scene, bpy_module, takes, tmp_path):
    bpy = bpy_module
    # No solved hand: the button is off and says why.
    assert bpy.ops.mocap_autolabel.import_markers(filepath=str(takes / "one.c3d")) == {"FINISHED"}
    assert not bpy.ops.mocap_autolabel.export_hand.poll()
    with pytest.raises(RuntimeError, match="Solve Hand"):
        bpy.ops.mocap_autolabel.export_hand(filepath=str(tmp_path / "x.fbx"))
    from mocap_autolabel.blender.export import export_hands
    from mocap_autolabel.core.errors import MocapInputError

    coll = bpy.context.scene.mocap_autolabel.take
    with pytest.raises(MocapInputError, match="No solved hand in take 'one'"):
        export_hands(coll, bpy.context.scene, filepath=str(tmp_path / "x.fbx"))
    assert bpy.ops.mocap_autolabel.solve_hand(layout="han19") == {"FINISHED"}
    before = _state(bpy)
    # A folder that cannot be made (a file holds its name; root may write anywhere else): one line naming
    # the file, nothing left behind.
    blocker = tmp_path / "blocker"
    blocker.write_text("a file, not a folder")
    with pytest.raises(RuntimeError) as err:
        bpy.ops.mocap_autolabel.export_hand(filepath=str(blocker / "x.fbx"))
    line = str(err.value).strip()
    assert len(line.splitlines()) == 1 and "Traceback" not in line
    assert str(blocker / "x.fbx") in line and "cannot write" in line
    with pytest.raises(RuntimeError, match="is a folder"):
        bpy.ops.mocap_autolabel.export_hand(filepath=str(tmp_path) + os.sep)
    with pytest.raises(MocapInputError, match="unknown bone names"):
        export_hands(coll, bpy.context.scene, filepath=str(tmp_path / "x.fbx"), bone_names="maya")
    assert _state(bpy) == before
    _no_partials(tmp_path)


def test_the_scenes_rigs_without_a_take_and_two_of_a_side(empty_scene, bpy_module, takes, tmp_path):
    """A scene opened from ``solve --blend`` (no take in the Take field): its rig; two takes' rigs of one side
    with the field empty: a one-line error that says what to do."""
    bpy = bpy_module
    first = _solved(bpy, takes, "one")
    settings = bpy.context.scene.mocap_autolabel
    settings.take = None
    for o in bpy.context.selected_objects:
        o.select_set(False)
    bpy.context.view_layer.objects.active = None
    assert bpy.ops.mocap_autolabel.export_hand(filepath=str(tmp_path / "a.fbx")) == {"FINISHED"}
    assert os.listdir(tmp_path) == ["a.fbx"]
    from mocap_autolabel.blender.export import default_hand_path

    assert default_hand_path(None, bpy.context.scene, ".bvh") == str(takes / "one_hand.bvh")
    second = tmp_path / "again.c3d"
    second.write_bytes((takes / "one.c3d").read_bytes())
    assert bpy.ops.mocap_autolabel.import_markers(filepath=str(second)) == {"FINISHED"}
    assert bpy.ops.mocap_autolabel.solve_hand(layout="han19") == {"FINISHED"}
    settings.take = None
    bpy.context.view_layer.objects.active = None
    with pytest.raises(RuntimeError, match="2 solved hands of one side in the scene .*Take field"):
        bpy.ops.mocap_autolabel.export_hand(filepath=str(tmp_path / "b.fbx"))
    settings.take = first  # the take chosen: its rig
    assert bpy.ops.mocap_autolabel.export_hand(filepath=str(tmp_path / "b.fbx")) == {"FINISHED"}
    assert sorted(os.listdir(tmp_path)) == ["a.fbx", "again.c3d", "b.fbx"]
