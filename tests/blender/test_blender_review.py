"""Review in Blender (bpy module): label a synthetic take, check the colours, correct, re-solve, save."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import save_and_reopen
from mocap_autolabel.core.formats.c3d import write_c3d
from mocap_autolabel.core.labeling import EMPTY, NULL, Constraint
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.review import (
    KEY_TYPES,
    LOCKED,
    marker_classes,
    review_queue,
    segment_classes,
    uncertain_segments,
)
from mocap_autolabel.core.synth.generate import synthesize

FRAMES = 600


@pytest.fixture(scope="module")
def take_file(tmp_path_factory):
    layout = load_layout("han19")
    take = synthesize(layout, FRAMES, seed=3).take
    path = tmp_path_factory.mktemp("review") / "syn.c3d"
    write_c3d(take, path)
    return path


@pytest.fixture
def labeled(empty_scene, bpy_module, take_file, tmp_path):
    import shutil

    bpy = bpy_module
    path = shutil.copy(take_file, tmp_path / "syn.c3d")  # a test may remove it
    bpy.ops.mocap_autolabel.import_markers(filepath=str(path))
    settings = empty_scene.mocap_autolabel
    settings.layout = "han19"
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    return bpy, settings.take


def state(coll):
    from mocap_autolabel.blender.review import load_state

    return load_state(coll)


def labeled_objects(coll):
    return {int(o["mocap_label"]): o for o in coll["mocap_labeled"].objects}


def key_types(obj) -> tuple[np.ndarray, np.ndarray]:
    from mocap_autolabel.blender import animio

    fc = animio.find_fcurve(obj, "location", 0)
    frames, _ = animio.read_keys(fc)
    return frames, animio.read_key_types(fc)


def assert_scene_shows(coll, labeling):
    """Every labeled empty is keyed exactly where its label has a sample, at that sample's
    position, with the key type of the sample's confidence class; likewise the unlabeled empties."""
    from mocap_autolabel.blender import animio
    from mocap_autolabel.blender.review import current_take, first_frame, key_type_values

    take = current_take(coll)
    first = first_frame(coll)
    per = labeling.per_sample()
    classes = marker_classes(labeling)
    types = key_type_values()
    for label, obj in labeled_objects(coll).items():
        frames, got = key_types(obj)
        idx = np.flatnonzero(per == label) // per.shape[1]
        slots = np.flatnonzero(per == label) % per.shape[1]
        np.testing.assert_array_equal(frames, idx + first, err_msg=labeling.names[label])
        np.testing.assert_array_equal(got, types[classes[idx, label]], err_msg=labeling.names[label])
        _, x = animio.read_keys(animio.find_fcurve(obj, "location", 0))
        np.testing.assert_allclose(x, take.positions[idx, slots, 0], atol=1e-6)
    # Computed here, not by null_classes: an unlabeled piece the review queue leaves out is keyed confident.
    seg_class = segment_classes(labeling)
    queued = np.isin(np.arange(len(labeling)), review_queue(labeling))
    seg_class[(labeling.label < 0) & ~queued & (seg_class != LOCKED)] = KEY_TYPES.index("KEYFRAME")
    seg_class = labeling._paint(seg_class, -1, np.int8)
    for obj in coll["mocap_unlabeled"].objects:
        slot = int(obj["mocap_null"])
        frames, got = key_types(obj)
        idx = np.flatnonzero(per[:, slot] == NULL)
        np.testing.assert_array_equal(frames, idx + first)
        np.testing.assert_array_equal(got, types[seg_class[idx, slot]])


def test_label_writes_collections_key_types_and_list(labeled):
    bpy, coll = labeled
    st = state(coll)
    lab = st.labeling
    assert (st.layout, st.method, st.temporal) == ("han19", "set", "vote")
    assert len(coll["mocap_raw"].objects) == lab.n_points
    assert sorted(labeled_objects(coll)) == sorted(np.unique(lab.label[lab.label >= 0]).tolist())
    assert {o.name for o in coll["mocap_labeled"].objects} <= set(lab.names)
    assert_scene_shows(coll, lab)
    # Finger colours on the channel groups.
    obj = labeled_objects(coll)[lab.names.index("IndexTip")]
    from mocap_autolabel.blender import animio

    assert animio.find_fcurve(obj, "location", 0).group.color_set == "THEME02"
    # The list is the Labeling's review queue, what to look at first on top; unlabeled ones under their
    # *N empty's name, every entry with its raw trajectory's.
    settings = bpy.context.scene.mocap_autolabel
    items = settings.uncertain

    def listed():
        return [(i.slot, i.frame_start - 1, i.label, i.point, i.unlabeled) for i in items]

    def queued(**filters):
        return [(int(lab.slot[s]), int(lab.start[s]), _shown_as(lab, s), f"*{lab.slot[s]}", bool(lab.label[s] < 0))
                for s in review_queue(lab, **filters)]

    assert listed() == queued() and len(items) == settings.uncertain_total > 0
    assert settings.uncertain_hidden == len(uncertain_segments(lab)) - len(items)
    # The filters: every uncertain unlabeled piece from 1 frame on, or labeled segments alone.
    settings.queue_min_frames = 1
    assert listed() == queued(min_frames=1) and (lab.label[review_queue(lab, min_frames=1)] < 0).any()
    assert settings.uncertain_total == len(uncertain_segments(lab)) and settings.uncertain_hidden == 0
    settings.queue_labeled_only = True
    assert listed() == queued(labeled_only=True) and not any(i.unlabeled for i in items)
    settings.queue_labeled_only, settings.queue_min_frames = False, 10
    assert listed() == queued()


def _slot_and_segment(lab, label, frame):
    per = lab.per_sample()
    slot = int(np.flatnonzero(per[frame] == label)[0])
    seg = int(np.flatnonzero((lab.slot == slot) & (lab.start <= frame) & (lab.stop > frame))[0])
    return slot, seg


def _select(bpy, *objs):
    for o in bpy.context.selected_objects:
        o.select_set(False)
    for o in objs:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objs[0]


def _long_segment_frame(lab, label):
    """A frame inside (not at the start of) the longest segment of ``label``."""
    seg = np.flatnonzero(lab.label == label)
    seg = seg[np.argmax(lab.length[seg])]
    return int(lab.start[seg] + lab.length[seg] // 3)


def test_assign_changes_exactly_the_expected_frames(labeled):
    bpy, coll = labeled
    before = state(coll).labeling
    a, b = before.names.index("IndexTip"), before.names.index("MiddleTip")
    frame = _long_segment_frame(before, a)
    slot, seg = _slot_and_segment(before, a, frame)
    stop = int(before.stop[seg])
    _select(bpy, labeled_objects(coll)[a])
    bpy.context.scene.frame_set(frame + 1)
    assert bpy.ops.mocap_autolabel.assign_label(label=str(b)) == {"FINISHED"}
    after = state(coll)
    assert after.review.constraints == [Constraint(slot, frame, stop, b)]
    pb, pa = before.per_sample(), after.labeling.per_sample()
    expected = pb.copy()
    rows = slice(frame, stop)
    took = expected[rows] == b
    took[:, slot] = False
    expected[rows][took] = NULL
    expected[rows, slot] = b
    np.testing.assert_array_equal(pa, expected)
    assert after.labeling.locked[(after.labeling.slot == slot) & (after.labeling.start == frame)].all()
    assert_scene_shows(coll, after.labeling)


def test_swap_unlabel_lock_split(labeled):
    bpy, coll = labeled
    lab = state(coll).labeling
    objs = labeled_objects(coll)
    a, b = lab.names.index("RingTip"), lab.names.index("PinkyTip")
    frame = _long_segment_frame(lab, a)
    slot_a, seg_a = _slot_and_segment(lab, a, frame)
    slot_b, seg_b = _slot_and_segment(lab, b, frame)
    bpy.context.scene.frame_set(frame + 1)
    _select(bpy, objs[a], objs[b])
    assert bpy.ops.mocap_autolabel.swap_labels() == {"FINISHED"}
    st = state(coll)
    assert set(st.review.constraints) == {Constraint(slot_a, frame, int(lab.stop[seg_a]), b),
                                          Constraint(slot_b, frame, int(lab.stop[seg_b]), a)}
    per = st.labeling.per_sample()
    assert per[frame, slot_a] == b and per[frame, slot_b] == a
    assert (per[:frame] == lab.per_sample()[:frame]).all()  # nothing before the frame moved
    assert_scene_shows(coll, st.labeling)

    # Unlabel the (now) b marker: its samples to the end of the segment become ghosts.
    objs = labeled_objects(coll)
    _select(bpy, objs[b])
    assert bpy.ops.mocap_autolabel.unlabel() == {"FINISHED"}
    st = state(coll)
    assert st.review.constraints[-1] == Constraint(slot_a, frame, int(lab.stop[seg_a]), NULL)
    per = st.labeling.per_sample()
    live = per[frame:int(lab.stop[seg_a]), slot_a]
    assert (live[live != EMPTY] == NULL).all()
    assert any(int(o["mocap_null"]) == slot_a for o in coll["mocap_unlabeled"].objects)
    assert_scene_shows(coll, st.labeling)

    # Lock a whole segment: its class becomes LOCKED (JITTER keys), labels unchanged.
    c = lab.names.index("ThumbTip")
    f2 = _long_segment_frame(st.labeling, c)
    lab_c = st.labeling
    slot_c, seg_c = _slot_and_segment(lab_c, c, f2)
    bpy.context.scene.frame_set(f2 + 1)
    _select(bpy, labeled_objects(coll)[c])
    labels_before = st.labeling.per_sample()
    assert bpy.ops.mocap_autolabel.lock() == {"FINISHED"}
    st = state(coll)
    seg_start, seg_stop = int(lab_c.start[seg_c]), int(lab_c.stop[seg_c])
    assert st.review.constraints[-1] == Constraint(slot_c, seg_start, seg_stop, c)
    np.testing.assert_array_equal(st.labeling.per_sample(), labels_before)
    frames, types = key_types(labeled_objects(coll)[c])
    from mocap_autolabel.blender import animio

    inside = (frames >= seg_start + 1) & (frames < seg_stop + 1)
    assert inside.any() and (types[inside] == animio.key_type_value(KEY_TYPES[LOCKED])).all()

    # Split: one more segment, same labels, recorded on the review.
    n = len(st.labeling)
    assert bpy.ops.mocap_autolabel.split() == {"FINISHED"}
    st2 = state(coll)
    assert st2.review.splits == [(slot_c, f2)] and len(st2.labeling) == n + 1
    np.testing.assert_array_equal(st2.labeling.per_sample(), labels_before)


def test_resolve_keeps_every_constraint_and_rewrites_only_changes(labeled):
    bpy, coll = labeled
    lab = state(coll).labeling
    a, b = lab.names.index("IndexTip"), lab.names.index("IndexPIP")
    frame = _long_segment_frame(lab, a)
    bpy.context.scene.frame_set(frame + 1)
    objs = labeled_objects(coll)
    _select(bpy, objs[a], objs[b])
    bpy.ops.mocap_autolabel.swap_labels()
    _select(bpy, labeled_objects(coll)[lab.names.index("ThumbTip")])
    bpy.ops.mocap_autolabel.unlabel()
    constraints = state(coll).review.constraints
    assert bpy.ops.mocap_autolabel.resolve() == {"FINISHED"}
    st = state(coll)
    assert st.review.constraints == constraints
    per = st.labeling.per_sample()
    for c in constraints:
        got = per[c.start:c.stop, c.slot]
        assert (got[got != EMPTY] == c.label).all(), c
    assert_scene_shows(coll, st.labeling)
    # A second re-solve changes nothing, so it rewrites nothing.
    from mocap_autolabel.blender.review import finish_label, prepare_label

    request = prepare_label(coll)
    counts = finish_label(bpy.context.scene, coll, request, request.run())
    assert counts == {"labeled": 0, "unlabeled": 0}


def test_save_reopen_keeps_the_review(labeled, tmp_path):
    bpy, coll = labeled
    lab = state(coll).labeling
    a = lab.names.index("MiddleTip")
    bpy.context.scene.frame_set(_long_segment_frame(lab, a) + 1)
    _select(bpy, labeled_objects(coll)[a])
    bpy.ops.mocap_autolabel.unlabel()
    before = state(coll)
    coll = save_and_reopen(bpy, tmp_path / "review.blend")
    after = state(coll)
    assert after.review.constraints == before.review.constraints
    for key in ("slot", "start", "stop", "label", "locked"):
        np.testing.assert_array_equal(getattr(after.labeling, key), getattr(before.labeling, key))
    np.testing.assert_allclose(after.labeling.confidence, before.labeling.confidence, atol=1e-6)
    assert len(bpy.context.scene.mocap_autolabel.uncertain) == len(review_queue(after.labeling))
    # The review goes on without the source file: the take is read back from the scene.
    import os

    os.remove(coll["mocap_source"])
    assert bpy.ops.mocap_autolabel.resolve() == {"FINISHED"}
    per = state(coll).labeling.per_sample()
    c = before.review.constraints[0]
    got = per[c.start:c.stop, c.slot]
    assert (got[got != EMPTY] == NULL).all()


def test_next_previous_and_jump(labeled):
    bpy, coll = labeled
    lab = state(coll).labeling
    scene = bpy.context.scene
    unsure = review_queue(lab)
    starts = np.sort(lab.start[unsure])
    scene.frame_set(1)
    assert bpy.ops.mocap_autolabel.next_uncertain() == {"FINISHED"}
    first = starts[0]  # a segment that starts on the current frame is the next one
    assert scene.frame_current == first + 1
    seg = unsure[lab.start[unsure] == first]
    assert bpy.context.active_object.name in {_shown_as(lab, s) for s in seg}
    scene.frame_set(int(starts[-1]) + 5)
    assert bpy.ops.mocap_autolabel.next_uncertain(previous=True) == {"FINISHED"}
    assert scene.frame_current == starts[-1] + 1
    settings = scene.mocap_autolabel
    settings.uncertain_index = 0  # a click in the list jumps
    item = settings.uncertain[0]
    assert scene.frame_current == item.frame_start
    assert bpy.context.active_object.name == item.label


def _shown_as(lab, seg) -> str:
    """The empty that shows a segment: its label's, or the slot's unlabeled *N."""
    return lab.names[lab.label[seg]] if lab.label[seg] >= 0 else f"*{lab.slot[seg]}"


def test_errors_are_clear(labeled):
    bpy, coll = labeled
    lab = state(coll).labeling
    a = lab.names.index("IndexTip")
    missing = np.flatnonzero((lab.per_sample() == a).sum(axis=1) == 0)
    if not len(missing):
        pytest.skip("the label never goes missing in this take")
    _select(bpy, labeled_objects(coll)[a])
    bpy.context.scene.frame_set(int(missing[0]) + 1)
    with pytest.raises(RuntimeError, match="no sample at frame"):
        bpy.ops.mocap_autolabel.unlabel()
    _select(bpy, labeled_objects(coll)[a])
    with pytest.raises(RuntimeError, match="exactly two"):
        bpy.ops.mocap_autolabel.swap_labels()


def test_a_file_that_names_its_points_gives_labeled_empties_the_plain_names(empty_scene, bpy_module, tmp_path):
    """A labeled file's points import under the label names; labeling moves them into Raw as
    "<name> (raw)", so the labeled empties are "BackHand1", not "BackHand1.001", and the
    unlabeled ones "*20", not "*20.001"."""
    import dataclasses

    from mocap_autolabel.blender.review import RAW_SUFFIX

    bpy = bpy_module
    layout = load_layout("han19")
    take = synthesize(layout, 200, seed=5).take
    names = [layout.names[i] if i < len(layout) else n for i, n in enumerate(take.names)]
    path = tmp_path / "named.c3d"
    write_c3d(dataclasses.replace(take, names=names), path)
    bpy.ops.mocap_autolabel.import_markers(filepath=str(path))
    settings = empty_scene.mocap_autolabel
    settings.layout = "han19"
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    coll = settings.take
    objs = labeled_objects(coll)
    assert len(objs) == len(layout)
    assert all(obj.name == layout.names[label] for label, obj in objs.items())
    raw = {o["mocap_point"]: o.name for o in coll["mocap_raw"].objects}
    assert all(raw[n] == n + RAW_SUFFIX for n in layout.names if n in raw)
    assert sum(n in raw for n in layout.names) == min(len(layout), len(take.names))
    # The unlabeled empties keep their slots' plain names too ("*20", not "*20.001").
    unlabeled = [(o.name, f"*{o['mocap_null']}") for o in coll["mocap_unlabeled"].objects]
    assert unlabeled and all(name == point for name, point in unlabeled)


def test_the_panel_labels_with_the_command_lines_default_layout(empty_scene):
    """A user who imports a take and presses Label gets the layout the CLI and batch use by default
    (han19), not the first layout by name. (cli.py and batch.py import only the standard library
    at module level, so they spell the name out; this keeps the three in step.) Batch picks each
    take's layout from its points' names, as Blender's import does, and han19 for unnamed points."""
    import numpy as np
    from mocap_autolabel.batch import BatchSettings
    from mocap_autolabel.cli import build_parser
    from mocap_autolabel.core.layout import DEFAULT_LAYOUT, load_layout
    from mocap_autolabel.core.process import choose_layout
    from mocap_autolabel.core.take import Take

    assert build_parser().parse_args(["label", "take.c3d"]).layout == DEFAULT_LAYOUT
    assert BatchSettings().layout is None
    unnamed = Take(positions=np.zeros((2, 3, 3), np.float32), names=["*0", "*1", "*2"], rate=120.0)
    assert choose_layout(unnamed, BatchSettings().layout) == DEFAULT_LAYOUT
    glove = Take(positions=np.zeros((2, 13, 3), np.float32), names=list(load_layout("glove13").names), rate=120.0)
    assert choose_layout(glove, None) == "glove13"
    assert choose_layout(glove, "han19") == "han19"  # the user's choice wins
    assert empty_scene.mocap_autolabel.layout == DEFAULT_LAYOUT


def test_labeling_with_the_wrong_layout_says_which_fits(labeled, tmp_path):
    """A glove13 take labeled with han19: the panel's summary names glove13, a re-solve keeps the
    warning, and labeling with glove13 clears it. The han19 take labeled with glove13 finds no hand:
    refused, naming han19 (batch's and the CLI's rule)."""
    from mocap_autolabel.blender.review import summary

    bpy, coll = labeled
    settings = bpy.context.scene.mocap_autolabel
    assert summary(state(coll).labeling, settings.sure)["layout_doubt"] is None
    settings.layout = "glove13"
    with pytest.raises(RuntimeError, match="no hand found.*'han19' fits better: use Layout han19 in the Mocap tab"):
        bpy.ops.mocap_autolabel.label()
    glove = tmp_path / "glove.c3d"
    write_c3d(synthesize(load_layout("glove13"), 300, seed=4).take, glove)
    bpy.ops.mocap_autolabel.import_markers(filepath=str(glove))
    coll = settings.take
    settings.layout = "han19"
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    doubt = summary(state(coll).labeling, settings.sure)["layout_doubt"]
    assert (doubt.layout, doubt.better) == ("han19", "glove13") and doubt.share < doubt.better_share
    assert bpy.ops.mocap_autolabel.resolve() == {"FINISHED"}
    assert summary(state(coll).labeling, settings.sure)["layout_doubt"] == doubt
    settings.layout = "glove13"
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    assert summary(state(coll).labeling, settings.sure)["layout_doubt"] is None


@pytest.mark.slow
def test_solve_hand_fits_the_reviewed_labels(labeled, tmp_path):
    """Solve Hand after Label (step 9 of the README) solves the labels in the scene, with the layout
    they were made with: the raw file on disk (unlabeled) is neither needed nor read."""
    from mocap_autolabel.blender import animio

    bpy, coll = labeled
    (tmp_path / "syn.c3d").unlink()
    _select(bpy, next(iter(labeled_objects(coll).values())))
    before = set(bpy.data.objects)
    assert bpy.ops.mocap_autolabel.solve_hand(layout="glove13") == {"FINISHED"}  # the take's own layout wins
    added = set(bpy.data.objects) - before
    arm = next(o for o in added if o.type == "ARMATURE")
    assert {len(fc.keyframe_points) for fc in animio.fcurves_of(arm)} == {FRAMES}
    markers = next(o for o in added if "marker_names" in o)
    assert list(markers["marker_names"]) == load_layout("han19").names
    assert arm["mocap_marker_rms_mm"] < 8.0


def test_label_needs_a_take(empty_scene, bpy_module):
    with pytest.raises(RuntimeError, match="Import a take first"):
        bpy_module.ops.mocap_autolabel.label()
    with pytest.raises(RuntimeError, match="Label a take first"):
        bpy_module.ops.mocap_autolabel.resolve()
    # Each operator on a labeled take says why it cannot run, not only that it cannot.
    for op in (bpy_module.ops.mocap_autolabel.export_labeled, bpy_module.ops.mocap_autolabel.jump_to_segment,
               bpy_module.ops.mocap_autolabel.jump_to_worst, bpy_module.ops.mocap_autolabel.next_uncertain):
        with pytest.raises(RuntimeError, match="Label a take first"):
            op()


def test_export_labeled_c3d_and_overlay(labeled, tmp_path):
    bpy, coll = labeled
    from mocap_autolabel.blender.review import current_take, overlay_geometry
    from mocap_autolabel.core.take import read_take

    lab = state(coll).labeling
    out = tmp_path / "labeled.c3d"
    assert bpy.ops.mocap_autolabel.export_labeled(filepath=str(out)) == {"FINISHED"}
    back = read_take(out)
    assert back.names[:19] == lab.names and back.n_frames == lab.n_frames
    assert back.valid.sum() == current_take(coll).valid.sum()  # every sample once
    per = lab.per_sample()
    np.testing.assert_array_equal(back.valid[:, :19].sum(axis=0),
                                  [(per == m).sum() for m in range(19)])
    # The overlay shows each present label once, in its finger's colour, and rings the uncertain ones.
    frame = 300
    bpy.context.scene.frame_set(frame + 1)
    classes = marker_classes(lab)
    geo = overlay_geometry(coll, load_layout("han19"), classes, frame)
    assert len(geo["points"]) == (classes[frame] >= 0).sum()
    assert len(geo["uncertain"]) == np.isin(classes[frame], (1, 2)).sum()
    assert geo["colors"].shape == (len(geo["points"]), 4) and len(geo["lines"]) % 2 == 0


def test_export_labeled_c3d_to_any_path_and_not_to_a_folder(labeled, tmp_path):
    """An upper-case .C3D failed ("No such file or directory: .x....partial.C3D") and left a .partial.C3D.c3d
    behind; a folder was reported by its hidden temporary name."""
    bpy, coll = labeled
    from mocap_autolabel.core.take import read_take

    out = tmp_path / "export" / "Überprüft take.C3D"
    assert bpy.ops.mocap_autolabel.export_labeled(filepath=str(out)) == {"FINISHED"}
    assert read_take(out).names[:19] == state(coll).labeling.names
    folder = tmp_path / "export" / "folder.c3d"
    folder.mkdir()
    with pytest.raises(RuntimeError) as info:
        bpy.ops.mocap_autolabel.export_labeled(filepath=str(folder))
    assert str(info.value).strip().splitlines()[-1] == f"Error: {folder}: is a folder; give a file name"
    assert sorted(p.name for p in out.parent.iterdir()) == ["folder.c3d", out.name]  # no partial file


@pytest.mark.slow
def test_cli_label_writes_a_review_scene_the_panel_adopts(empty_scene, bpy_module, take_file, tmp_path):
    from mocap_autolabel.cli import main

    bpy = bpy_module
    out = tmp_path / "review.blend"
    assert main(["label", str(take_file), "--layout", "han19", "--blend", str(out), "--solve-hand"]) == 0
    import addon_utils

    addon_utils.enable("mocap_autolabel", default_set=True)  # the CLI's factory reset disabled it
    bpy.ops.wm.open_mainfile(filepath=str(out))
    settings = bpy.context.scene.mocap_autolabel
    coll = settings.take
    assert coll is not None and coll["mocap_source"] == str(take_file)
    lab = state(coll).labeling
    assert len(settings.uncertain) == len(review_queue(lab))
    assert_scene_shows(coll, lab)
    assert any(o.type == "ARMATURE" for o in bpy.data.collections["Hand"].all_objects)
    assert bpy.ops.mocap_autolabel.resolve() == {"FINISHED"}
    # Solving again replaces the CLI's hand, objects, data and actions, instead of adding one.
    _select(bpy, next(iter(labeled_objects(coll).values())))
    counts = []
    for _ in range(2):
        assert bpy.ops.mocap_autolabel.solve_hand() == {"FINISHED"}
        arms = [o for o in bpy.data.objects if o.type == "ARMATURE"]
        assert len(arms) == 1 and len(bpy.data.armatures) == 1 and arms[0].name == "Hand"
        assert [c.name for c in arms[0].users_collection] == [f"{coll.name} hand"]
        counts.append((len(bpy.data.objects), len(bpy.data.meshes), len(bpy.data.actions)))
    assert "Hand" not in bpy.data.collections and counts[0] == counts[1]


def test_cli_label_blend_needs_a_blend_path(tmp_path, take_file):
    from mocap_autolabel.cli import main

    assert main(["label", str(take_file), "--blend", str(tmp_path / "x.c3d")]) == 2
    assert main(["label", str(take_file), "--solve-hand"]) == 2
    assert not list(tmp_path.iterdir())


def test_review_ui_registers_and_unregisters_cleanly(bpy_module):
    import addon_utils

    bpy = bpy_module
    names = ("MOCAPAL_PT_review", "MOCAPAL_PT_relabel", "MOCAPAL_PT_legend", "MOCAPAL_UL_uncertain",
             "MOCAPAL_MT_mocap")
    assert all(hasattr(bpy.types, n) for n in names)
    assert hasattr(bpy.types.Scene, "mocap_autolabel")
    draw_funcs = [f.__name__ for f in bpy.types.VIEW3D_MT_object._dyn_ui_initialize()]
    assert "menu_mocap" in draw_funcs
    addon_utils.disable("mocap_autolabel", default_set=True)
    try:
        assert not any(hasattr(bpy.types, n) for n in names)
        assert not hasattr(bpy.types.Scene, "mocap_autolabel")
        assert not any(getattr(h, "__name__", "") == "on_load" for h in bpy.app.handlers.load_post)
    finally:
        addon_utils.enable("mocap_autolabel", default_set=True)
    assert all(hasattr(bpy.types, n) for n in names)


def test_a_labeling_that_finishes_after_an_edit_is_refused(labeled):
    from mocap_autolabel.blender.review import finish_label, prepare_label

    bpy, coll = labeled
    request = prepare_label(coll)  # what the modal Label operator hands its worker thread
    result = request.run()
    lab = state(coll).labeling
    a = lab.names.index("IndexTip")
    bpy.context.scene.frame_set(_long_segment_frame(lab, a) + 1)
    _select(bpy, labeled_objects(coll)[a])
    bpy.ops.mocap_autolabel.unlabel()  # the reviewer edits while the job runs
    edited = state(coll)
    with pytest.raises(ValueError, match="changed while the labeling ran"):
        finish_label(bpy.context.scene, coll, request, result)
    assert state(coll).review.constraints == edited.review.constraints


def test_label_a_body_take_is_an_error_and_builds_nothing(empty_scene, bpy_module):
    """The CLI's and batch's no-hand rule: a body capture used to be labeled with 'finger' names and
    FINISHED ('5 / 19 labels, 0.0 % confident'); now one ERROR line and no labeled collection."""
    from conftest import data_path

    bpy = bpy_module
    bpy.ops.mocap_autolabel.import_markers(filepath=str(data_path("c3d", "ezc3d-testFiles", "Vicon.c3d")))
    coll = empty_scene.mocap_autolabel.take
    before = set(bpy.data.collections.keys())
    with pytest.raises(RuntimeError, match=r"Vicon: no hand found: only 0 % of frames have half of the han19"):
        bpy.ops.mocap_autolabel.label()
    assert set(bpy.data.collections.keys()) == before and "mocap_labeled" not in coll.keys()


def test_label_warns_when_the_vote_hit_its_work_bound(empty_scene, bpy_module, take_file, monkeypatch, capfd):
    """As the CLI and batch do ('the vote's exclusive assignment reached its work bound ...')."""
    from mocap_autolabel.core import pipeline, process

    real = pipeline.label_take

    def hurried(*args, **kwargs):  # a hand take never reaches the bound: say it did
        labeling = real(*args, **kwargs)
        labeling.info["work_limited"] = 2
        return labeling

    monkeypatch.setattr(pipeline, "label_take", hurried)
    monkeypatch.setattr(process, "label_take", hurried)  # the front ends' entry (process_take) calls it there
    bpy_module.ops.mocap_autolabel.import_markers(filepath=str(take_file))
    assert bpy_module.ops.mocap_autolabel.label() == {"FINISHED"}
    out = capfd.readouterr()
    assert "reached its work bound 2 time(s) (1000 search nodes" in out.out + out.err


def test_gmm_labels_in_blender_without_a_fit_take(empty_scene, bpy_module, take_file):
    """gmm always failed in the panel (it had no field for the labeled take it fits on); it now fits
    on the layout's synthetic range of motion."""
    bpy_module.ops.mocap_autolabel.import_markers(filepath=str(take_file))
    settings = empty_scene.mocap_autolabel
    settings.method = "gmm"
    assert bpy_module.ops.mocap_autolabel.label() == {"FINISHED"}
    assert state(settings.take).labeling.info["method"] == "gmm"


def test_the_panel_says_why_perm_leaves_every_segment_for_review(empty_scene, bpy_module):
    from conftest import ROOT
    from mocap_autolabel.blender.review import load_state, summary

    bpy = bpy_module
    assert bpy.ops.mocap_autolabel.import_markers(filepath=str(ROOT / "samples" / "demo_take.c3d")) == {"FINISHED"}
    coll = empty_scene.mocap_autolabel.take
    sure = empty_scene.mocap_autolabel.sure
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    assert not summary(load_state(coll).labeling, sure)["never_confident"]  # set is trusted
    assert bpy.ops.mocap_autolabel.label(method="perm") == {"FINISHED"}
    s = summary(load_state(coll).labeling, sure)
    assert s["never_confident"] and s["confident"] == 0.0


def test_the_panel_says_gmm_has_no_calibration_for_a_sparse_layout(empty_scene, bpy_module, tmp_path):
    from mocap_autolabel.blender.review import load_state, summary
    from mocap_autolabel.core.layout import load_layout
    from mocap_autolabel.core.synth.generate import save_synth, synthesize

    bpy = bpy_module
    path = tmp_path / "sparse.c3d"
    save_synth(synthesize(load_layout("tips5_hand3"), 240, seed=2), str(path))
    assert bpy.ops.mocap_autolabel.import_markers(filepath=str(path)) == {"FINISHED"}
    settings = empty_scene.mocap_autolabel
    settings.layout = "tips5_hand3"
    assert bpy.ops.mocap_autolabel.label(method="gmm") == {"FINISHED"}
    s = summary(load_state(settings.take).labeling, settings.sure)
    assert s["never_confident"] == "uncalibrated" and s["confident"] == 0.0


def test_label_puts_back_a_sparse_takes_finger_order(empty_scene, bpy_module, tmp_path):
    # Blender labels through a remembering labeler: the finger-order check must see the model behind it.
    from mocap_autolabel.blender.review import load_state
    from mocap_autolabel.core.layout import load_layout
    from mocap_autolabel.core.synth.generate import save_synth, synthesize

    bpy = bpy_module
    layout = load_layout("tips5_hand3")
    synth = synthesize(layout, 300, seed=4)  # set + vote swap the middle and ring tips for the whole take
    path = tmp_path / "sparse.c3d"
    save_synth(synth, str(path))
    assert bpy.ops.mocap_autolabel.import_markers(filepath=str(path)) == {"FINISHED"}
    settings = empty_scene.mocap_autolabel
    settings.layout = "tips5_hand3"
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    labeling = load_state(settings.take).labeling
    assert labeling.info["finger_order"][0]["moved"] == {"middle": "ring", "ring": "middle"}
    ok = synth.take.valid & (synth.labels >= 0)
    assert (labeling.per_sample()[ok] == synth.labels[ok]).mean() > 0.95
