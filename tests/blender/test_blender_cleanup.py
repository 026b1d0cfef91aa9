"""The Cleanup panel's tools in the bpy module (issue 48), on the labeled demo take: Find Spikes, Smooth,
Delete Short Fragments, the Fill Preview and Quick Label; each with its undo and its one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import import_take as _import
from helpers import review_state as state
from helpers import select as _select
from mocap_autolabel.core.labeling import NULL

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "samples" / "demo_take.c3d"


@pytest.fixture(scope="module")
def demo_blend(bpy_module, tmp_path_factory):
    """The demo take imported and labeled once, saved: each test opens its own copy."""
    bpy = bpy_module
    folder = tmp_path_factory.mktemp("cleanup")
    bpy.ops.wm.read_homefile(use_empty=True)
    coll = _import(bpy, DEMO, folder)
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    path = folder / "labeled.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path, coll.name


@pytest.fixture
def labeled(empty_scene, bpy_module, demo_blend):
    bpy = bpy_module
    path, name = demo_blend
    bpy.ops.wm.open_mainfile(filepath=str(path))
    coll = bpy.data.collections[name]
    assert bpy.context.scene.mocap_autolabel.take == coll
    return bpy, coll


def _labeled(coll) -> dict:
    return {o.name: o for o in coll["mocap_labeled"].all_objects}


def _keys(obj) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An empty's location keys: frames (int), ``(n, 3)`` values and key type names."""
    from mocap_autolabel.blender import animio

    curves = [animio.find_fcurve(obj, "location", axis) for axis in range(3)]
    frames = np.rint(animio.read_keys(curves[0])[0]).astype(int)
    xyz = np.stack([animio.read_keys(c)[1] for c in curves], axis=1)
    names = {v: k for k, v in animio._KEY_TYPE.items()}
    return frames, xyz, np.array([names[v] for v in animio.read_key_types(curves[0])])


def _raw(coll, slot: int):
    from mocap_autolabel.blender.takes import raw_markers

    return next(o for o in raw_markers(coll) if o["mocap_slot"] == slot)


def _shift_raw(coll, slot: int, frames, offset) -> None:
    """Move a raw trajectory's samples at Blender ``frames`` by ``offset`` ``(len(frames), 3)`` or ``(3,)``
    scene units: an edit of its keys, as a hand in the Graph Editor makes."""
    from mocap_autolabel.blender import animio

    obj = _raw(coll, slot)
    offset = np.broadcast_to(np.asarray(offset, dtype=np.float32), (len(frames), 3))
    for axis in range(3):
        fc = animio.find_fcurve(obj, "location", axis)
        co = np.empty(2 * len(fc.keyframe_points), dtype=np.float32)
        fc.keyframe_points.foreach_get("co", co)
        at = np.searchsorted(co[0::2], np.asarray(frames, dtype=np.float32))
        co[2 * at + 1] += offset[:, axis]
        fc.keyframe_points.foreach_set("co", co)
        fc.update()


def _carrier(coll, name: str) -> int:
    """The one raw trajectory that carries a label over the whole take."""
    lab = state(coll).labeling
    slots = np.unique(lab.slot[lab.label == lab.names.index(name)])
    assert len(slots) == 1
    return int(slots[0])


def _undo_around(bpy, op) -> None:
    """Run ``op`` as its own undo step (the UI pushes one after each REGISTER/UNDO operator), then undo it."""
    bpy.ops.ed.undo_push(message="before")
    op()
    bpy.ops.ed.undo_push(message="after")
    bpy.ops.ed.undo()


def test_the_panel_defaults_are_the_cores_and_the_tools_are_registered(bpy_module):
    from mocap_autolabel.blender import cleanup_settings as ui
    from mocap_autolabel.core import cleanup, fill

    assert (ui.MAX_ACCEL, ui.MAX_SPEED, ui.FILTER_ORDER, ui.MAX_GAP) == (cleanup.MAX_ACCEL, cleanup.MAX_SPEED,
                                                                       cleanup.FILTER_ORDER, fill.MAX_GAP)
    bpy = bpy_module
    assert bpy.types.MOCAPAL_PT_cleanup.bl_parent_id == "MOCAPAL_PT_review"
    from mocap_autolabel.operators import cleanup as ops

    for cls in ops.classes:
        assert cls.bl_options >= {"REGISTER", "UNDO"}, cls.bl_idname
        assert hasattr(bpy.ops.mocap_autolabel, cls.bl_idname.split(".")[1])


def test_tools_need_a_labeled_take(empty_scene, bpy_module, tmp_path):
    bpy = bpy_module
    _import(bpy, DEMO, tmp_path)  # imported, not labeled
    for op in (bpy.ops.mocap_autolabel.find_spikes, bpy.ops.mocap_autolabel.smooth,
               bpy.ops.mocap_autolabel.delete_short_fragments, bpy.ops.mocap_autolabel.quick_label):
        with pytest.raises(RuntimeError, match="Label a take first"):
            op()
    with pytest.raises(RuntimeError, match="Select a labeled marker"):
        bpy.ops.mocap_autolabel.fill_preview()
    with pytest.raises(RuntimeError, match="Preview the fill of a labeled marker first"):
        bpy.ops.mocap_autolabel.fill_preview_apply()


# --- Find Spikes ----------------------------------------------------------------------------------

def test_find_spikes_marks_injected_spikes_for_review_and_undo_takes_them_back(labeled, capfd):
    bpy, coll = labeled
    scene = bpy.context.scene
    first = int(coll["mocap_first"])
    _select(bpy)
    assert bpy.ops.mocap_autolabel.find_spikes() == {"FINISHED"}
    assert "No suspect samples on the labeled markers" in capfd.readouterr().out  # the take as recorded
    assert not state(coll).review.splits

    slot = _carrier(coll, "IndexMCP")
    spiked = [first + 300, first + 301, first + 700]
    _shift_raw(coll, slot, spiked, [[0.012, 0, 0], [0.013, 0.002, 0], [0, 0, -0.015]])
    name = coll.name
    bpy.ops.ed.undo_push(message="spiked")
    assert bpy.ops.mocap_autolabel.find_spikes() == {"FINISHED"}
    out = capfd.readouterr().out
    assert f"3 suspect samples on 1 marker (IndexMCP {first + 300}-{first + 301}, {first + 700}): marked very " \
        "uncertain for review" in out
    # The keys of the suspect samples (and only those) take the very-uncertain colour.
    frames, _, types = _keys(_labeled(coll)["IndexMCP"])
    assert set(frames[types == "EXTREME"]) == set(spiked)
    # Each spike is a piece of its own, very uncertain, cut by splits a re-solve keeps.
    lab = state(coll).labeling
    mine = np.flatnonzero((lab.slot == slot) & (lab.confidence == 0.0))
    assert sorted((int(lab.start[i]), int(lab.stop[i])) for i in mine) == [(300, 302), (700, 701)]
    assert sorted(state(coll).review.splits) == [(slot, 300), (slot, 302), (slot, 700), (slot, 701)]
    # The review queue shows them: the panel's list, and Next walks to them.
    rows = [(r.label, r.frame_start, r.frame_end) for r in scene.mocap_autolabel.uncertain]
    assert ("IndexMCP", first + 300, first + 301) in rows and ("IndexMCP", first + 700, first + 700) in rows
    scene.frame_set(first + 299)
    scene.mocap_autolabel.walk_slot = -1
    visited = []
    for _ in range(60):
        if bpy.ops.mocap_autolabel.next_uncertain() != {"FINISHED"} or scene.frame_current > first + 700:
            break
        visited.append((scene.frame_current, bpy.context.active_object.name))
    assert (first + 300, "IndexMCP") in visited and (first + 700, "IndexMCP") in visited

    bpy.ops.ed.undo_push(message="Find Spikes")
    bpy.ops.ed.undo()
    coll = bpy.data.collections[name]
    frames, _, types = _keys(_labeled(coll)["IndexMCP"])
    assert "EXTREME" not in set(types[np.isin(frames, spiked)])
    assert not state(coll).review.splits and not (state(coll).labeling.confidence == 0.0).any()


def test_find_spikes_thresholds_come_from_the_panel(labeled, capfd):
    bpy, coll = labeled
    first = int(coll["mocap_first"])
    _shift_raw(coll, _carrier(coll, "IndexMCP"), [first + 500], [0.008, 0, 0])  # an 8 mm one-frame spike
    _select(bpy, _labeled(coll)["IndexMCP"])
    settings = bpy.context.scene.mocap_autolabel.cleanup
    settings.max_accel = 100.0  # a course allowed to turn that hard hides an 8 mm spike
    assert bpy.ops.mocap_autolabel.find_spikes() == {"FINISHED"}
    assert "No suspect samples on 1 selected marker (max acceleration 100 m/s²" in capfd.readouterr().out
    settings.max_accel = 20.0
    assert bpy.ops.mocap_autolabel.find_spikes() == {"FINISHED"}
    assert "1 suspect sample on 1 marker" in capfd.readouterr().out


# --- Smooth ---------------------------------------------------------------------------------------

def test_smooth_removes_a_wiggle_without_lag_keeps_gaps_and_undo_restores(labeled, capfd):
    from mocap_autolabel.blender.takes import current_take

    bpy, coll = labeled
    name, first, rate = coll.name, int(coll["mocap_first"]), float(coll["mocap_rate"])
    objs = _labeled(coll)
    f_clean, clean, _ = _keys(objs["IndexMCP"])
    gappy_frames, gappy, gappy_types = _keys(objs["IndexTip"])
    thumb = _keys(objs["ThumbTip"])
    assert len(gappy_frames) < len(f_clean)  # IndexTip has gaps
    # A 2 mm wiggle at 40 Hz on IndexMCP's trajectory.
    slot = _carrier(coll, "IndexMCP")
    wiggle = 0.002 * np.sin(2 * np.pi * 40.0 * np.arange(len(f_clean)) / rate)
    _shift_raw(coll, slot, f_clean, np.stack([wiggle, 0 * wiggle, 0 * wiggle], axis=1))

    with pytest.raises(RuntimeError, match=r"Cut-off of 70 Hz is not below the Nyquist frequency \(60 Hz"):
        bpy.ops.mocap_autolabel.smooth(cutoff_hz=70.0)
    _select(bpy, objs["IndexMCP"], objs["IndexTip"])
    bpy.ops.ed.undo_push(message="before")
    assert bpy.ops.mocap_autolabel.smooth(cutoff_hz=8.0) == {"FINISHED"}
    assert "Smoothed 2 selected markers" in capfd.readouterr().out
    bpy.ops.ed.undo_push(message="Smooth")

    frames, smooth, _ = _keys(objs["IndexMCP"])
    np.testing.assert_array_equal(frames, f_clean)
    inner = slice(30, -30)
    t = np.arange(len(frames))[inner] / rate

    def amplitude(x):  # of the 40 Hz component of a departure from the recorded motion
        return 2 * np.hypot(np.mean(x * np.sin(2 * np.pi * 40 * t)), np.mean(x * np.cos(2 * np.pi * 40 * t)))

    assert amplitude(wiggle[inner]) > 0.0019
    assert amplitude(smooth[inner, 0] - clean[inner, 0]) < 0.0001  # the wiggle is gone
    # ... and the motion is where it was: no lag (the closest shift is none), within a millimetre RMS.
    err = {k: np.sqrt(np.mean((smooth[30:-30] - clean[30 + k:len(clean) - 30 + k]) ** 2)) for k in range(-5, 6)}
    assert min(err, key=err.get) == 0 and err[0] < 0.001
    # Gaps stay gaps; markers not selected are untouched; the take itself holds the smoothed samples.
    frames, values, types = _keys(objs["IndexTip"])
    np.testing.assert_array_equal(frames, gappy_frames)
    assert list(types) == list(gappy_types) and np.abs(values - gappy).max() > 1e-5
    after = _keys(objs["ThumbTip"])
    np.testing.assert_array_equal(after[1], thumb[1])
    scale = float(coll["mocap_scale"])
    take = current_take(coll)
    np.testing.assert_allclose(take.positions[f_clean - first, slot] * scale, smooth, atol=1e-6)

    bpy.ops.ed.undo()
    coll = bpy.data.collections[name]
    _, back, _ = _keys(_labeled(coll)["IndexMCP"])
    np.testing.assert_allclose(back[:, 0], clean[:, 0], atol=1e-6)  # the labeled keys as they were...
    take = current_take(coll)  # ... and the take the session reads, without a hint to read it again
    np.testing.assert_allclose(take.positions[f_clean - first, slot, 0] * scale, clean[:, 0] + wiggle, atol=1e-6)


def test_smooth_keeps_fills_as_they_were(labeled, capfd):
    bpy, coll = labeled
    objs = _labeled(coll)
    _select(bpy, objs["IndexTip"])
    assert bpy.ops.mocap_autolabel.fill_gaps(method="spline") == {"FINISHED"}
    frames, values, types = _keys(objs["IndexTip"])
    assert (types == "GENERATED").sum() > 0
    assert bpy.ops.mocap_autolabel.smooth() == {"FINISHED"}  # the panel's 10 Hz
    assert "the fills of 1 marker kept as they were" in capfd.readouterr().out
    after_frames, after, after_types = _keys(objs["IndexTip"])
    np.testing.assert_array_equal(after_frames, frames)
    np.testing.assert_array_equal(after_types, types)
    filled = types == "GENERATED"
    np.testing.assert_array_equal(after[filled], values[filled])
    assert np.abs(after[~filled] - values[~filled]).max() > 1e-5
    assert '"label": 6' in coll["mocap_fill"]


def test_smooth_on_a_take_imported_as_a_point_cloud(empty_scene, bpy_module, tmp_path):
    from mocap_autolabel.blender.takes import current_take

    bpy = bpy_module
    path = tmp_path / "demo_take.c3d"
    path.write_bytes(DEMO.read_bytes())
    assert bpy.ops.mocap_autolabel.import_markers(filepath=str(path), as_point_cloud=True) == {"FINISHED"}
    coll = bpy.context.scene.mocap_autolabel.take
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    before = current_take(coll).positions.copy()
    thumb = _keys(_labeled(coll)["ThumbTip"])[1]
    _select(bpy, _labeled(coll)["ThumbTip"])
    assert bpy.ops.mocap_autolabel.smooth(cutoff_hz=5.0) == {"FINISHED"}
    after = current_take(coll).positions
    moved = np.flatnonzero(np.nanmax(np.abs(after - before), axis=(0, 2)) > 1e-6)
    assert moved.tolist() == np.unique(state(coll).labeling.slot[state(coll).labeling.label == 3]).tolist()
    assert np.abs(_keys(_labeled(coll)["ThumbTip"])[1] - thumb).max() > 1e-5


# --- Delete Short Fragments -----------------------------------------------------------------------

def test_delete_short_fragments_unlabels_them_for_good_and_undo_restores(labeled, capfd):
    from mocap_autolabel.core.cleanup_labels import carriers

    bpy, coll = labeled
    name, first = coll.name, int(coll["mocap_first"])
    lab = state(coll).labeling
    before_keys = {n: _keys(o)[0] for n, o in _labeled(coll).items()}
    valid = carriers(lab) >= 0
    # The runs of each label shorter than 10 frames, found here on their own.
    short = np.zeros(valid.shape, dtype=bool)
    for m in range(valid.shape[1]):
        edges = np.flatnonzero(np.diff(np.concatenate([[0], valid[:, m].astype(int), [0]])))
        for a, b in zip(edges[::2], edges[1::2]):
            if b - a < 10:
                short[a:b, m] = True
    assert short.sum() > 0
    _select(bpy)
    bpy.ops.ed.undo_push(message="before")
    assert bpy.ops.mocap_autolabel.delete_short_fragments(min_frames=10) == {"FINISHED"}
    out = capfd.readouterr().out
    assert f"Deleted {int(short.sum())} samples in runs shorter than 10 frames" in out
    bpy.ops.ed.undo_push(message="Delete Short Fragments")
    after = state(coll)
    f, m = np.nonzero(short)
    slots = carriers(lab)[f, m]
    assert (after.labeling.per_sample()[f, slots] == NULL).all()
    assert all(c.label == NULL for c in after.review.constraints) and after.review.constraints
    for n, obj in _labeled(coll).items():
        gone = set(np.flatnonzero(short[:, lab.names.index(n)]) + first)
        assert set(_keys(obj)[0]) == set(before_keys[n]) - gone, n
    # A re-solve keeps them off the labels (corrections).
    assert bpy.ops.mocap_autolabel.resolve() == {"FINISHED"}
    assert (state(coll).labeling.per_sample()[f, slots] == NULL).all()
    # Nothing shorter than 1 frame.
    assert bpy.ops.mocap_autolabel.delete_short_fragments(min_frames=1) == {"FINISHED"}
    assert "No run shorter than 1 frames on the labeled markers" in capfd.readouterr().out

    bpy.ops.ed.undo()
    coll = bpy.data.collections[name]
    assert not state(coll).review.constraints
    assert {n: _keys(o)[0].tolist() for n, o in _labeled(coll).items()} == \
        {n: k.tolist() for n, k in before_keys.items()}


# --- Fill Preview ---------------------------------------------------------------------------------

def test_fill_preview_lists_the_gaps_another_method_per_gap_and_apply(labeled, capfd, tmp_path):
    from mocap_autolabel.core.fill import spline_fill
    from mocap_autolabel.core.formats.c3d import read_c3d

    bpy, coll = labeled
    name, first = coll.name, int(coll["mocap_first"])
    settings = bpy.context.scene.mocap_autolabel.cleanup
    index_tip = _labeled(coll)["IndexTip"]
    frames, values, _ = _keys(index_tip)
    _select(bpy, index_tip)
    assert bpy.ops.mocap_autolabel.fill_preview() == {"FINISHED"}
    rows = list(settings.preview)
    methods = [r.method for r in rows]
    said = ", ".join(f"{methods.count(m)} {m}" for m in sorted(set(methods)))
    assert f"IndexTip: {len(rows)} gaps, {len(rows)} filled by auto ({said})" in capfd.readouterr().out
    # Every gap of IndexTip, inside its span (the frames it has no key at), with auto's pick.
    span = np.arange(frames[0], frames[-1] + 1)
    missing = span[~np.isin(span, frames)]
    assert sum(r.frame_end - r.frame_start + 1 for r in rows) == len(missing)
    for r in rows:
        assert r.asked == "auto" and r.method in ("pose", "spline") and r.error_mm > 0
        assert "hand: no hand solve" in r.tried and "pose" in r.tried and "spline" in r.tried
        if r.method == "pose":  # read off the other markers
            assert "ThumbTip" in r.donors and "IndexTip" not in r.donors
        else:  # from IndexTip's own samples
            assert r.donors == ""
    # Another method for the first gap the pose fills: the spline.
    row = next(i for i, r in enumerate(rows) if r.method == "pose")
    gap = (rows[row].frame_start, rows[row].frame_end)
    assert bpy.ops.mocap_autolabel.fill_preview_method(method="hand", row=row) == {"FINISHED"}
    assert settings.preview[row].method == "" and "no hand solve" in settings.preview[row].reason
    bpy.ops.ed.undo_push(message="preview")
    assert bpy.ops.mocap_autolabel.fill_preview_method(method="spline", row=row) == {"FINISHED"}
    picked = settings.preview[row]
    assert (picked.asked, picked.method, picked.donors) == ("spline", "spline", "") and picked.error_mm > 0
    expected = [r.method for r in settings.preview]
    bpy.ops.ed.undo_push(message="spline picked")

    assert bpy.ops.mocap_autolabel.fill_preview_apply() == {"FINISHED"}
    assert f"Filled {len(rows)} of {len(rows)} gaps of IndexTip" in capfd.readouterr().out
    bpy.ops.ed.undo_push(message="apply")
    got_frames, got, types = _keys(index_tip)
    np.testing.assert_array_equal(got_frames[types == "GENERATED"], missing)  # every gap filled
    # The gap picked holds the spline through IndexTip's own samples.
    x = np.full((int(span[-1]) + 1 - first, 3), np.nan)
    x[frames - first] = values
    a, b = gap[0] - first, gap[1] + 1 - first
    want = spline_fill(x, np.isfinite(x[:, 0]), a, b)
    np.testing.assert_allclose(got[np.isin(got_frames, np.arange(a, b) + first)], want, atol=1e-5)
    assert [g["method"] for g in json.loads(coll["mocap_fill"])["gaps"]] == expected
    # Export writes them as computed samples.
    out = tmp_path / "labeled.c3d"
    assert bpy.ops.mocap_autolabel.export_labeled(filepath=str(out)) == {"FINISHED"}
    back = read_c3d(out)
    assert int(back.filled[:, back.names.index("IndexTip")].sum()) == len(missing)

    # Undo takes the fills back, then the pick of the method (the list and the preview follow).
    bpy.ops.ed.undo()
    coll = bpy.data.collections[name]
    assert "GENERATED" not in set(_keys(_labeled(coll)["IndexTip"])[2]) and "mocap_fill" not in coll
    assert bpy.context.scene.mocap_autolabel.cleanup.preview[row].asked == "spline"
    bpy.ops.ed.undo()
    coll, settings = bpy.data.collections[name], bpy.context.scene.mocap_autolabel.cleanup
    assert settings.preview[row].asked == "hand"
    assert bpy.ops.mocap_autolabel.fill_preview_apply() == {"FINISHED"}  # the hand leaves that gap open
    assert f"Filled {len(rows) - 1} of {len(rows)} gaps of IndexTip" in capfd.readouterr().out
    got_frames, _, types = _keys(_labeled(coll)["IndexTip"])
    assert not np.isin(got_frames[types == "GENERATED"], np.arange(a, b) + first).any()


def test_fill_preview_refuses_labels_changed_since(labeled):
    bpy, coll = labeled
    objs = _labeled(coll)
    _select(bpy, objs["IndexTip"])
    assert bpy.ops.mocap_autolabel.fill_preview(max_gap=0.3) == {"FINISHED"}
    settings = bpy.context.scene.mocap_autolabel.cleanup
    assert any(r.reason.startswith("longer than max_gap") for r in settings.preview)
    lab = state(coll).labeling
    seg = np.flatnonzero(lab.label == lab.names.index("ThumbTip"))[0]
    bpy.context.scene.frame_set(int(lab.start[seg]) + int(coll["mocap_first"]) + 3)
    _select(bpy, objs["ThumbTip"])
    assert bpy.ops.mocap_autolabel.unlabel() == {"FINISHED"}
    with pytest.raises(RuntimeError, match="changed since the fill preview: Preview Fill again"):
        bpy.ops.mocap_autolabel.fill_preview_apply()


def test_fill_preview_applies_the_picks_after_the_file_is_opened_again(labeled, tmp_path, capfd):
    """The preview's models live in the session; the picks live in the scene: a file saved and opened
    again applies what its list shows."""
    from helpers import save_and_reopen

    bpy, coll = labeled
    _select(bpy, _labeled(coll)["IndexTip"])
    assert bpy.ops.mocap_autolabel.fill_preview() == {"FINISHED"}
    settings = bpy.context.scene.mocap_autolabel.cleanup
    row = next(i for i, r in enumerate(settings.preview) if r.method == "pose")
    assert bpy.ops.mocap_autolabel.fill_preview_method(method="spline", row=row) == {"FINISHED"}
    expected = [r.method for r in settings.preview]
    coll = save_and_reopen(bpy, tmp_path / "previewed.blend")
    assert bpy.ops.mocap_autolabel.fill_preview_apply() == {"FINISHED"}
    assert [g["method"] for g in json.loads(coll["mocap_fill"])["gaps"]] == expected


# --- Quick Label ----------------------------------------------------------------------------------

def test_quick_label_gives_the_next_labels_and_a_resolve_keeps_them(labeled, capfd):
    bpy, coll = labeled
    scene = bpy.context.scene
    first = int(coll["mocap_first"])
    settings = scene.mocap_autolabel.cleanup
    with pytest.raises(RuntimeError, match="no marker selected"):
        _select(bpy)
        bpy.ops.mocap_autolabel.quick_label()
    lab = state(coll).labeling
    ghosts = np.flatnonzero(lab.label == NULL)
    ghosts = ghosts[np.argsort(-lab.length[ghosts])][:2]  # the two longest unlabeled pieces
    nulls = {o["mocap_null"]: o for o in coll["mocap_unlabeled"].objects}
    settings.quick_next = lab.names.index("BackHand2")
    made = []
    for seg in ghosts:
        scene.frame_set(int(lab.start[seg] + lab.stop[seg]) // 2 + first)  # anywhere in the piece
        _select(bpy, nulls[int(lab.slot[seg])])
        assert bpy.ops.mocap_autolabel.quick_label() == {"FINISHED"}
        made.append((int(lab.slot[seg]), int(lab.start[seg]), int(lab.stop[seg])))
    out = capfd.readouterr().out
    assert "labeled BackHand2" in out and "next: BackHand3" in out
    assert "labeled BackHand3" in out and "next: ThumbCMC (the layout's first again)" in out
    assert settings.quick_next == 0
    review = state(coll).review
    assert [(c.slot, c.start, c.stop, c.label) for c in review.constraints] == \
        [(s, a, b, lab.names.index(n)) for (s, a, b), n in zip(made, ("BackHand2", "BackHand3"))]
    assert bpy.ops.mocap_autolabel.resolve() == {"FINISHED"}
    per = state(coll).labeling.per_sample()
    for (s, a, b), n in zip(made, ("BackHand2", "BackHand3")):
        assert (per[a:b, s] == lab.names.index(n)).all()
        frames, _, types = _keys(_labeled(coll)[n])
        assert set(types[np.isin(frames, np.arange(a, b) + first)]) == {"JITTER"}  # locked
    # A label by name, on a labeled marker's trajectory.
    with pytest.raises(RuntimeError, match="there is no label 'Nose'"):
        _select(bpy, _labeled(coll)["ThumbTip"])
        bpy.ops.mocap_autolabel.quick_label(label="Nose")
