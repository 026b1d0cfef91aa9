"""The solve command in the bpy module: the rig in the .blend, and FBX/BVH that re-import with the same joints."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mocap_autolabel.core.formats.c3d import write_c3d
from mocap_autolabel.core.hand.skeleton import BONE_NAMES
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.synth.generate import clean_config, synthesize
from mocap_autolabel.core.take import Take

FRAMES = (1, 37, 150, 299)


@pytest.fixture(scope="module")
def solved(tmp_path_factory, bpy_module):
    """A labeled synthetic take solved by the CLI with every output."""
    from mocap_autolabel.cli import main

    folder = tmp_path_factory.mktemp("solve")
    layout = load_layout("han19")
    synth = synthesize(layout, 300, seed=8, config=clean_config())
    markers = synth.markers + np.random.default_rng(8).normal(0, 0.0005, synth.markers.shape)
    markers[100:130, 5] = np.nan  # a gap: that marker drops out of those frames
    take = Take(positions=markers.astype(np.float32), names=layout.names, rate=120.0, first_frame=1,
                source="labeled.c3d")
    write_c3d(take, folder / "labeled.c3d")
    out = {k: folder / f"out.{k}" for k in ("blend", "fbx", "bvh")}
    code = main(["solve", str(folder / "labeled.c3d"), "--blend", str(out["blend"]), "--fbx", str(out["fbx"]),
                 "--bvh", str(out["bvh"]), "--report", str(folder / "report.json"),
                 "--save-calibration", str(folder / "calib.json")])
    assert code == 0
    return out | {"report": folder / "report.json", "calib": folder / "calib.json", "synth": synth}


def _bone_rotations(bpy, arm, frames=FRAMES) -> dict[str, np.ndarray]:
    """Per bone ``(len(frames), 3, 3)``: its rotation in the world at each frame."""
    scene = bpy.context.scene
    out = {name: [] for name in BONE_NAMES}
    for f in frames:
        scene.frame_set(f)
        world = np.array(arm.matrix_world)[:3, :3]  # an importer may animate the object itself
        world = world / np.linalg.norm(world, axis=0)
        for name in BONE_NAMES:
            out[name].append(world @ np.array(arm.pose.bones[name].matrix)[:3, :3])
    return {n: np.array(v) for n, v in out.items()}


def _changes(rotations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Each bone's rotation since the first frame, in the world: ``R(f) R(f0)^T``.

    Another program may give a bone another rest orientation or roll (a constant factor on the
    right of R); this cancels it, and with every bone's change equal, every joint rotation is.
    """
    return {n: r @ np.swapaxes(r[:1], -1, -2) for n, r in rotations.items()}


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    rel = np.swapaxes(a, -1, -2) @ b
    cos = (np.trace(rel, axis1=-2, axis2=-1) - 1) / 2
    return float(np.degrees(np.arccos(np.clip(cos, -1, 1))).max())


def _reference(bpy, solved):
    bpy.ops.wm.open_mainfile(filepath=str(solved["blend"]))
    return _bone_rotations(bpy, bpy.data.objects["Hand"])


def test_blend_has_the_calibrated_rig_keyed_on_every_solved_frame(bpy_module, solved):
    bpy = bpy_module
    from mocap_autolabel.blender import animio

    bpy.ops.wm.open_mainfile(filepath=str(solved["blend"]))
    arm = bpy.data.objects["Hand"]
    cal = json.loads(arm["mocap_calibration"])
    assert cal["layout"] == "han19" and cal["side"] == solved["synth"].hand.side
    curves = [fc for fc in animio.fcurves_of(arm) if fc.data_path.endswith("rotation_quaternion")]
    assert len(curves) == 4 * len(BONE_NAMES)
    assert {len(fc.keyframe_points) for fc in curves} == {300}
    assert "HandMarkers" in bpy.data.objects and len(bpy.data.objects["HandMarkers"].data.vertices) == 19
    report = json.loads(solved["report"].read_text())
    assert report["solved_frames"] == 300 and report["marker_rms_mm"] < 1.5
    assert len(report["per_frame_rms_mm"]) == 300 and report["per_marker_rms_mm"]["IndexPIP"] is not None


def test_solved_joint_angles_follow_the_truth(bpy_module, solved):
    """The keyed rig and the true hand agree in their joint rotations (a loose, noise-level bound)."""
    bpy = bpy_module
    from mocap_autolabel.blender.armature import build_hand, key_poses

    ours = _reference(bpy, solved)
    synth = solved["synth"]
    truth = build_hand(synth.hand, name="Truth", mesh=False)["armature"]
    key_poses(truth, synth.hand, synth.poses, first_frame=1)
    true_rot = _bone_rotations(bpy, truth)
    errors = [_angle_deg(ours[n], true_rot[n]) for n in BONE_NAMES]
    assert np.median(errors) < 5.0


@pytest.mark.parametrize("kind", ["fbx", "bvh"])
def test_exports_reimport_with_the_same_joint_rotations(bpy_module, solved, kind):
    bpy = bpy_module
    reference = _reference(bpy, solved)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = 120, 1.0
    if kind == "fbx":
        bpy.ops.import_scene.fbx(filepath=str(solved["fbx"]), anim_offset=0.0)  # the default shifts by 1
    else:
        # Blender's BVH exporter writes its own Z-up axes; the importer assumes Y-up unless told.
        bpy.ops.import_anim.bvh(filepath=str(solved["bvh"]), frame_start=1, use_fps_scale=False,
                                axis_forward="Y", axis_up="Z")
    arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
    assert {b.name for b in arm.data.bones} >= set(BONE_NAMES)
    back = _bone_rotations(bpy, arm)
    ref_change, back_change = _changes(reference), _changes(back)
    worst = max(_angle_deg(ref_change[n], back_change[n]) for n in BONE_NAMES)
    assert worst < 0.1, f"{kind}: joint rotations differ by up to {worst:.3f} degrees"


def test_solve_errors_are_one_line(tmp_path, capsys, bpy_module):
    from mocap_autolabel.cli import main

    raw = synthesize(load_layout("han19"), 20, seed=1).take  # unlabeled: *N names
    write_c3d(raw, tmp_path / "raw.c3d")
    assert main(["solve", str(tmp_path / "raw.c3d")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "raw.c3d" in err and "is not labeled with a built-in layout" in err
    assert main(["solve", str(tmp_path / "raw.c3d"), "--fbx", "x.obj"]) == 2
    (tmp_path / "calib.json").write_text("{}")
    assert main(["solve", str(tmp_path / "raw.c3d"), "--calibration", str(tmp_path / "calib.json")]) == 1
    assert "not a valid calibration" in capsys.readouterr().err


def test_solve_operator_on_an_imported_labeled_take(bpy_module, solved, empty_scene, tmp_path):
    bpy = bpy_module
    from mocap_autolabel.blender import animio

    labeled = solved["blend"].parent / "labeled.c3d"
    bpy.ops.mocap_autolabel.import_markers(filepath=str(labeled))
    bpy.context.view_layer.objects.active = bpy.data.objects["IndexTip"]
    calib = tmp_path / "calib.json"
    result = bpy.ops.mocap_autolabel.solve_hand(layout="han19", calibration=str(solved["calib"]),
                                                save_calibration=str(calib))
    assert result == {"FINISHED"}
    arm = bpy.data.objects["Hand"]
    assert json.loads(calib.read_text())["hand_length_mm"] == json.loads(solved["calib"].read_text())["hand_length_mm"]
    assert {len(fc.keyframe_points) for fc in animio.fcurves_of(arm)} == {300}
    # A bad calibration file is one error, and nothing is added.
    objects = len(bpy.data.objects)
    (tmp_path / "bad.json").write_text("[")
    with pytest.raises(RuntimeError, match="bad.json"):
        bpy.ops.mocap_autolabel.solve_hand(layout="han19", calibration=str(tmp_path / "bad.json"))
    assert len(bpy.data.objects) == objects


def test_solve_hand_on_an_imported_take_not_labeled_yet_says_label_it_first(bpy_module, empty_scene, tmp_path):
    bpy = bpy_module
    raw = synthesize(load_layout("han19"), 20, seed=1).take  # unlabeled: *N names
    write_c3d(raw, tmp_path / "raw.c3d")
    assert bpy.ops.mocap_autolabel.import_markers(filepath=str(tmp_path / "raw.c3d")) == {"FINISHED"}
    objects = len(bpy.data.objects)
    with pytest.raises(RuntimeError, match="is not labeled yet .*: label it first .*Label Markers"):
        bpy.ops.mocap_autolabel.solve_hand(layout="han19")
    assert len(bpy.data.objects) == objects


def test_drive_a_users_own_armature_through_a_bone_map(bpy_module):
    """Another rig (other names, rolled bones, moved and turned object) turns bone for bone like ours."""
    bpy = bpy_module
    from mathutils import Matrix
    from mocap_autolabel.blender.armature import build_hand, drive_armature, key_poses

    bpy.ops.wm.read_homefile(use_empty=True)
    synth = synthesize(load_layout("han19"), 120, seed=3, config=clean_config())
    ours = build_hand(synth.hand, name="Ours", mesh=False)["armature"]
    key_poses(ours, synth.hand, synth.poses, first_frame=1)
    theirs = build_hand(synth.hand, name="Theirs", mesh=False)["armature"]
    bpy.context.view_layer.objects.active = theirs
    bpy.ops.object.mode_set(mode="EDIT")
    for i, eb in enumerate(theirs.data.edit_bones):
        eb.roll += 0.3 * i  # other bone rolls than ours
    bpy.ops.object.mode_set(mode="OBJECT")
    for bone in theirs.data.bones:
        bone.name = f"R_{bone.name}"
    theirs.matrix_world = Matrix.Translation((1.0, 2.0, 0.5)) @ Matrix.Rotation(0.7, 4, "Z")
    mapped = [n for n in BONE_NAMES if not n.endswith("_meta")]  # leave some bones unmapped
    drive_armature(theirs, synth.hand, synth.poses, {n: f"R_{n}" for n in mapped}, first_frame=1)
    a = _changes(_bone_rotations(bpy, ours, (1, 40, 80, 120)))
    b = _bone_rotations_named(bpy, theirs, (1, 40, 80, 120), {n: f"R_{n}" for n in mapped})
    worst = {n: round(_angle_deg(a[n], b[n]), 4) for n in mapped}
    assert max(worst.values()) < 0.1, worst  # the bar for joint rotations; measured up to 0.05
    with pytest.raises(ValueError, match="missing"):
        drive_armature(theirs, synth.hand, synth.poses, {"palm": "nope"})


def _bone_rotations_named(bpy, arm, frames, names: dict[str, str]) -> dict[str, np.ndarray]:
    scene = bpy.context.scene
    out = {n: [] for n in names}
    for f in frames:
        scene.frame_set(f)
        world = np.array(arm.matrix_world)[:3, :3]
        for ours, theirs in names.items():
            out[ours].append(world @ np.array(arm.pose.bones[theirs].matrix)[:3, :3])
    return _changes({n: np.array(v) for n, v in out.items()})
