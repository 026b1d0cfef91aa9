"""The raw take as a point cloud driven by geometry nodes (bpy module, no mocks): the positions shown at a
frame are the take's, missing samples are not shown, it survives save and reopen, and labeling and review
work on it as on keyed empties. Also: the keyed import's keys equal the file's samples exactly."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import save_and_reopen, select, small_take
from mocap_autolabel.core.formats.c3d import write_c3d
from mocap_autolabel.core.take import read_take


def _import(bpy, path, **kw):
    assert bpy.ops.mocap_autolabel.import_markers(filepath=str(path), **kw) == {"FINISHED"}
    return bpy.context.scene.mocap_autolabel.take


def _cloud(coll):
    from mocap_autolabel.blender.review import raw_cloud

    obj = raw_cloud(coll)
    assert obj is not None
    return obj


def _shown(bpy, obj, frame: int) -> tuple[np.ndarray, np.ndarray]:
    """(positions (n, 3), marker columns (n,)) of the points the cloud shows at ``frame``."""
    bpy.context.scene.frame_set(frame)
    deps = bpy.context.evaluated_depsgraph_get()
    for inst in deps.object_instances:
        if inst.object.original == obj and inst.object.type == "POINTCLOUD":
            cloud = inst.object.data
            n = len(cloud.points)
            pos = np.empty(n * 3, np.float32)
            cloud.attributes["position"].data.foreach_get("vector", pos)
            col = np.empty(n, np.int32)
            cloud.attributes["marker"].data.foreach_get("value", col)
            return pos.reshape(n, 3), col
    return np.zeros((0, 3), np.float32), np.zeros(0, np.int32)


@pytest.fixture
def gappy(tmp_path):
    take = small_take(frames=60, points=5)
    path = tmp_path / "gappy.c3d"
    write_c3d(take, path)
    return read_take(path), path  # the file's own float32 samples


def test_point_cloud_shows_each_frames_samples_and_hides_the_missing(empty_scene, bpy_module, gappy):
    bpy = bpy_module
    take, path = gappy
    coll = _import(bpy, path, as_point_cloud=True, scale=2.0, frame_offset=10)
    assert len(coll.objects) == 1  # one object, no empties
    obj = _cloud(coll)
    assert obj.animation_data is None and not bpy.data.actions  # no keys at all
    assert list(obj["mocap_names"]) == take.names
    first = take.first_frame + 10
    for index in (0, 5, 7, 20, take.n_frames - 1):  # 5..8 miss point 0, 20 point 1, the last 3 point 4
        pos, col = _shown(bpy, obj, first + index)
        valid = take.valid[index]
        np.testing.assert_array_equal(col, np.flatnonzero(valid))
        np.testing.assert_array_equal(pos, take.positions[index, valid] * np.float32(2.0))
    for outside in (first - 1, first + take.n_frames):  # no point before or after the take
        assert len(_shown(bpy, obj, outside)[0]) == 0
    scene = bpy.context.scene
    assert (scene.frame_start, scene.frame_end) == (first, first + take.n_frames - 1)


def test_point_cloud_reads_back_exactly_after_save_and_reopen(empty_scene, bpy_module, gappy, tmp_path):
    from mocap_autolabel.blender.review import current_take

    bpy = bpy_module
    take, path = gappy
    coll = _import(bpy, path, as_point_cloud=True)
    coll = save_and_reopen(bpy, tmp_path / "cloud.blend")
    back = current_take(coll)
    np.testing.assert_array_equal(back.positions, take.positions)  # NaN where missing, bit for bit
    assert back.names == take.names and back.first_frame == take.first_frame and back.rate == take.rate
    pos, col = _shown(bpy, _cloud(coll), take.first_frame + 6)
    np.testing.assert_array_equal(col, np.flatnonzero(take.valid[6]))
    np.testing.assert_array_equal(pos, take.positions[6, take.valid[6]])


def test_point_cloud_of_some_points_reads_back_the_others_as_missing(empty_scene, bpy_module, tmp_path):
    from mocap_autolabel.blender.review import current_take

    bpy = bpy_module
    take = small_take(frames=30, points=4)
    take.names[:] = ["ThumbTip", "IndexTip", "Wrist", "ThumbBase"]
    path = tmp_path / "named.c3d"
    write_c3d(take, path)
    take = read_take(path)
    coll = _import(bpy, path, as_point_cloud=True, name_filter="thumb*")
    obj = _cloud(coll)
    assert list(obj["mocap_slots"]) == [0, 3] and list(obj["mocap_names"]) == ["ThumbTip", "ThumbBase"]
    back = current_take(coll)
    assert back.names == ["ThumbTip", "*1", "*2", "ThumbBase"]
    np.testing.assert_array_equal(back.positions[:, [0, 3]], take.positions[:, [0, 3]])
    assert np.isnan(back.positions[:, [1, 2]]).all()
    pos, col = _shown(bpy, obj, take.first_frame + 2)
    np.testing.assert_array_equal(pos, take.positions[2, [0, 3]])


@pytest.fixture(scope="module")
def hand_file(tmp_path_factory):
    from mocap_autolabel.core.layout import load_layout
    from mocap_autolabel.core.synth.generate import synthesize

    take = synthesize(load_layout("han19"), 400, seed=5).take
    path = tmp_path_factory.mktemp("cloud") / "hand.c3d"
    write_c3d(take, path)
    return path


def _label(bpy):
    bpy.context.scene.mocap_autolabel.layout = "han19"
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    return bpy.context.scene.mocap_autolabel.take


def test_label_and_review_work_on_a_point_cloud_take(empty_scene, bpy_module, hand_file, tmp_path):
    """The same labels as with keyed empties; the labeled markers are keyed empties; the cloud moves into the
    hidden Raw collection; corrections, re-solve and export work, also after save and reopen without the
    source file."""
    import os
    import shutil

    from mocap_autolabel.blender.review import load_state
    from mocap_autolabel.core.labeling import EMPTY, NULL

    bpy = bpy_module
    keyed = _label_import(bpy, hand_file, tmp_path, "keyed.c3d", as_point_cloud=False)
    bpy.ops.wm.read_homefile(use_empty=True)
    src = shutil.copy(hand_file, tmp_path / "cloud.c3d")
    _import(bpy, src, as_point_cloud=True)
    coll = _label(bpy)
    state = load_state(coll)
    np.testing.assert_array_equal(state.labeling.per_sample(), keyed.per_sample())
    labeled = {int(o["mocap_label"]): o for o in coll["mocap_labeled"].objects}
    assert len(labeled) == 19 and all(o.animation_data is not None for o in labeled.values())
    cloud = _cloud(coll)
    assert cloud.name in coll["mocap_raw"].objects and cloud.name not in coll.objects
    # a correction on a labeled marker, then save, reopen without the source and re-solve
    lab = state.labeling
    a = lab.names.index("MiddleTip")
    present = np.flatnonzero((lab.per_sample() == a).any(axis=1))
    frame = int(present[len(present) // 2])
    bpy.context.scene.frame_set(frame + int(coll["mocap_first"]))
    select(bpy, labeled[a])
    assert bpy.ops.mocap_autolabel.unlabel() == {"FINISHED"}
    constraints = load_state(coll).review.constraints
    coll = save_and_reopen(bpy, tmp_path / "cloud.blend")
    os.remove(src)
    assert bpy.ops.mocap_autolabel.resolve() == {"FINISHED"}
    after = load_state(coll)
    assert after.review.constraints == constraints
    c = constraints[0]
    got = after.labeling.per_sample()[c.start:c.stop, c.slot]
    assert len(got) and (got[got != EMPTY] == NULL).all()
    out = tmp_path / "labeled.c3d"
    assert bpy.ops.mocap_autolabel.export_labeled(filepath=str(out)) == {"FINISHED"}
    back, raw = read_take(out), read_take(hand_file)
    assert back.valid.sum() == raw.valid.sum()  # every sample once


def _label_import(bpy, path, tmp_path, name, **kw):
    import shutil

    from mocap_autolabel.blender.review import load_state

    _import(bpy, shutil.copy(path, tmp_path / name), **kw)
    return load_state(_label(bpy)).labeling


def test_keyed_import_keys_equal_the_files_samples_exactly(empty_scene, bpy_module, gappy):
    """One key per sample, bit for bit the file's float32 value times the Scale; LINEAR between samples,
    CONSTANT on the last key before a gap; none inside a gap; hidden while missing."""
    from mocap_autolabel.blender import animio

    bpy = bpy_module
    take, path = gappy
    coll = _import(bpy, path, scale=0.5)
    frames_all = np.arange(take.n_frames, dtype=np.float32) + take.first_frame
    lin, const = animio.interpolation_value("LINEAR"), animio.interpolation_value("CONSTANT")
    for obj in coll.objects:
        slot = int(obj["mocap_slot"])
        valid = take.valid[:, slot]
        idx = np.flatnonzero(valid)
        for axis in range(3):
            fc = animio.find_fcurve(obj, "location", axis)
            frames, values = animio.read_keys(fc)
            np.testing.assert_array_equal(frames, frames_all[valid])
            np.testing.assert_array_equal(values, take.positions[valid, slot, axis] * np.float32(0.5))
            interp = np.empty(len(frames), np.uint8)
            fc.keyframe_points.foreach_get("interpolation", interp)
            expected = np.full(len(frames), lin)
            expected[:-1][np.diff(idx) > 1] = const
            np.testing.assert_array_equal(interp, expected)
        for f in range(take.n_frames):
            bpy.context.scene.frame_set(int(frames_all[f]))
            assert obj.hide_viewport == (not valid[f]), (obj.name, f)


def test_the_import_suggests_a_point_cloud_for_a_very_long_take(bpy_module):
    from mocap_autolabel.blender.scene import ImportOptions
    from mocap_autolabel.operators.import_markers import SUGGEST_POINT_CLOUD, _suggestion

    assert _suggestion(ImportOptions(), SUGGEST_POINT_CLOUD - 1) == ""
    assert "As Point Cloud" in _suggestion(ImportOptions(), 216_000 * 50)
    assert _suggestion(ImportOptions(as_point_cloud=True), 216_000 * 50) == ""


def test_two_point_cloud_takes_keep_apart(empty_scene, bpy_module, gappy, tmp_path):
    """A second take gets its collection's prefix (never .001), shares the one node group, and each reads
    back its own samples."""
    from mocap_autolabel.blender.pointcloud import CLOUD_NAME
    from mocap_autolabel.blender.review import current_take

    bpy = bpy_module
    take, path = gappy
    first = _cloud(_import(bpy, path, as_point_cloud=True))
    coll2 = _import(bpy, path, as_point_cloud=True, frame_offset=100)
    second = _cloud(coll2)
    assert first.name == CLOUD_NAME and second.name == f"{coll2.name}:{CLOUD_NAME}"
    assert len([g for g in bpy.data.node_groups if "mocap_cloud_version" in g]) == 1
    np.testing.assert_array_equal(current_take(coll2).positions, take.positions)
    pos, _ = _shown(bpy, second, take.first_frame + 100 + 6)
    np.testing.assert_array_equal(pos, take.positions[6, take.valid[6]])
