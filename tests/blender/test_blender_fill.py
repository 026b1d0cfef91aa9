"""Fill Gaps and Clear Fill in the bpy module: keys of their own type, selection, undo, a relabel,
a saved file and the exported C3D."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import import_take as _import
from helpers import review_state as state
from helpers import select as _select
from mocap_autolabel.core.formats.c3d import read_c3d, write_c3d
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.review import KEY_TYPES
from mocap_autolabel.core.synth.generate import synthesize


@pytest.fixture(scope="module")
def take_file(tmp_path_factory):
    """A synthetic han19 take whose labels have gaps inside it (600 frames)."""
    path = tmp_path_factory.mktemp("fill") / "syn.c3d"
    write_c3d(synthesize(load_layout("han19"), 600, seed=1).take, path)
    return path


@pytest.fixture
def labeled(empty_scene, bpy_module, take_file, tmp_path):
    bpy = bpy_module
    coll = _import(bpy, take_file, tmp_path)
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    return bpy, coll


def _objects(coll):
    return {int(o["mocap_label"]): o for o in coll["mocap_labeled"].all_objects}


def _keys(obj):
    """(frames, key type names) of an empty's location keys."""
    from mocap_autolabel.blender import animio

    fc = animio.find_fcurve(obj, "location", 0)
    names = {animio.key_type_value(t): t for t in (*KEY_TYPES, "GENERATED", "MOVING_HOLD")}
    return animio.read_keys(fc)[0], [names[v] for v in animio.read_key_types(fc)]


def _gap_labels(coll) -> list[int]:
    """Labels with a gap inside the take (samples before and after it)."""
    per = state(coll).labeling.per_sample()
    out = []
    for label in range(len(state(coll).labeling.names)):
        seen = np.flatnonzero((per == label).any(axis=1))
        if len(seen) and len(seen) < seen[-1] - seen[0] + 1:
            out.append(label)
    return out


def test_fill_gaps_keys_fills_as_generated_and_clear_fill_removes_them(labeled):
    bpy, coll = labeled
    gappy = _gap_labels(coll)
    assert gappy, "the take must have a gap to fill"
    objs = _objects(coll)
    before = {label: _keys(objs[label]) for label in gappy}
    _select(bpy)  # nothing selected: every labeled marker
    assert bpy.ops.mocap_autolabel.fill_gaps(method="spline") == {"FINISHED"}
    record = coll["mocap_fill"]
    assert '"method": "spline"' in record
    for label in gappy:
        frames, kinds = _keys(objs[label])
        old_frames, old_kinds = before[label]
        assert kinds.count("GENERATED") > 0 and "GENERATED" not in old_kinds
        measured = [f for f, k in zip(frames, kinds) if k != "GENERATED"]
        np.testing.assert_array_equal(measured, old_frames)  # the measured keys stay as they were
        assert [k for k in kinds if k != "GENERATED"] == old_kinds
    assert bpy.ops.mocap_autolabel.clear_fill() == {"FINISHED"}
    objs = _objects(coll)
    for label in gappy:
        assert _keys(objs[label])[1] == before[label][1]
    assert "mocap_fill" not in coll


def test_fill_acts_on_the_selected_markers_and_a_relabel_clears_their_fills(labeled):
    bpy, coll = labeled
    gappy = _gap_labels(coll)
    objs = _objects(coll)
    one = objs[gappy[0]]
    _select(bpy, one)
    assert bpy.ops.mocap_autolabel.fill_gaps(method="spline") == {"FINISHED"}
    assert "GENERATED" in _keys(one)[1]
    others = [label for label in gappy[1:]]
    assert all("GENERATED" not in _keys(objs[label])[1] for label in others)
    _select(bpy)
    assert bpy.ops.mocap_autolabel.fill_gaps(method="auto") == {"FINISHED"}  # no solved hand: pose, spline
    assert all("GENERATED" in _keys(objs[label])[1] for label in gappy)
    # Another Confident at recolours markers: their fills stay.
    counts = {label: _keys(objs[label])[1].count("GENERATED") for label in gappy}
    bpy.context.scene.mocap_autolabel.sure = 0.6
    assert {label: _keys(objs[label])[1].count("GENERATED") for label in gappy} == counts
    # Unlabel a segment of the first marker: its keys are rewritten and its fills go (stated).
    lab = state(coll).labeling
    seg = np.flatnonzero(lab.label == gappy[0])[0]
    bpy.context.scene.frame_set(int(lab.start[seg]) + 1)
    _select(bpy, one)
    assert bpy.ops.mocap_autolabel.unlabel() == {"FINISHED"}
    assert "GENERATED" not in _keys(_objects(coll)[gappy[0]])[1]
    assert f'"label": {gappy[0]},' not in coll.get("mocap_fill", "")
    if len(gappy) > 1:
        assert "GENERATED" in _keys(_objects(coll)[gappy[1]])[1]


def test_fills_are_saved_and_exported_as_computed(labeled, tmp_path):
    bpy, coll = labeled
    _select(bpy)
    assert bpy.ops.mocap_autolabel.fill_gaps(method="spline", max_gap=2.0) == {"FINISHED"}
    counts = {label: _keys(obj)[1].count("GENERATED") for label, obj in _objects(coll).items()}
    blend, name = tmp_path / "filled.blend", coll.name
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    coll = bpy.data.collections[name]
    assert {label: _keys(obj)[1].count("GENERATED") for label, obj in _objects(coll).items()} == counts
    out = tmp_path / "labeled.c3d"
    assert bpy.ops.mocap_autolabel.export_labeled(filepath=str(out)) == {"FINISHED"}
    back = read_c3d(out)
    names = state(coll).labeling.names
    assert back.names[:len(names)] == names
    for label, n in counts.items():
        assert int(back.filled[:, label].sum()) == n
    assert sum(counts.values()) > 0 and back.filled[:, len(names):].sum() == 0


def test_hand_fill_without_a_solve_says_so(labeled):
    bpy, coll = labeled
    _select(bpy)
    with pytest.raises(RuntimeError, match="Solve Hand first"):
        bpy.ops.mocap_autolabel.fill_gaps(method="hand")


def test_a_new_solve_refills_the_gaps_filled_from_the_hand(labeled):
    """The solve is one of an uncalibrated hand, of two sizes (a calibration takes seconds and is
    tested in test_fill); what is checked is that the hand's fills follow a new solve."""
    from mocap_autolabel.blender.fill import fill_scene, filled_keys, refill
    from mocap_autolabel.blender.review import current_take
    from mocap_autolabel.core.hand import HandModel
    from mocap_autolabel.core.hand.calibrate import detect_side
    from mocap_autolabel.core.hand.ik import HandSolver
    from mocap_autolabel.core.labeling import labeled_take, layout_markers
    from mocap_autolabel.core.solve import HandSolve

    bpy, coll = labeled
    layout = load_layout("han19")
    observed = layout_markers(labeled_take(current_take(coll), state(coll).labeling), layout)

    def solve(scale: float) -> list:
        hand = HandModel(side=detect_side(observed, layout), length=0.19 * scale, breadth=0.085 * scale)
        solver = HandSolver(hand, layout.place(hand)[0])
        return [("", HandSolve(None, solver.solve(observed, rate=120.0), layout, 120.0, 1, {}, solver))]

    report = fill_scene(coll, "hand", 1.0, solves=solve(1.0))
    assert report["filled"] > 0 and set(report["methods"]) == {"hand"}
    _, _, before = filled_keys(coll, len(layout))
    again = refill(coll, solve(1.1))  # another solve: other fills of the same gaps
    _, _, after = filled_keys(coll, len(layout))
    assert again["filled"] == report["filled"] and before.shape == after.shape
    assert np.abs(after - before).max() > 1e-4


@pytest.mark.slow
def test_hand_fill_after_solve_hand_fills_from_the_solved_rig(labeled, capfd):
    """The whole path: Solve Hand (a real calibration and solve), then Fill Gaps with the hand: the
    solve the rig keeps is used as it is (the labels did not change) and every gap inside a label's
    span is filled from it, near the take's true markers."""
    from mocap_autolabel.blender.fill import fill_record, filled_keys

    bpy, coll = labeled
    assert bpy.ops.mocap_autolabel.solve_hand() == {"FINISHED"}
    _select(bpy)
    assert bpy.ops.mocap_autolabel.fill_gaps(method="hand", max_gap=1.0) == {"FINISHED"}
    said = capfd.readouterr().out  # the operator's message says when it solves the hand again
    assert "Filled" in said and "solved again" not in said
    record = fill_record(coll)
    assert record["gaps"] and {g["method"] for g in record["gaps"]} == {"hand"}
    idx, labels, at = filled_keys(coll, len(state(coll).labeling.names))
    truth = synthesize(load_layout("han19"), 600, seed=1).markers  # the labels are the layout's, in order
    err = np.linalg.norm(at - truth[idx, labels], axis=1)
    assert bpy.ops.mocap_autolabel.fill_gaps(method="spline", max_gap=1.0) == {"FINISHED"}
    again, _, spline = filled_keys(coll, len(state(coll).labeling.names))
    assert np.array_equal(again, idx)  # the same gaps
    # (the take's samples are noisy and slip on the skin: 3.4 mm median against 18 mm for the spline)
    assert np.median(err) < np.median(np.linalg.norm(spline - truth[idx, labels], axis=1)) / 3
