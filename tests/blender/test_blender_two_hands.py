"""Two hands in one take in Blender (issue 32, item 6), in the bpy module with the add-on enabled:
Label Markers gives one Labeled collection per hand, the relabel tools work across both hands,
re-solve, save and reopen keep both, Solve Hand adds one rig per hand, Export Labeled C3D writes
both hands by their side names, and the headless review scene (``label --blend``) holds both."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import import_take as _import
from helpers import import_written, save_and_reopen
from helpers import review_state as _state
from helpers import select as _select
from mocap_autolabel.core.formats.c3d import write_c3d
from mocap_autolabel.core.hands import split_hands
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.synth.two_hands import TwoHandConfig, two_hand_take
from mocap_autolabel.core.take import read_take

M = 19  # han19's markers: labels 0..18 are the left hand's, 19..37 the right's


@pytest.fixture(scope="module")
def two_hands(tmp_path_factory):
    """A 400-frame synthetic take of two hands that stay apart, written as a raw C3D, and its truth."""
    folder = tmp_path_factory.mktemp("two_hands")
    synth = two_hand_take(load_layout("han19"), 400, seed=3, config=TwoHandConfig(close_share=0.0))
    path = folder / "two.c3d"
    write_c3d(synth.take, path)
    return path, synth.labels


@pytest.fixture
def labeled(empty_scene, bpy_module, two_hands, tmp_path):
    bpy = bpy_module
    coll = _import(bpy, two_hands[0], tmp_path)
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    return bpy, coll


def _objects(coll) -> dict[int, object]:
    return {int(o["mocap_label"]): o for o in coll["mocap_labeled"].all_objects}


def _frame_with(lab, label: int, at_least: int = 0) -> tuple[int, int]:
    """(sample index, slot) of the first sample at or after ``at_least`` that carries ``label``."""
    per = lab.per_sample()
    f, s = np.nonzero(per[at_least:] == label)
    return int(f[0]) + at_least, int(s[0])


def test_label_gives_one_labeled_collection_per_hand(labeled, two_hands):
    from mocap_autolabel.blender import animio
    from mocap_autolabel.blender.review import (
        FINGER_COLOR_SETS,
        current_take,
        finger_of,
        marker_classes,
        overlay_geometry,
        summary,
        take_collection,
    )

    bpy, coll = labeled
    lab = _state(coll).labeling
    layout = load_layout("han19")
    assert lab.names == [f"L_{n}" for n in layout.names] + [f"R_{n}" for n in layout.names]
    assert lab.info["hands"]["count"] == 2 and lab.info["hands"]["sides"] == ["left", "right"]
    # "Labeled" holds one child collection per hand, each with its hand's 19 empties, side-named.
    labeled_coll = coll["mocap_labeled"]
    assert not labeled_coll.objects
    left, right = coll["mocap_labeled_left"], coll["mocap_labeled_right"]
    assert [c.name for c in labeled_coll.children] == ["Left hand", "Right hand"]
    assert sorted(o.name for o in left.objects) == sorted(lab.names[:M])
    assert sorted(o.name for o in right.objects) == sorted(lab.names[M:])
    assert {int(o["mocap_label"]) for o in right.objects} == set(range(M, 2 * M))
    for obj in right.objects:  # a hand's empty belongs to the take; its channels are coloured by finger
        assert take_collection(obj) == coll
        finger = finger_of(layout, int(obj["mocap_label"]) % M)
        assert animio.find_fcurve(obj, "location", 0).group.color_set == FINGER_COLOR_SETS[finger]
    # Right against the truth (labels 0..18 the left hand's, as the labeling's).
    path, truth = two_hands
    valid = current_take(coll).valid
    assert (lab.per_sample()[valid] == truth[valid]).mean() > 0.99
    # The panel's figures and the uncertain list cover both hands.
    s = summary(lab, bpy.context.scene.mocap_autolabel.sure)
    assert s["labels"] == f"{2 * M} / {2 * M}" and s["hands"].startswith("2 hands: left and right")
    listed = {item.label for item in bpy.context.scene.mocap_autolabel.uncertain}
    assert listed & set(lab.names[:M]) and listed & set(lab.names[M:])
    # Next walks segments of both hands and selects their empties.
    seen = set()
    for _ in range(60):
        if bpy.ops.mocap_autolabel.next_uncertain() != {"FINISHED"}:
            break
        obj = bpy.context.active_object
        if "mocap_label" in obj:
            seen.add(int(obj["mocap_label"]) // M)
    assert seen == {0, 1}
    # The timeline overview marks the worst frames of both hands; Worst Frames goes there.
    assert [m for m in bpy.context.scene.timeline_markers if m.name.startswith(f"?{coll.name}:")]
    assert bpy.ops.mocap_autolabel.jump_to_worst() == {"FINISHED"}
    # The overlay draws both hands: 38 points, sticks along each hand's digits, none across hands.
    index = 200
    bpy.context.scene.frame_set(index + int(coll["mocap_first"]))
    geo = overlay_geometry(coll, layout, marker_classes(lab, 0.95), index)
    objs = _objects(coll)
    shown = [label for label in range(2 * M) if (lab.per_sample()[index] == label).any()]
    assert len(geo["points"]) == len(shown) > M
    hand_of = {tuple(np.round(objs[label].matrix_world.translation, 5)): label // M for label in shown}
    ends = [hand_of[tuple(np.round(p, 5))] for p in geo["lines"]]
    assert len(ends) > 2 * 10 and all(a == b for a, b in zip(ends[::2], ends[1::2], strict=True))
    assert {ends[0], ends[-1]} == {0, 1}


def test_relabel_tools_work_across_both_hands_and_re_solve_keeps_them(labeled, two_hands, capfd):
    from mocap_autolabel.blender.review import prepare_label, sample_index

    bpy, coll = labeled
    scene = bpy.context.scene
    first = int(coll["mocap_first"])
    lab = _state(coll).labeling
    objs = _objects(coll)
    # Move a trajectory from the right hand to the left: give R_IndexTip's trajectory L_IndexTip.
    l_tip, r_tip = lab.names.index("L_IndexTip"), lab.names.index("R_IndexTip")
    index, slot = _frame_with(lab, r_tip, 100)
    scene.frame_set(index + first)
    _select(bpy, objs[r_tip])
    assert bpy.ops.mocap_autolabel.assign_label(label=str(l_tip)) == {"FINISHED"}
    lab = _state(coll).labeling
    assert lab.per_sample()[index, slot] == l_tip
    assert bpy.context.active_object == _objects(coll)[l_tip]  # the selection follows the trajectory
    # Swap between hands: L_ThumbTip and R_ThumbTip trade labels from a frame on.
    l_thumb, r_thumb = lab.names.index("L_ThumbTip"), lab.names.index("R_ThumbTip")
    index2, slot_l = _frame_with(lab, l_thumb, 250)
    slot_r = int(np.flatnonzero(lab.per_sample()[index2] == r_thumb)[0])
    scene.frame_set(index2 + first)
    objs = _objects(coll)
    _select(bpy, objs[l_thumb], objs[r_thumb])
    assert bpy.ops.mocap_autolabel.swap_labels() == {"FINISHED"}
    lab = _state(coll).labeling
    assert lab.per_sample()[index2, slot_l] == r_thumb and lab.per_sample()[index2, slot_r] == l_thumb
    corrections = list(_state(coll).review.constraints)
    texts = [item.text for item in scene.mocap_autolabel.corrections]
    assert any(t.startswith("L_IndexTip on ") for t in texts) and any(t.startswith("R_ThumbTip on ") for t in texts)
    assert {c.label for c in corrections} >= {l_tip, l_thumb, r_thumb}
    # Re-solve: the hands keep their sides (passed back, so no labeling run decides them again) and
    # every correction holds.
    request = prepare_label(coll)
    assert request.hand_options["hand_count"] == 2
    assert request.hand_options["sides"] == lab.info["hands"]["by_hand_order"]
    assert bpy.ops.mocap_autolabel.resolve() == {"FINISHED"}
    state = _state(coll)
    again = state.labeling
    assert state.review.constraints == corrections
    assert again.names == lab.names and again.info["hands"]["sides"] == ["left", "right"]
    assert again.per_sample()[index, slot] == l_tip
    assert again.per_sample()[index2, slot_l] == r_thumb and again.per_sample()[index2, slot_r] == l_thumb
    assert sample_index(coll, scene.frame_current) == index2
    # Labeling again (the Label button) keeps the two hands and the corrections too.
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    assert _state(coll).labeling.per_sample()[index, slot] == l_tip
    assert [c.name for c in coll["mocap_labeled"].children] == ["Left hand", "Right hand"]
    # Hands: One on this take labels one of its two hands (38 points labeled as one hand are no hand:
    # the no-hand rule of the command line and batch), the one found in more frames, and says so.
    capfd.readouterr()
    assert bpy.ops.mocap_autolabel.label(hands="1") == {"FINISHED"}
    out = capfd.readouterr()
    assert "two hands found; Hands: One labels one of them, the left hand here" in out.out + out.err
    one = _state(coll).labeling
    assert one.names == load_layout("han19").names and one.info["hands"]["count"] == 1
    per = one.per_sample()
    truth = two_hands[1]
    assert (truth[per >= 0] // M == 0).mean() > 0.99  # the left hand's markers, labeled alone
    scene.mocap_autolabel.hands = "2"  # the panel's setting
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    assert _state(coll).labeling.names == lab.names and len(_objects(coll)) == 2 * M
    assert [c.name for c in coll["mocap_labeled"].children] == ["Left hand", "Right hand"]


@pytest.mark.slow
def test_save_and_reopen_keep_both_hands_then_solve_and_export(labeled, tmp_path):
    bpy, coll = labeled
    lab = _state(coll).labeling
    index, slot = _frame_with(lab, lab.names.index("R_PinkyTip"), 50)
    bpy.context.scene.frame_set(index + int(coll["mocap_first"]))
    _select(bpy, _objects(coll)[lab.names.index("R_PinkyTip")])
    assert bpy.ops.mocap_autolabel.lock() == {"FINISHED"}
    coll = save_and_reopen(bpy, tmp_path / "review.blend")
    state = _state(coll)
    assert state.labeling.names == lab.names and len(state.review.constraints) == 1
    assert [c.name for c in coll["mocap_labeled"].children] == ["Left hand", "Right hand"]
    assert len(_objects(coll)) == 2 * M
    assert bpy.ops.mocap_autolabel.resolve() == {"FINISHED"}
    assert _state(coll).labeling.info["hands"]["sides"] == ["left", "right"]

    # Solve Hand: one rig per hand, named by side; solving again replaces them.
    _select(bpy, _objects(coll)[0])
    assert bpy.ops.mocap_autolabel.solve_hand(save_calibration=str(tmp_path / "c.json")) == {"FINISHED"}
    arms = sorted(o.name for o in bpy.data.objects if o.type == "ARMATURE")
    assert arms == ["Hand_L", "Hand_R"]
    assert (tmp_path / "c_left.json").exists() and (tmp_path / "c_right.json").exists()
    assert bpy.ops.mocap_autolabel.solve_hand(calibration=str(tmp_path / "c_left.json")) == {"FINISHED"}
    assert sorted(o.name for o in bpy.data.objects if o.type == "ARMATURE") == ["Hand_L", "Hand_R"]

    # Export Labeled C3D: both hands by their side names, read back hand by hand.
    out = tmp_path / "two_labeled.c3d"
    assert bpy.ops.mocap_autolabel.export_labeled(filepath=str(out)) == {"FINISHED"}
    back = read_take(out)
    assert back.names[:2 * M] == lab.names
    hands = split_hands(back, load_layout("han19"))
    assert [side for side, _ in hands] == ["left", "right"]
    per = _state(coll).labeling.per_sample()
    raw = read_take(coll["mocap_source"])
    f, s = np.nonzero(per == M + 3)  # the right hand's fourth marker, where it is labeled
    assert np.allclose(hands[1][1].positions[f, 3], raw.positions[f, s], atol=1e-4)


@pytest.mark.slow
def test_cli_review_scene_holds_both_hands(bpy_module, two_hands, tmp_path, capsys):
    from mocap_autolabel.cli import main

    bpy = bpy_module
    blend = tmp_path / "review.blend"
    assert main(["label", str(two_hands[0]), "--blend", str(blend), "--solve-hand"]) == 0
    printed = capsys.readouterr().out
    assert "solved hands (marker RMS left" in printed
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    coll = next(c for c in bpy.data.collections if "mocap_source" in c)
    assert [c.name for c in coll["mocap_labeled"].children] == ["Left hand", "Right hand"]
    assert _state(coll).labeling.info["hands"]["count"] == 2
    assert sorted(o.name for o in bpy.data.objects if o.type == "ARMATURE") == ["Hand_L", "Hand_R"]


def test_a_held_prop_is_kept_out_of_the_hands_in_blender(empty_scene, bpy_module, tmp_path):
    """Label Markers on a take whose left hand holds a rigid prop that the labeler alone gives hand
    labels: the prop's points stay unlabeled and the Review panel says why."""
    from mocap_autolabel.blender.review import summary

    bpy = bpy_module
    synth = two_hand_take(load_layout("han19"), 1200, seed=1, config=TwoHandConfig(prop_markers=4))
    coll = import_written(bpy, synth.take, tmp_path, "prop")
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    lab = _state(coll).labeling
    assert lab.info["props"]
    per, valid = lab.per_sample(), synth.take.valid
    assert not ((per[:, synth.prop_slots] >= 0) & valid[:, synth.prop_slots]).any()
    line = summary(lab, bpy.context.scene.mocap_autolabel.sure)["props"]
    assert line.startswith("1 rigid prop kept out of the hands")


@pytest.mark.slow
def test_hands_that_traded_places_stay_put_back_through_review(empty_scene, bpy_module, tmp_path):
    """A long take of interacting hands whose tracker swaps them for a stretch: Label Markers puts
    them back and says where, in scene frames; a correction's re-solve, save and reopen keep it."""
    from mocap_autolabel.blender.review import first_frame, summary

    bpy = bpy_module
    scene = bpy.context.scene
    synth = two_hand_take(load_layout("han19"), 3000, seed=1)
    coll = import_written(bpy, synth.take, tmp_path, "trade")
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    lab = _state(coll).labeling
    swaps = lab.info["hands"]["swaps"]
    assert swaps
    first = first_frame(coll)
    (a, b), *_ = swaps
    line = summary(lab, scene.mocap_autolabel.sure, first)["hands_traded"]
    assert f"put back in frames {a + first}-{b - 1 + first}" in line
    per, valid = lab.per_sample(), synth.take.valid
    ok = valid & (synth.labels >= 0) & (per >= 0)
    assert ((synth.labels[ok] < M) == (per[ok] < M)).mean() > 0.99  # every sample on its own hand
    # Lock a marker inside the stretch the hands traded, re-solve, save and reopen, re-solve again.
    l_tip = lab.names.index("L_IndexTip")
    index = a + int(np.argmax((per[a:b] == l_tip).any(axis=1)))
    scene.frame_set(index + first)
    _select(bpy, _objects(coll)[l_tip])
    assert bpy.ops.mocap_autolabel.lock() == {"FINISHED"}
    assert bpy.ops.mocap_autolabel.resolve() == {"FINISHED"}
    assert _state(coll).labeling.info["hands"]["swaps"] == swaps
    assert (_state(coll).labeling.per_sample()[valid] == per[valid]).mean() > 0.99
    coll = save_and_reopen(bpy, tmp_path / "trade.blend")
    assert len(_state(coll).review.constraints) == 1
    assert bpy.ops.mocap_autolabel.resolve() == {"FINISHED"}
    assert _state(coll).labeling.info["hands"]["swaps"] == swaps
