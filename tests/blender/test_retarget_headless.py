"""Headless retargeting and engine-ready exports: ``solve --retarget CHARACTER.blend[:ARMATURE]``, batch's
``retarget`` TOML key, and ``--fbx/--bvh --bone-names``, each FBX read back by Blender's importer (and by
ufbx, a second reader, where installed): the bone names, ONE animation stack, the rotations over every frame."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from mocap_autolabel.cli import main
from mocap_autolabel.core.formats.c3d import write_c3d
from mocap_autolabel.core.hand.skeleton import BONE_NAMES
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.synth.generate import clean_config, synthesize
from mocap_autolabel.core.take import Take

FRAMES = 120
PRESETS = ("ours", "ue5", "unity", "mixamo", "rigify")
#: Blender's world from an FBX's (ufbx reads the file's own axes): Y up, forward -Z files (every preset but
#: ue5) turn back by +90 degrees about x; ue5's Z up, forward Y file is Blender's own axes.
TO_BLENDER = {"y_up": np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]), "z_up": np.eye(3)}


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles between rotations, degrees, exact near zero (arccos of the trace is not: float32 matrices
    alone read as 0.03 degrees there)."""
    rel = np.swapaxes(a, -1, -2) @ b
    cos = (np.trace(rel, axis1=-2, axis2=-1) - 1) / 2
    sin = np.linalg.norm(np.stack([rel[..., 2, 1] - rel[..., 1, 2], rel[..., 0, 2] - rel[..., 2, 0],
                                   rel[..., 1, 0] - rel[..., 0, 1]], axis=-1), axis=-1) / 2
    return np.degrees(np.arctan2(sin, cos))


def _rotations(bpy, arm, bones: list[str], frames=range(1, FRAMES + 1)) -> np.ndarray:
    """``(F, B, 3, 3)``: each bone's rotation in the world at each frame (scale taken off)."""
    scene = bpy.context.scene
    out = np.empty((len(frames), len(bones), 3, 3))
    for i, f in enumerate(frames):
        scene.frame_set(f)
        world = np.array(arm.matrix_world)[:3, :3]
        world = world / np.linalg.norm(world, axis=0)
        for j, name in enumerate(bones):
            out[i, j] = world @ np.array(arm.pose.bones[name].matrix)[:3, :3]
    return out


def _fbx_tree(path):
    from io_scene_fbx import parse_fbx  # Blender's own FBX parser (its add-on's folder is on sys.path with bpy)

    root, _ = parse_fbx.parse(str(path))
    return next(e for e in root.elems if e.id == b"Objects")


def _fbx_names(path, kind: bytes) -> list[str]:
    """Names of the FBX's objects of one kind (``AnimationStack``, ``Model``), as the file holds them."""
    return [e.props[1].split(b"\x00\x01")[0].decode() for e in _fbx_tree(path).elems if e.id == kind]


def _import_fbx(bpy, path):
    """The FBX's armature in a fresh scene (Blender's importer, no frame offset)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.scene.render.fps, bpy.context.scene.render.fps_base = 120, 1.0
    bpy.ops.import_scene.fbx(filepath=str(path), anim_offset=0.0)
    arms = [o for o in bpy.context.scene.objects if o.type == "ARMATURE"]
    assert len(arms) == 1, [o.name for o in bpy.context.scene.objects]
    return arms[0]


def _digest(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def _no_partials(folder) -> None:
    left = [os.path.join(r, f) for r, _, files in os.walk(folder) for f in files if ".partial" in f]
    assert not left, left


@pytest.fixture(scope="module")
def work(tmp_path_factory, bpy_module):
    """A labeled synthetic right hand solved once (its calibration kept for the other runs), and character
    .blend files: one UE5-named character, a file of two characters, one of a prop, one of no armature."""
    import rigs

    bpy = bpy_module
    folder = tmp_path_factory.mktemp("retarget")
    layout = load_layout("han19")
    synth = synthesize(layout, FRAMES, seed=8, config=clean_config())
    assert synth.hand.side == "right"
    markers = synth.markers + np.random.default_rng(8).normal(0, 0.0005, synth.markers.shape)
    write_c3d(Take(positions=markers.astype(np.float32), names=layout.names, rate=120.0, first_frame=1,
                   source="labeled.c3d"), folder / "labeled.c3d")
    assert main(["solve", str(folder / "labeled.c3d"), "--blend", str(folder / "solved.blend"), "--save-calibration",
                 str(folder / "cal.json"), "--quiet"]) == 0
    for name, build in (("char", [rigs.ue5_character]), ("two", [rigs.ue5_character, rigs.mixamo_character]),
                        ("prop", []), ("empty", None)):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        for make in build or []:
            make(bpy)
        if build == []:  # an armature with no hand: two bones of a prop
            arm = bpy.data.armatures.new("Prop")
            obj = bpy.data.objects.new("Prop", arm)
            bpy.context.scene.collection.objects.link(obj)
            bpy.context.view_layer.objects.active = obj
            bpy.ops.object.mode_set(mode="EDIT")
            for i, bone in enumerate(("stick", "tip")):
                eb = arm.edit_bones.new(bone)
                eb.head, eb.tail = (0, 0, i * 0.1), (0, 0, i * 0.1 + 0.1)
            bpy.ops.object.mode_set(mode="OBJECT")
        bpy.ops.wm.save_as_mainfile(filepath=str(folder / f"{name}.blend"))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return folder


def _solve(work, *more: str) -> int:
    return main(["solve", str(work / "labeled.c3d"), "--calibration", str(work / "cal.json"), "--quiet", *more])


def test_the_flags_spell_the_registries(bpy_module):
    from mocap_autolabel.blender.export import BONE_NAME_PRESETS
    from mocap_autolabel.commands.solve import BONE_NAME_CHOICES, WRIST_CHOICES, split_character
    from mocap_autolabel.core.retarget.transfer import WRIST_MODES

    assert BONE_NAME_CHOICES == BONE_NAME_PRESETS and WRIST_CHOICES == WRIST_MODES
    assert split_character("a/char.blend:Armature") == ("a/char.blend", "Armature")
    assert split_character("C:\\chars\\x.Blend") == ("C:\\chars\\x.Blend", None)
    with pytest.raises(ValueError, match="CHARACTER.blend"):
        split_character("char.fbx")


def test_solve_retargets_onto_the_character_and_exports_its_armature(work, bpy_module, tmp_path):
    bpy = bpy_module
    before = _digest(work / "char.blend")
    out = {k: tmp_path / f"out.{k}" for k in ("blend", "fbx", "bvh")}
    assert _solve(work, "--retarget", str(work / "char.blend"), "--blend", str(out["blend"]), "--fbx", str(out["fbx"]),
                  "--bvh", str(out["bvh"]), "--bone-names", "ue5", "--retarget-wrist", "rotation",
                  "--report", str(tmp_path / "r.json")) == 0
    assert _digest(work / "char.blend") == before  # the character's own file is never written
    facts = json.loads((tmp_path / "r.json").read_text())["retarget"]
    assert facts["armature"] == "ue5_character" and facts["convention"] == "ue5"
    bones = facts["hands"]["right"]["bones"]
    assert "hand_r" in bones and "index_03_r" in bones and facts["hands"]["right"]["frames"] == FRAMES
    _no_partials(tmp_path)

    bpy.ops.wm.open_mainfile(filepath=str(out["blend"]))
    character = bpy.data.objects["ue5_character"]
    track = character.animation_data.nla_tracks["Mocap hands"]
    assert [s.action.name for s in track.strips] == ["ue5_character_hands"]
    assert "Hand" in bpy.data.objects and "mocap_calibration" in bpy.data.objects["Hand"]  # our rig beside it
    assert not [o.name for o in bpy.data.objects if "~" in o.name or o.name.endswith(".001")]
    reference = _rotations(bpy, character, bones)
    own = {b.name for b in character.data.bones}

    # The FBX: the character's armature alone, its own names, one stack named after the file, no leaf bones.
    assert _fbx_names(out["fbx"], b"AnimationStack") == ["out"]
    assert sorted(_fbx_names(out["fbx"], b"Model")) == sorted(["ue5_character", *own])
    arm = _import_fbx(bpy, out["fbx"])
    assert {b.name for b in arm.data.bones} == own
    worst = _angle_deg(reference, _rotations(bpy, arm, bones)).max()
    assert worst < 0.1, f"retargeted FBX rotations differ by up to {worst:.4f} degrees"
    assert len(bpy.data.actions) == 1  # one stack: one action

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_anim.bvh(filepath=str(out["bvh"]), frame_start=1, use_fps_scale=False, axis_forward="Y",
                            axis_up="Z")
    arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
    assert set(bones) <= {b.name for b in arm.data.bones}


@pytest.fixture(scope="module")
def presets(work, bpy_module):
    """Per --bone-names preset, the solve's .blend and FBX (and, for ue5, the BVH)."""
    out = {}
    for preset in PRESETS:
        files = {"blend": work / f"{preset}.blend", "fbx": work / f"{preset}.fbx"}
        if preset == "ue5":
            files["bvh"] = work / f"{preset}.bvh"
        more = ["--bvh", str(files["bvh"])] if "bvh" in files else []
        assert _solve(work, "--blend", str(files["blend"]), "--fbx", str(files["fbx"]), "--bone-names", preset,
                      *more) == 0
        out[preset] = files
    return out


@pytest.mark.parametrize("preset", PRESETS)
def test_each_bone_names_preset_reads_back_with_blenders_importer(presets, bpy_module, preset):
    from mocap_autolabel.core.retarget.bone_maps import export_names

    bpy = bpy_module
    files = presets[preset]
    names = export_names(preset, "right")
    bpy.ops.wm.open_mainfile(filepath=str(files["blend"]))
    rig = bpy.data.objects["Hand"]
    assert [b.name for b in rig.data.bones] == list(BONE_NAMES)  # the .blend keeps our names
    assert not [a.name for a in bpy.data.actions if a.name.endswith(".001")]
    reference = _rotations(bpy, rig, list(BONE_NAMES))

    assert _fbx_names(files["fbx"], b"AnimationStack") == [preset]  # ONE stack, named after the file
    assert sorted(_fbx_names(files["fbx"], b"Model")) == sorted(["Hand", *names.values()])  # the rig alone
    arm = _import_fbx(bpy, files["fbx"])
    assert {b.name for b in arm.data.bones} == set(names.values())  # renamed, no leaf bones
    assert [a.name for a in bpy.data.actions] == [f"Hand|{preset}"]
    worst = _angle_deg(reference, _rotations(bpy, arm, [names[b] for b in BONE_NAMES])).max()
    assert worst < 0.1, f"{preset}: rotations differ by up to {worst:.4f} degrees over {FRAMES} frames"
    if preset == "ue5":  # centimetres, the armature at scale 1 in the file: Blender reads it back at 0.01
        assert np.allclose(arm.scale, 0.01)
        bpy.ops.wm.read_factory_settings(use_empty=True)
        bpy.ops.import_anim.bvh(filepath=str(files["bvh"]), frame_start=1, use_fps_scale=False)
        bvh = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
        assert {b.name for b in bvh.data.bones} == set(names.values())
    else:
        assert np.allclose(arm.scale, 1.0)


#: Run in a child process: ufbx 0.0.5's binding hands out borrowed references (an object fetched twice, or
#: dropped, crashes the process), so each object is fetched once and kept, and the process ends with os._exit.
READ_WITH_UFBX = textwrap.dedent("""
    import json, os, sys
    import ufbx
    keep = []
    def once(obj):
        keep.append(obj)
        return obj
    scene = once(ufbx.load_file(sys.argv[1]))
    order = json.loads(sys.argv[2])
    stacks = once(scene.anim_stacks)
    stack_list = [once(stacks[i]) for i in range(len(stacks))]
    out = {"stacks": [once(s.name) for s in stack_list], "scales": {}, "rotations": []}
    anim = once(stack_list[0].anim)
    settings = once(scene.settings)
    out["unit_meters"] = settings.unit_meters
    out["up"] = int(once(settings.axes).up)
    nodes = once(scene.nodes)
    for i in range(len(nodes)):
        node = once(nodes[i])
        name = once(node.name)
        if name:
            s = once(once(node.local_transform).scale)
            out["scales"][name] = [s.x, s.y, s.z]
    for frame in range(1, int(sys.argv[3]) + 1):
        evaluated = once(once(scene.evaluate(anim, frame / 120.0)).nodes)
        found = {}
        for i in range(len(evaluated)):
            node = once(evaluated[i])
            name = once(node.name)
            if name in order:
                m = once(node.node_to_world)
                found[name] = [[c.x, c.y, c.z] for c in (once(m.c0), once(m.c1), once(m.c2))]
        out["rotations"].append([found[n] for n in order])
    print(json.dumps(out), flush=True)
    os._exit(0)
""")


@pytest.mark.parametrize("preset", ["ours", "ue5"])
def test_a_second_reader_ufbx_reads_the_same_names_stack_units_and_rotations(presets, bpy_module, preset):
    pytest.importorskip("ufbx", reason="ufbx (pip install ufbx, in the dev extra) is not installed")
    from mocap_autolabel.core.retarget.bone_maps import export_names

    bpy = bpy_module
    files = presets[preset]
    names = [export_names(preset, "right")[b] for b in BONE_NAMES]
    done = subprocess.run([sys.executable, "-c", READ_WITH_UFBX, str(files["fbx"]), json.dumps(names), str(FRAMES)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    read = json.loads(done.stdout)
    assert read["stacks"] == [preset]
    # metres, or centimetres for Unreal; either way no node carries a scale (the exporter's default puts 100 there)
    assert read["unit_meters"] == pytest.approx(0.01 if preset == "ue5" else 1.0)
    assert all(np.allclose(s, 1.0, atol=1e-5) for s in read["scales"].values()), read["scales"]
    assert read["up"] == (4 if preset == "ue5" else 2)  # ufbx's CoordinateAxis POSITIVE_Z, POSITIVE_Y
    back = np.array(read["rotations"]).transpose(0, 1, 3, 2)  # columns -> rows
    back = TO_BLENDER["z_up" if preset == "ue5" else "y_up"] @ (back / np.linalg.norm(back, axis=-2, keepdims=True))
    bpy.ops.wm.open_mainfile(filepath=str(files["blend"]))
    reference = _rotations(bpy, bpy.data.objects["Hand"], list(BONE_NAMES))
    worst = _angle_deg(reference, back).max()
    assert worst < 0.1, f"ufbx: {preset} rotations differ by up to {worst:.4f} degrees"


def test_batch_retargets_per_take_from_the_studio_toml(work, bpy_module, tmp_path):
    bpy = bpy_module
    (tmp_path / "studio.toml").write_text(textwrap.dedent(f"""
        [batch]
        calibration = "{work / 'cal.json'}"
        blend = true
        fbx = true
        retarget = "{work / 'char.blend'}:ue5_character"
        retarget_wrist = "fingers"
        pinch = true
        bone_names = "unity"
    """))
    take = tmp_path / "takes" / "t1.c3d"
    take.parent.mkdir()
    take.write_bytes((work / "labeled.c3d").read_bytes())
    out = tmp_path / "out"
    assert main(["batch", str(take.parent), "-o", str(out), "--config", str(tmp_path / "studio.toml"), "--quiet"]) == 0
    report = json.loads((out / "t1.report.json").read_text())
    assert report["status"] == "ok", report.get("error")
    assert report["outputs"] == {"labeled": "t1.labeled.c3d", "blend": "t1.blend", "fbx": "t1.fbx"}
    assert report["retarget"]["armature"] == "ue5_character" and len(report["retarget"]["hands"]["right"]["bones"]) > 10
    summary = (out / "summary.csv").read_text()
    assert "retarget" in summary.splitlines()[0] and "ue5_character (right " in summary
    assert json.loads((out / "summary.json").read_text())["takes_detail"][0]["retarget"].startswith("ue5_character")
    assert _fbx_names(out / "t1.fbx", b"AnimationStack") == ["t1"]
    arm = _import_fbx(bpy, out / "t1.fbx")
    assert arm.name == "ue5_character" and "index_01_r" in arm.data.bones
    _no_partials(out)


def test_retarget_errors_are_one_line_and_come_before_the_solve(work, bpy_module, tmp_path, capsys):
    (tmp_path / "garbage.blend").write_text("not a blend")
    (tmp_path / "bad.json").write_text("{")
    (tmp_path / "wrong.json").write_text(json.dumps({"format": "mocap_autolabel.bone_map/1", "convention": "x",
                                                     "sides": {"right": {"palm": "no_such_bone"}}}))
    blend = tmp_path / "never.blend"
    cases = [
        ([str(tmp_path / "missing.blend")], f"error: {tmp_path / 'missing.blend'}: no such file"),
        ([str(tmp_path / "garbage.blend")], f"error: {tmp_path / 'garbage.blend'}: cannot be opened as a .blend"),
        ([str(work / "empty.blend")], f"error: {work / 'empty.blend'}: holds no armature to retarget onto"),
        ([str(work / "prop.blend")], f"error: {work / 'prop.blend'}: holds no armature with hand bones (its "
                                     f"armatures: 'Prop')"),
        ([str(work / "two.blend")], f"error: {work / 'two.blend'}: holds 2 armatures with hand bones "
                                    f"('mixamo_character', 'ue5_character'): name one as two.blend:ARMATURE"),
        ([f"{work / 'two.blend'}:Nope"], f"error: {work / 'two.blend'}: has no armature 'Nope' (its armatures: "
                                         f"'mixamo_character', 'ue5_character')"),
        ([str(work / "char.blend"), "--bone-map", str(tmp_path / "bad.json")],
         f"error: {tmp_path / 'bad.json'}: not a readable bone map JSON"),
        ([str(work / "char.blend"), "--bone-map", str(tmp_path / "wrong.json")],
         f"error: {work / 'char.blend'}: holds no armature with the bone map's bones (its armatures: "
         f"'ue5_character')"),
        ([str(work / "char.blend"), "--bone-map", "no preset of this name"], "error: no preset of this name: no bone "
                                                                             "map preset of that name in "),
    ]
    for more, line in cases:
        code = _solve(work, "--retarget", *more, "--blend", str(blend))
        err = capsys.readouterr().err
        assert code == 1 and err.startswith(line) and err.count("\n") == 1, (more, err)
        assert "Traceback" not in err
    assert not blend.exists()
    for flags in (["--bone-map", "x.json"], ["--pinch"], ["--retarget", str(work / "char.blend")],
                  ["--bone-names", "ue5", "--blend", str(blend)], ["--retarget", "char.fbx", "--blend", str(blend)]):
        assert _solve(work, *flags) == 2, flags
        assert capsys.readouterr().err.startswith("mocap_autolabel solve: error: ")
    _no_partials(tmp_path)


def test_a_saved_bone_map_preset_is_found_by_name(work, bpy_module, tmp_path):
    from mocap_autolabel.blender.retarget import preset_path
    from mocap_autolabel.core.retarget.bone_maps import BoneMap

    name = f"test preset {os.getpid()}"
    path = preset_path(name)
    mapped = {"palm": "hand_r", "index_prox": "index_01_r", "index_mid": "index_02_r", "middle_prox": "middle_01_r",
              "middle_mid": "middle_02_r"}
    BoneMap("ue5", {"right": mapped}).save(path)
    try:
        assert _solve(work, "--retarget", str(work / "char.blend"), "--bone-map", name, "--blend",
                      str(tmp_path / "o.blend"), "--report", str(tmp_path / "r.json")) == 0
    finally:
        os.remove(path)
    assert sorted(json.loads((tmp_path / "r.json").read_text())["retarget"]["hands"]["right"]["bones"]) == \
        sorted(v for k, v in mapped.items() if k != "palm")  # the preset's fingers only; the wrist stays


def test_an_unwritable_output_leaves_no_partial_file(work, bpy_module, tmp_path, capsys):
    (tmp_path / "a_file").write_text("")
    before = _digest(work / "char.blend")
    target = tmp_path / "a_file" / "out.blend"
    assert _solve(work, "--retarget", str(work / "char.blend"), "--blend", str(target)) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"error: {target}: ") and err.count("\n") == 1, err
    assert sorted(os.listdir(tmp_path)) == ["a_file"] and _digest(work / "char.blend") == before
    fbx = tmp_path / "a_file" / "out.fbx"
    assert _solve(work, "--fbx", str(fbx), "--bone-names", "unity") == 1
    assert capsys.readouterr().err.startswith(f"error: {fbx}: ")
    assert sorted(os.listdir(tmp_path)) == ["a_file"]
