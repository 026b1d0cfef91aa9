"""README, "Reviewing labels in Blender: a walkthrough", steps 1 to 9 in order on the bundled demo take,
in the bpy module, as an animator would follow them: each step's operator, and what the README says
it leaves in the scene (issue 33, "Measured").

Steps 1 to 8 take about a second and run in every test run; step 9 (Solve Hand, a calibration and
two solves of the 1,200 frames) takes most of the walkthrough's time, so the whole walk, steps 1 to 9,
is a second test marked slow."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from helpers import review_state as _state
from helpers import select as _select
from mocap_autolabel.core.labeling import EMPTY, NULL, unlabeled_point_names
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.review import KEY_TYPES, marker_classes, null_classes, review_queue, uncertain_segments

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "samples" / "demo_take.c3d"
FIX_OPERATORS = ("assign_label", "swap_labels", "unlabel", "split", "lock", "unlock", "delete_correction")


def _keys(obj):
    from mocap_autolabel.blender import animio

    fc = animio.find_fcurve(obj, "location", 0)
    return animio.read_keys(fc)[0].astype(int), animio.read_key_types(fc), fc


def _assert_keys_show(coll, lab, sure):
    """Every labeled empty keyed exactly where its label has a sample, each key's type its confidence
    class at ``sure``; every unlabeled empty likewise for its slot's unassigned samples."""
    from mocap_autolabel.blender.review import first_frame, key_type_values

    first, types, per = first_frame(coll), key_type_values(), lab.per_sample()
    classes, nulls = marker_classes(lab, sure), null_classes(lab, sure)
    for obj in coll["mocap_labeled"].objects:
        label = int(obj["mocap_label"])
        frames, got, _ = _keys(obj)
        idx = np.flatnonzero((per == label).any(axis=1))
        np.testing.assert_array_equal(frames, idx + first, err_msg=obj.name)
        np.testing.assert_array_equal(got, types[classes[idx, label]], err_msg=obj.name)
    for obj in coll["mocap_unlabeled"].objects:
        slot = int(obj["mocap_null"])
        frames, got, _ = _keys(obj)
        idx = np.flatnonzero(per[:, slot] == NULL)
        np.testing.assert_array_equal(frames, idx + first, err_msg=obj.name)
        np.testing.assert_array_equal(got, types[nulls[idx, slot]], err_msg=obj.name)


def _assert_corrections_hold(lab, review):
    """Every stored correction is honoured exactly by the labeling."""
    per = lab.per_sample()
    for c in review.constraints:
        got = per[c.start:c.stop, c.slot]
        assert (got[got != EMPTY] == c.label).all(), c
    for slot, frame in review.splits:
        assert ((lab.slot == slot) & (lab.start == frame)).any(), (slot, frame)


def _walk(bpy, previous):
    seen = []
    while True:
        try:
            if bpy.ops.mocap_autolabel.next_uncertain(previous=previous) != {"FINISHED"}:
                break
        except RuntimeError:
            break
        obj = bpy.context.active_object
        seen.append((bpy.context.scene.frame_current, obj.name))
        assert len(seen) < 1000
    return seen


def _expected_walk(coll, lab, sure):
    from mocap_autolabel.blender.review import first_frame, object_for

    unsure = review_queue(lab, sure)
    order = unsure[np.lexsort((lab.slot[unsure], lab.start[unsure]))]
    return [(int(lab.start[s]) + first_frame(coll), object_for(coll, lab, int(s)).name) for s in order]


def _long_segment(lab, label):
    seg = np.flatnonzero(lab.label == label)
    return int(seg[np.argmax(lab.stop[seg] - lab.start[seg])])


def _steps_1_to_8(empty_scene, bpy, tmp_path, capfd):
    """Steps 1 to 8 in order, each checked; what step 9 goes on from: the Labeled empties of the
    reopened take by name, its first scene frame and the raw take."""
    from mocap_autolabel.blender.properties import is_take
    from mocap_autolabel.blender.review import FINGER_COLOR_SETS, finger_of, first_frame, key_type_values
    from mocap_autolabel.core.take import read_take

    scene = empty_scene
    settings = scene.mocap_autolabel
    ops = bpy.ops.mocap_autolabel
    src = shutil.copy(DEMO, tmp_path / "demo_take.c3d")
    raw = read_take(src)

    # --- 1. Import: the Take field points at the new take, its first marker is the active object.
    assert ops.import_markers(filepath=str(src)) == {"FINISHED"}
    coll = settings.take
    assert coll is not None and coll.name == "demo_take"
    active = bpy.context.active_object
    assert active is not None and active in list(coll.objects) and active["mocap_slot"] == 0
    assert [o.name for o in bpy.context.selected_objects] == [active.name]
    assert len(coll.objects) == raw.n_points

    # --- 2. Label with the defaults (han19, set, Trajectory voting), whichever marker is selected.
    assert (settings.layout, settings.method, settings.temporal) == ("han19", "set", "vote")
    _select(bpy)  # nothing selected: Label acts on the take in the Take field
    assert ops.label() == {"FINISHED"}
    st = _state(coll)
    assert (st.layout, st.method, st.temporal) == ("han19", "set", "vote")
    lab = st.labeling
    layout = load_layout("han19")
    assert lab.names == layout.names
    # The field offers imported takes only, not their Raw, Labeled or Unlabeled collections.
    children = [coll[k] for k in ("mocap_raw", "mocap_labeled", "mocap_unlabeled")]
    assert is_take(settings, coll) and not any(is_take(settings, c) for c in children)
    assert not is_take(settings, scene.collection)

    # --- 3. What you get: Labeled, Unlabeled and Raw inside the take's collection.
    assert {c.name for c in coll.children} == {"Labeled", "Unlabeled", "Raw"}
    assert sorted(o.name for o in coll["mocap_labeled"].objects) == sorted(layout.names)
    per = lab.per_sample()
    point_names = unlabeled_point_names(raw.names, lab.names)
    with_nulls = np.flatnonzero((per == NULL).any(axis=0))
    assert sorted(o.name for o in coll["mocap_unlabeled"].objects) == sorted(point_names[s] for s in with_nulls)
    assert all(o.name == f"*{o['mocap_null']}" for o in coll["mocap_unlabeled"].objects)  # the demo names none
    raw_coll = coll["mocap_raw"]
    assert sorted(o.name for o in raw_coll.objects) == sorted(f"{n} (raw)" for n in raw.names)
    assert not coll.objects  # every imported empty moved into Raw
    layer = bpy.context.view_layer.layer_collection.children[coll.name].children[raw_coll.name]
    assert layer.hide_viewport and not raw_coll.hide_viewport  # the Outliner's eye, not the monitor flag

    # --- 4. Read the colours: key types by confidence class at Confident at (0.95 by default).
    assert settings.sure == pytest.approx(0.95)
    _assert_keys_show(coll, lab, settings.sure)
    for obj in coll["mocap_labeled"].objects:  # channel groups coloured by finger
        fc = _keys(obj)[2]
        assert fc.group.color_set == FINGER_COLOR_SETS[finger_of(layout, int(obj["mocap_label"]))]
    types = key_type_values()
    assert set(np.unique(_keys(coll["mocap_labeled"].objects["ThumbTip"])[1])) <= set(types.tolist())
    # Moving Confident at recolours the keys and refreshes the list, the counts and the walk at once.
    for sure in (0.999, 0.95):
        settings.sure = sure
        _assert_keys_show(coll, lab, sure)
        assert settings.uncertain_total == len(settings.uncertain) == len(review_queue(lab, sure))
    assert len(uncertain_segments(lab, 0.999)) > len(uncertain_segments(lab, 0.95))
    assert KEY_TYPES == ("KEYFRAME", "BREAKDOWN", "EXTREME", "JITTER")  # confident, uncertain, very, locked

    # --- 5. Go through what is uncertain: the list (worst first, labeled and unlabeled), a click
    # jumps with the marker selected, the Timeline's markers, Worst Frames, Previous / Next.
    unsure = review_queue(lab, settings.sure)
    first = first_frame(coll)
    assert len(settings.uncertain) == len(unsure) > 0
    kinds = [i.unlabeled for i in settings.uncertain]
    assert kinds == sorted(kinds)  # labeled segments in doubt first, then unlabeled pieces
    conf = [i.confidence for i in settings.uncertain if not i.unlabeled]
    assert conf == sorted(conf)  # the least confident first
    labels = {i.label for i in settings.uncertain}
    assert labels & set(layout.names) and any(n.startswith("*") for n in labels)  # labeled and unlabeled ones
    for k in (0, len(settings.uncertain) - 1):
        item = settings.uncertain[k]
        settings.uncertain_index = k  # a click in the list
        assert scene.frame_current == item.frame_start
        assert bpy.context.active_object.name == item.label
        assert [o.name for o in bpy.context.selected_objects] == [item.label]
    ours = [m for m in scene.timeline_markers if m.name.startswith("?demo_take: ")]
    assert 0 < len(ours) <= 20 and all(("uncertain" in m.name or "missing" in m.name) for m in ours)
    assert ops.jump_to_worst() == {"FINISHED"}
    assert bpy.context.active_object is not None
    expected = _expected_walk(coll, lab, settings.sure)
    scene.frame_set(first)
    assert _walk(bpy, previous=False) == expected
    scene.frame_set(first + lab.n_frames - 1)
    assert _walk(bpy, previous=True) == expected[::-1]

    # --- 6. Fix: each edit is one undo step and one correction stored on the take.
    from mocap_autolabel.operators import corrections as review_ops

    for name in FIX_OPERATORS:
        assert "UNDO" in getattr(review_ops, f"MOCAPAL_OT_{name}").bl_options, name
    labeled = {o.name: o for o in coll["mocap_labeled"].objects}

    def corrections():
        review = _state(coll).review
        assert len(settings.corrections) == len(review.constraints) + len(review.splits)
        return review

    # Assign Label: IndexTip's trajectory becomes MiddleTip from this frame to its segment's end;
    # the selection follows it.
    index_tip, middle_tip = lab.names.index("IndexTip"), lab.names.index("MiddleTip")
    seg = _long_segment(lab, index_tip)
    at = int(lab.start[seg]) + 10
    slot = int(lab.slot[seg])
    owner = np.flatnonzero(lab.per_sample()[at] == middle_tip)  # the trajectory MiddleTip is taken from
    scene.frame_set(at + first)
    _select(bpy, labeled["IndexTip"])
    capfd.readouterr()
    assert ops.assign_label(label=str(middle_tip)) == {"FINISHED"}
    assert f"labeled MiddleTip from frame {at + first}" in capfd.readouterr().out
    review = corrections()
    assert review.constraints[-1].slot == slot and review.constraints[-1].label == middle_tip
    assert _state(coll).labeling.per_sample()[at, slot] == middle_tip
    assert bpy.context.active_object == labeled["MiddleTip"]
    # A label taken from another trajectory leaves that one unlabeled (pink: very uncertain).
    assert len(owner) == 1
    other = int(owner[0])
    assert _state(coll).labeling.per_sample()[at, other] == NULL
    frames, got, _ = _keys(coll["mocap_unlabeled"].objects[f"*{other}"])
    assert got[frames == at + first][0] == types[KEY_TYPES.index("EXTREME")]
    # Swap Labels: two labeled markers, their labels swap from this frame on.
    lab = _state(coll).labeling
    ring, pinky = lab.names.index("RingTip"), lab.names.index("PinkyTip")
    per = lab.per_sample()
    both = np.flatnonzero((per == ring).any(axis=1) & (per == pinky).any(axis=1))
    at = int(both[len(both) // 2])
    s_ring, s_pinky = int(np.flatnonzero(per[at] == ring)[0]), int(np.flatnonzero(per[at] == pinky)[0])
    scene.frame_set(at + first)
    n = len(review.constraints)
    _select(bpy, labeled["RingTip"], labeled["PinkyTip"])
    assert ops.swap_labels() == {"FINISHED"}
    review = corrections()
    assert len(review.constraints) == n + 2
    per = _state(coll).labeling.per_sample()
    assert (per[at, s_ring], per[at, s_pinky]) == (pinky, ring)
    # Unlabel: the selected trajectory is a ghost from this frame.
    lab = _state(coll).labeling
    thumb = lab.names.index("ThumbTip")
    seg = _long_segment(lab, thumb)
    at, slot = int(lab.start[seg]) + 5, int(lab.slot[seg])
    scene.frame_set(at + first)
    _select(bpy, labeled["ThumbTip"])
    assert ops.unlabel() == {"FINISHED"}
    review = corrections()
    assert review.constraints[-1].label == NULL and review.constraints[-1].slot == slot
    assert _state(coll).labeling.per_sample()[at, slot] == NULL
    assert coll["mocap_unlabeled"].objects.get(f"*{slot}") is not None
    # Split Trajectory: a new segment starts here on that trajectory.
    lab = _state(coll).labeling
    seg = _long_segment(lab, lab.names.index("MiddleMCP"))
    at, slot = (int(lab.start[seg]) + int(lab.stop[seg])) // 2, int(lab.slot[seg])
    scene.frame_set(at + first)
    _select(bpy, labeled["MiddleMCP"])
    assert ops.split() == {"FINISHED"}
    review = corrections()
    assert review.splits == [(slot, at)]
    assert ((_state(coll).labeling.slot == slot) & (_state(coll).labeling.start == at)).any()
    # Lock: the segment under this frame stays as it is (locked keys are jitter, green).
    lab = _state(coll).labeling
    seg = _long_segment(lab, lab.names.index("IndexMCP"))
    at, slot = int(lab.start[seg]) + 3, int(lab.slot[seg])
    scene.frame_set(at + first)
    _select(bpy, labeled["IndexMCP"])
    n = len(review.constraints)
    assert ops.lock() == {"FINISHED"}
    review = corrections()
    assert len(review.constraints) == n + 1 and _state(coll).labeling.locked[seg]
    frames, got, _ = _keys(labeled["IndexMCP"])
    assert got[frames == at + first][0] == types[KEY_TYPES.index("JITTER")]
    # Unlock: the lock goes, and the take is labeled again without it.
    n = len(review.constraints)
    assert ops.unlock() == {"FINISHED"}
    review = corrections()
    assert len(review.constraints) == n - 1
    assert not any(c.slot == slot and c.start <= at < c.stop for c in review.constraints)
    # Lock it again, and delete it from the Corrections list with X.
    assert ops.lock() == {"FINISHED"}
    review = corrections()
    texts = [c.text for c in settings.corrections]
    assert texts[-2].startswith("IndexMCP on *") and texts[-1].startswith("split *")
    settings.corrections_index = len(review.constraints) - 1
    assert ops.delete_correction() == {"FINISHED"}
    review = corrections()
    assert len(review.constraints) == n - 1 and len([c for c in settings.corrections]) == len(texts) - 1
    _assert_corrections_hold(_state(coll).labeling, review)

    # --- 7. Re-solve keeps every correction exactly.
    before = _state(coll).review
    assert ops.resolve() == {"FINISHED"}
    after = _state(coll)
    assert after.review.constraints == before.constraints and after.review.splits == before.splits
    _assert_corrections_hold(after.labeling, after.review)
    _assert_keys_show(coll, after.labeling, settings.sure)

    # --- 8. Save, reopen (also without the source file), continue; export the labeled C3D.
    blend = tmp_path / "review.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    bpy.ops.wm.read_homefile(use_empty=True)
    Path(src).unlink()
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    scene = bpy.context.scene
    settings = scene.mocap_autolabel
    coll = settings.take
    assert coll is not None and coll.name == "demo_take"
    reopened = _state(coll)
    assert reopened.review.constraints == after.review.constraints and reopened.review.splits == after.review.splits
    np.testing.assert_array_equal(reopened.labeling.per_sample(), after.labeling.per_sample())
    assert len(settings.uncertain) == len(review_queue(reopened.labeling, settings.sure))
    assert len(settings.corrections) == len(after.review.constraints) + len(after.review.splits)
    # Continue: Next and a correction after reopening, then a re-solve from the scene alone.
    scene.frame_set(first)
    assert ops.next_uncertain() == {"FINISHED"}
    labeled = {o.name: o for o in coll["mocap_labeled"].objects}
    lab = reopened.labeling
    seg = _long_segment(lab, lab.names.index("RingMCP"))
    scene.frame_set(int(lab.start[seg]) + first + 2)
    _select(bpy, labeled["RingMCP"])
    assert ops.lock() == {"FINISHED"}
    assert ops.resolve() == {"FINISHED"}
    final = _state(coll)
    assert len(final.review.constraints) == len(reopened.review.constraints) + 1
    _assert_corrections_hold(final.labeling, final.review)
    # Export: the layout's markers by name, then one point per unlabeled trajectory named as its
    # empty; every input sample once, in the file's frames and units.
    out = tmp_path / "demo_labeled.c3d"
    assert ops.export_labeled(filepath=str(out)) == {"FINISHED"}
    back = read_take(out)
    m = len(layout)
    assert back.names[:m] == layout.names
    assert sorted(back.names[m:]) == sorted(o.name for o in coll["mocap_unlabeled"].objects)
    assert back.first_frame == raw.first_frame and back.n_frames == raw.n_frames
    assert back.source_units == raw.source_units
    assert int(back.valid.sum()) == int(raw.valid.sum())
    per = final.labeling.per_sample()
    for label, name in enumerate(layout.names):
        f, s = np.nonzero(per == label)
        np.testing.assert_allclose(back.positions[f, label], raw.positions[f, s], atol=1e-4, err_msg=name)
    for k, name in enumerate(back.names[m:], m):
        slot = int(coll["mocap_unlabeled"].objects[name]["mocap_null"])
        f = np.flatnonzero(per[:, slot] == NULL)
        assert np.flatnonzero(back.valid[:, k]).tolist() == f.tolist(), name
        np.testing.assert_allclose(back.positions[f, k], raw.positions[f, slot], atol=1e-4, err_msg=name)
    return labeled, first, raw


def test_the_readme_walkthrough_steps_1_to_8_on_the_demo_take(empty_scene, bpy_module, tmp_path, capfd):
    _steps_1_to_8(empty_scene, bpy_module, tmp_path, capfd)


@pytest.mark.slow
def test_the_readme_walkthrough_step_by_step_on_the_demo_take(empty_scene, bpy_module, tmp_path, capfd):
    bpy = bpy_module
    ops = bpy.ops.mocap_autolabel
    labeled, first, raw = _steps_1_to_8(empty_scene, bpy, tmp_path, capfd)

    # --- 9. Solve Hand: one keyed rig at the take's frames; solving again replaces it.
    _select(bpy, labeled["IndexTip"])
    calibration = tmp_path / "performer.json"
    assert ops.solve_hand(save_calibration=str(calibration)) == {"FINISHED"}

    def rigs():
        return [o for o in bpy.data.objects if o.type == "ARMATURE"]

    assert len(rigs()) == 1
    arm = rigs()[0]
    from mocap_autolabel.blender import animio

    keyed = sorted({int(k.co[0]) for fc in animio.fcurves_of(arm) for k in fc.keyframe_points})
    assert keyed and keyed[0] >= first and keyed[-1] <= first + raw.n_frames - 1  # the take's frames
    assert tuple(arm.scale) == pytest.approx((1.0, 1.0, 1.0))  # the take's Scale (imported at 1)
    n_objects = len(bpy.data.objects)
    assert ops.solve_hand(calibration=str(calibration)) == {"FINISHED"}  # a reused calibration skips that stage
    assert len(rigs()) == 1 and len(bpy.data.objects) == n_objects
    assert len([c for c in bpy.data.collections if c.get("mocap_solved_from") == "demo_take"]) == 1
