"""The import operator in a real headless Blender (the bpy module)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import data_path
from helpers import small_take
from mocap_autolabel.core.formats.c3d import write_c3d
from mocap_autolabel.core.take import read_take

RAW = ("c3d", "auto-marker-label/data/S01_Pronetokneel01_mksrem.c3d")  # unlabeled *N, 20 % missing


def _animio():
    from mocap_autolabel.blender import animio

    return animio


def test_operator_imports_real_unlabeled_take(empty_scene, bpy_module):
    path = data_path(*RAW)
    take = read_take(path)
    bpy_module.ops.mocap_autolabel.import_markers(filepath=str(path))
    collection = bpy_module.data.collections["S01_Pronetokneel01_mksrem"]
    assert len(collection.objects) == take.n_points
    animio = _animio()
    frames_all = np.arange(take.n_frames) + take.first_frame
    for obj in collection.objects:
        slot = obj["mocap_slot"]
        valid = take.valid[:, slot]
        for axis in range(3):
            frames, values = animio.read_keys(animio.find_fcurve(obj, "location", axis))
            # One key per valid sample, equal to it; none inside a gap.
            np.testing.assert_array_equal(frames, frames_all[valid])
            np.testing.assert_allclose(values, take.positions[valid, slot, axis], atol=1e-6)
        if not valid.all():
            hide_frames, hidden = animio.read_keys(animio.find_fcurve(obj, "hide_viewport"))
            state = np.interp(frames_all, hide_frames, hidden, left=0)  # CONSTANT keys: sample at keys
            idx = np.searchsorted(hide_frames, frames_all, side="right") - 1
            np.testing.assert_array_equal(hidden[idx] > 0.5, ~valid)
            assert state.shape == valid.shape
    scene = empty_scene
    assert scene.render.fps / scene.render.fps_base == pytest.approx(take.rate)
    assert (scene.frame_start, scene.frame_end) == (take.first_frame, take.first_frame + take.n_frames - 1)


def test_no_interpolation_across_gaps(empty_scene, bpy_module, tmp_path):
    take = small_take(frames=40, points=3)
    path = tmp_path / "gappy.c3d"
    write_c3d(take, path)
    bpy_module.ops.mocap_autolabel.import_markers(filepath=str(path))
    obj = bpy_module.data.collections["gappy"].objects["*0"]  # gap at frames 5..8 (0-based)
    fc = _animio().find_fcurve(obj, "location", 0)
    before_gap = [k for k in fc.keyframe_points if k.co[0] == take.first_frame + 4][0]
    assert before_gap.interpolation == "CONSTANT"
    assert fc.evaluate(take.first_frame + 6) == pytest.approx(take.positions[4, 0, 0], abs=1e-6)
    scene = empty_scene
    scene.frame_set(take.first_frame + 6)
    assert obj.hide_viewport
    scene.frame_set(take.first_frame + 10)
    assert not obj.hide_viewport


def test_options_scale_offset_and_name_filter(empty_scene, bpy_module, tmp_path):
    take = small_take(frames=30, points=4)
    take.names = ["ThumbTip", "IndexTip", "*2", "*3"]
    path = tmp_path / "opts.c3d"
    write_c3d(take, path)
    bpy_module.ops.mocap_autolabel.import_markers(filepath=str(path), scale=10.0, frame_offset=100,
                                                  name_filter="*tip")
    objs = {o.name: o for o in bpy_module.data.collections["opts"].objects}
    assert set(objs) == {"ThumbTip", "IndexTip"}
    frames, values = _animio().read_keys(_animio().find_fcurve(objs["IndexTip"], "location", 2))
    assert frames[0] == take.first_frame + 100
    np.testing.assert_allclose(values, 10.0 * take.positions[take.valid[:, 1], 1, 2], rtol=1e-5)
    assert empty_scene.frame_start == take.first_frame + 100


def test_non_integer_rate(empty_scene, bpy_module):
    path = data_path("c3d", "kineticstoolkit/data/kinematics/racing_full.c3d")  # 69.993 Hz
    bpy_module.ops.mocap_autolabel.import_markers(filepath=str(path))
    scene = empty_scene
    assert scene.render.fps / scene.render.fps_base == pytest.approx(69.99261, abs=1e-4)


def test_bad_file_reports_error_without_crash(empty_scene, bpy_module, tmp_path):
    bad = tmp_path / "noise.c3d"
    bad.write_bytes(b"\x00" * 4000)
    with pytest.raises(RuntimeError, match="noise.c3d.*not a C3D file"):
        bpy_module.ops.mocap_autolabel.import_markers(filepath=str(bad))
    assert len(bpy_module.data.collections) == 0


@pytest.mark.parametrize("scale", [0.0, -1.0])
def test_a_scale_of_zero_or_below_is_refused_and_imports_nothing(empty_scene, bpy_module, tmp_path, scale):
    """Blender clamped Scale 0 or -1 to 1e-6 and the import reported success."""
    path = tmp_path / "take.c3d"
    write_c3d(small_take(frames=20, points=3), path)
    with pytest.raises(RuntimeError) as info:  # the operator's ERROR report, as bpy.ops shows it to a script
        bpy_module.ops.mocap_autolabel.import_markers(filepath=str(path), scale=scale)
    assert str(info.value).strip().splitlines()[-1] == f"Error: Scale must be above 0 (got {scale:g}); nothing imported"
    assert len(bpy_module.data.collections) == 0 and len(bpy_module.data.objects) == 0
    assert bpy_module.ops.mocap_autolabel.import_markers(filepath=str(path), scale=0.001) == {"FINISHED"}


@pytest.mark.parametrize("name, text", [
    ("empty.trc", "PathFileType\t4\t(X/Y/Z)\tempty.trc\nDataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\n"
                  "120\t120\t0\t2\tmm\nFrame#\tTime\ta\t\t\tb\nX1\tY1\tZ1\tX2\tY2\tZ2\n"),
    ("empty.tsv", "NO_OF_FRAMES\t0\nNO_OF_MARKERS\t2\nFREQUENCY\t100\nMARKER_NAMES\ta\tb\n")])
def test_a_file_of_no_frames_says_so(empty_scene, bpy_module, tmp_path, name, text):
    """A TRC or TSV with a header and no data rows was reported as "no marker points (analog data only?)"."""
    path = tmp_path / name
    path.write_text(text)
    assert read_take(path).n_points == 2
    with pytest.raises(RuntimeError, match=f"{name}: the file holds no frames .*; nothing imported") as info:
        bpy_module.ops.mocap_autolabel.import_markers(filepath=str(path))
    assert "analog" not in str(info.value) and len(bpy_module.data.collections) == 0


def test_menu_and_file_handler_registered(bpy_module):
    assert hasattr(bpy_module.types, "MOCAPAL_FH_markers")
    fh = bpy_module.types.MOCAPAL_FH_markers
    assert fh.bl_import_operator == "mocap_autolabel.import_markers"
    assert ".c3d" in fh.bl_file_extensions
    menu_funcs = [f.__name__ for f in bpy_module.types.TOPBAR_MT_file_import._dyn_ui_initialize()]
    assert "menu_import" in menu_funcs


def test_animio_slotted_and_legacy_paths_agree(empty_scene, bpy_module):
    """The 4.4+ path (slots/layers/channel bags) is what bpy 5.0 runs; 4.2's action.fcurves is gone."""
    animio = _animio()
    obj = bpy_module.data.objects.new("probe", None)
    empty_scene.collection.objects.link(obj)
    animio.ensure_action(obj)
    fc = animio.new_fcurve(obj, "location", 1, group="Location")
    animio.write_keys(fc, np.array([1, 2, 5], np.float32), np.array([0.5, 0.25, -1.0], np.float32))
    assert animio.SLOTTED == hasattr(bpy_module.types, "ActionSlot")
    if animio.SLOTTED:
        assert obj.animation_data.action_slot is not None
        assert not hasattr(obj.animation_data.action, "fcurves") or bpy_module.app.version < (5, 0, 0)
    frames, values = animio.read_keys(animio.find_fcurve(obj, "location", 1))
    np.testing.assert_array_equal(frames, [1, 2, 5])
    empty_scene.frame_set(2)
    assert obj.location[1] == pytest.approx(0.25)


@pytest.mark.parametrize("offset", [-5000, -300, 1_048_574])
def test_a_frame_offset_that_puts_frames_outside_the_scene_is_refused(empty_scene, bpy_module, tmp_path, offset):
    """Issue 47: Blender's scene range holds frames 0 to 1,048,574. At -5,000 the range became 0-0 with every
    key before it, and Next found nothing; at -300 Next from the start skipped every segment before frame 0."""
    take = small_take(frames=600, points=3)
    path = tmp_path / "take.c3d"
    write_c3d(take, path)
    scene = empty_scene
    scene.frame_start, scene.frame_end = 1, 250
    with pytest.raises(RuntimeError) as info:
        bpy_module.ops.mocap_autolabel.import_markers(filepath=str(path), frame_offset=offset)
    first = take.first_frame + offset
    assert str(info.value).strip().splitlines()[-1] == (
        f"Error: take.c3d: Frame Offset {offset} puts the take at frames {first} to {first + 599}, outside the "
        f"frames 0 to 1048574 a Blender scene holds; use a Frame Offset from {-take.first_frame} to "
        f"{1048574 - take.first_frame - 599}; nothing imported")
    assert len(bpy_module.data.collections) == 0 and len(bpy_module.data.objects) == 0
    assert (scene.frame_start, scene.frame_end) == (1, 250)
    # The lowest offset it names puts the take's first frame on frame 0, the range showing all of it.
    assert bpy_module.ops.mocap_autolabel.import_markers(filepath=str(path), frame_offset=-take.first_frame) \
        == {"FINISHED"}
    assert (scene.frame_start, scene.frame_end, scene.frame_current) == (0, 599, 0)
