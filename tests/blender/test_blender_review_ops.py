"""The review operators as an animator uses them (issue 33), in the bpy module: which take they act on,
what happens to corrections, the walk through uncertain segments, the threshold, locks, shortcuts
and messages. Each test failed on the code before its fix."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import import_take as _import
from helpers import import_written
from helpers import review_state as state
from helpers import select as _select
from mocap_autolabel.core.formats.c3d import write_c3d
from mocap_autolabel.core.labeling import EMPTY, NULL
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.review import KEY_TYPES, marker_classes, review_queue, uncertain_segments
from mocap_autolabel.core.synth.generate import synthesize

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "samples" / "demo_take.c3d"


@pytest.fixture(scope="module")
def take_files(tmp_path_factory):
    """A han19 take and a glove13 take (synthetic, 600 frames each)."""
    folder = tmp_path_factory.mktemp("review_ops")
    out = {}
    for name, layout, seed in (("syn", "han19", 3), ("glove", "glove13", 4)):
        path = folder / f"{name}.c3d"
        write_c3d(synthesize(load_layout(layout), 600, seed=seed).take, path)
        out[name] = path
    return out


@pytest.fixture
def labeled(empty_scene, bpy_module, take_files, tmp_path):
    bpy = bpy_module
    coll = _import(bpy, take_files["syn"], tmp_path)
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    return bpy, coll


def labeled_objects(coll):
    return {int(o["mocap_label"]): o for o in coll["mocap_labeled"].objects}


def _long_segment(lab, label):
    seg = np.flatnonzero(lab.label == label)
    return int(seg[np.argmax(lab.length[seg])])


def _key_types(obj):
    from mocap_autolabel.blender import animio

    fc = animio.find_fcurve(obj, "location", 0)
    return animio.read_keys(fc)[0], animio.read_key_types(fc)


# --- bug 1: Label acts on the panel's take, import makes the new take active, corrections survive ---

def test_label_acts_on_the_panels_take_and_never_drops_corrections_silently(labeled, take_files, tmp_path, capfd):
    bpy, syn = labeled
    lab = state(syn).labeling
    thumb, index = lab.names.index("ThumbTip"), lab.names.index("IndexTip")
    # Two corrections on the han19 take: lock a ThumbTip segment, unlabel IndexTip.
    seg = _long_segment(lab, thumb)
    bpy.context.scene.frame_set(int(lab.start[seg]) + 2)
    _select(bpy, labeled_objects(syn)[thumb])
    assert bpy.ops.mocap_autolabel.lock() == {"FINISHED"}
    lab = state(syn).labeling
    seg = _long_segment(lab, index)
    bpy.context.scene.frame_set(int(lab.start[seg]) + 2)
    _select(bpy, labeled_objects(syn)[index])
    assert bpy.ops.mocap_autolabel.unlabel() == {"FINISHED"}
    before = state(syn)
    assert len(before.review.constraints) == 2

    # Import a second take: it is the panel's take and the active one.
    glove = _import(bpy, take_files["glove"], tmp_path)
    settings = bpy.context.scene.mocap_autolabel
    assert settings.take == glove and glove != syn
    active_after_import = bpy.context.active_object
    # Even with the first take's marker active, Label acts on the take in the Take field.
    _select(bpy, labeled_objects(syn)[thumb])
    settings.layout = "glove13"
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    after = state(syn)
    assert after.layout == "han19" and after.review.constraints == before.review.constraints
    assert settings.take == glove and state(glove).layout == "glove13"
    from mocap_autolabel.blender.review import take_collection

    assert take_collection(active_after_import) == glove  # the import made the new take the active one

    # Relabeling a take with another layout keeps the ghost decision (valid in any layout) and says
    # that a lock on a marker the new layout lacks cannot follow: a glove13 take labeled with han19
    # (it warns), corrected, then labeled as glove13 (the README's "Label as glove13"). (The han19
    # take relabeled with glove13, as this test did before, is refused now: no glove13 hand in it.)
    settings.take = syn
    assert settings.layout == "han19"  # the Layout field follows the take (the one it was labeled with)
    settings.take = glove
    assert settings.layout == "glove13"
    wrong = import_written(bpy, synthesize(load_layout("glove13"), 300, seed=4).take, tmp_path, "glove1")
    settings.layout = "han19"
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    for name, op in (("ThumbIP", bpy.ops.mocap_autolabel.lock), ("IndexTip", bpy.ops.mocap_autolabel.unlabel)):
        lab = state(wrong).labeling
        seg = _long_segment(lab, lab.names.index(name))
        bpy.context.scene.frame_set(int(lab.start[seg]) + 2)
        _select(bpy, labeled_objects(wrong)[lab.names.index(name)])
        assert op() == {"FINISHED"}
    before = state(wrong)
    settings.layout = "glove13"
    capfd.readouterr()
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    out = capfd.readouterr().out
    unlabel = before.review.constraints[1]
    assert state(wrong).layout == "glove13" and state(wrong).review.constraints == [unlabel]
    assert "dropped" in out and "ThumbIP on" in out and "1 correction kept" in out
    per = state(wrong).labeling.per_sample()[unlabel.start:unlabel.stop, unlabel.slot]
    assert (per[per != EMPTY] == NULL).all()


def test_the_issue_scenario_on_the_real_glove_recording(empty_scene, bpy_module, tmp_path):
    """Issue 33, bug 1 as found: the demo take labeled with 2 corrections, then the real glove
    recording imported and labeled with glove13 from the panel: the glove is labeled, the demo keeps
    its labels and corrections, and the panel stays on the glove."""
    from conftest import data_path

    glove_file = data_path("hands", "qualisys_glove13", "recording_part1.tsv")
    bpy = bpy_module
    demo = _import(bpy, DEMO, tmp_path)
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    thumb = demo["mocap_labeled"].objects["ThumbTip"]
    for frame, op in ((900, bpy.ops.mocap_autolabel.lock), (100, bpy.ops.mocap_autolabel.unlabel)):
        bpy.context.scene.frame_set(frame)
        _select(bpy, thumb)
        assert op() == {"FINISHED"}
    before = state(demo)
    glove = _import(bpy, glove_file, tmp_path)
    settings = bpy.context.scene.mocap_autolabel
    settings.layout = "glove13"
    _select(bpy, thumb)  # the demo's marker still active, as in the report
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    assert settings.take == glove and state(glove).layout == "glove13"
    after = state(demo)
    assert after.layout == "han19" and after.review.constraints == before.review.constraints


# --- bug 5: Previous / Next reach every segment of the review queue ---------------------------

def _walk(bpy, previous):
    scene = bpy.context.scene
    seen = []
    while True:
        try:
            result = bpy.ops.mocap_autolabel.next_uncertain(previous=previous)
        except RuntimeError:
            break
        if result != {"FINISHED"}:
            break
        obj = bpy.context.active_object  # a labeled marker, or the unlabeled *N empty of its slot
        seen.append((scene.frame_current, int(obj["mocap_label"]) if "mocap_label" in obj else -1))
        assert len(seen) < 1000
    return seen


def _in_time_order(lab, queue, first: int) -> list[tuple[int, int]]:
    order = queue[np.lexsort((lab.slot[queue], lab.start[queue]))]
    return [(int(lab.start[s]) + first, int(lab.label[s])) for s in order]


def test_previous_and_next_visit_every_uncertain_segment_in_time_order(empty_scene, bpy_module, tmp_path):
    """The demo take's review queue (labeled and unlabeled segments), some starting on frame 1 and
    several on one frame: Next from frame 1 and Previous from the end each visit all of them, once,
    in time order; with the panel's filters, the entries the list shows."""
    bpy = bpy_module
    coll = _import(bpy, DEMO, tmp_path)
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    lab = state(coll).labeling
    settings = bpy.context.scene.mocap_autolabel
    expected = _in_time_order(lab, review_queue(lab, settings.sure), 1)
    assert len(expected) >= 2 and len({f for f, _ in expected}) < len(expected)  # a shared start frame
    assert any(label < 0 for _, label in expected) and len(expected) < len(uncertain_segments(lab, settings.sure))
    bpy.context.scene.frame_set(1)
    assert _walk(bpy, previous=False) == expected
    bpy.context.scene.frame_set(lab.n_frames)
    assert _walk(bpy, previous=True) == expected[::-1]
    settings.queue_labeled_only = True
    labeled = _in_time_order(lab, review_queue(lab, settings.sure, labeled_only=True), 1)
    assert labeled == [e for e in expected if e[1] >= 0]
    bpy.context.scene.frame_set(lab.n_frames)
    assert _walk(bpy, previous=True) == labeled[::-1]


def test_next_and_previous_walk_the_whole_take_imported_from_frame_0(empty_scene, bpy_module, take_files):
    """Issue 47: a negative Frame Offset put keys before frame 0, where the scene's range and current frame
    cannot go, and Next from the start skipped every segment there. The lowest offset import allows puts the
    take on frame 0: Next from the start and Previous from the end each visit every segment, in time order."""
    from mocap_autolabel.core.take import read_take

    bpy = bpy_module
    first = read_take(take_files["syn"]).first_frame
    assert bpy.ops.mocap_autolabel.import_markers(filepath=str(take_files["syn"]), frame_offset=-first) == {"FINISHED"}
    coll = bpy.context.scene.mocap_autolabel.take
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    lab = state(coll).labeling
    scene = bpy.context.scene
    expected = _in_time_order(lab, review_queue(lab, scene.mocap_autolabel.sure), 0)  # sample 0 is frame 0
    assert (scene.frame_start, scene.frame_end) == (0, lab.n_frames - 1) and expected[0][0] == 0
    scene.frame_set(scene.frame_start)
    assert _walk(bpy, previous=False) == expected
    scene.frame_set(scene.frame_end)
    assert _walk(bpy, previous=True) == expected[::-1]


# --- bug 6: Confident at refreshes the list, the counts, the walk and the key colours ----------

def test_confident_at_refreshes_list_counts_and_key_colours(labeled):
    from mocap_autolabel.blender import animio
    from mocap_autolabel.blender.review import key_type_values, summary

    bpy, coll = labeled
    settings = bpy.context.scene.mocap_autolabel
    lab = state(coll).labeling
    types = key_type_values()
    for sure in (0.9, 0.999, 0.95):
        settings.sure = sure
        expected = review_queue(lab, settings.sure)
        assert len(settings.uncertain) == settings.uncertain_total == len(expected)
        assert summary(lab, settings.sure)["uncertain"] == len(uncertain_segments(lab, settings.sure)) == \
            len(expected) + settings.uncertain_hidden
        assert [(i.slot, i.frame_start - 1) for i in settings.uncertain] == \
            [(int(lab.slot[s]), int(lab.start[s])) for s in expected]
        classes = marker_classes(lab, settings.sure)
        for label, obj in labeled_objects(coll).items():
            frames, got = _key_types(obj)
            np.testing.assert_array_equal(got, types[classes[frames.astype(int) - 1, label]])
    # 0.999 makes more segments uncertain than 0.9: the colours really changed in between.
    assert len(uncertain_segments(lab, 0.999)) > len(uncertain_segments(lab, 0.9))
    assert animio.key_type_value(KEY_TYPES[0]) in types


# --- bug 7: overriding a lock says so; Unlock; list and delete single corrections -------------

def test_overriding_a_lock_warns_and_corrections_can_be_listed_unlocked_and_deleted(labeled, capfd):
    bpy, coll = labeled
    scene = bpy.context.scene
    settings = scene.mocap_autolabel
    lab = state(coll).labeling
    thumb = lab.names.index("ThumbTip")
    seg = _long_segment(lab, thumb)
    start, stop = int(lab.start[seg]), int(lab.stop[seg])
    late, early = start + 2 * (stop - start) // 3, start + (stop - start) // 3
    _select(bpy, labeled_objects(coll)[thumb])
    scene.frame_set(late + 1)
    assert bpy.ops.mocap_autolabel.lock() == {"FINISHED"}
    assert [c.text for c in settings.corrections] == [f"ThumbTip on *{lab.slot[seg]}, frames {start + 1}-{stop}"]
    capfd.readouterr()
    scene.frame_set(early + 1)
    assert bpy.ops.mocap_autolabel.unlabel() == {"FINISHED"}
    out = capfd.readouterr().out
    assert "Warning: this overrides your earlier correction (ThumbTip on" in out
    review = state(coll).review
    assert len(review.constraints) == 2 and len(settings.corrections) == 2
    assert settings.corrections[1].kind == "ghost"

    # Unlock at the early frame removes the unlabel (and only it) and re-solves.
    _select(bpy, coll["mocap_unlabeled"].objects[f"*{lab.slot[seg]}"])
    assert bpy.ops.mocap_autolabel.unlock() == {"FINISHED"}
    assert state(coll).review.constraints == review.constraints[:1]
    assert len(settings.corrections) == 1
    # Delete the remaining one from the list: no correction left, nothing locked.
    settings.corrections_index = 0
    assert bpy.ops.mocap_autolabel.delete_correction() == {"FINISHED"}
    after = state(coll)
    assert after.review.constraints == [] and not after.labeling.locked.any() and len(settings.corrections) == 0
    # A split is a correction too: listed after the decisions, deleted the same way.
    lab = after.labeling
    seg = _long_segment(lab, thumb)
    scene.frame_set(int(lab.start[seg]) + 5 + 1)
    _select(bpy, labeled_objects(coll)[thumb])
    assert bpy.ops.mocap_autolabel.split() == {"FINISHED"}
    assert [c.kind for c in settings.corrections] == ["split"]
    assert settings.corrections[0].text == f"split *{lab.slot[seg]} at frame {int(lab.start[seg]) + 6}"
    assert bpy.ops.mocap_autolabel.delete_correction(index=0) == {"FINISHED"}
    assert state(coll).review.splits == [] and len(settings.corrections) == 0
    # Nothing to unlock: a clear error naming the marker and the frame.
    _select(bpy, labeled_objects(coll)[thumb])
    scene.frame_set(late + 1)
    with pytest.raises(RuntimeError, match=f"ThumbTip: no correction at frame {late + 1}"):
        bpy.ops.mocap_autolabel.unlock()


# --- bug 8: the Take field holds only imported takes ------------------------------------------

def test_the_take_field_holds_only_imported_takes(labeled):
    bpy, coll = labeled
    settings = bpy.context.scene.mocap_autolabel
    raw = coll["mocap_raw"]
    settings.take = raw  # a take's own child stands for its take
    n_collections = len(bpy.data.collections)
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    assert len(bpy.data.collections) == n_collections  # no second labeled take inside Raw
    assert not any(o.name.endswith("(raw) (raw)") for o in bpy.data.objects)
    assert settings.take == coll
    from mocap_autolabel.blender.properties import is_take

    assert is_take(settings, coll) and not is_take(settings, raw)  # what the field offers
    other = bpy.data.collections.new("Props")
    bpy.context.scene.collection.children.link(other)
    settings.take = other  # not a take: refused
    assert settings.take is None
    _select(bpy)
    with pytest.raises(RuntimeError, match="Import a take first"):
        bpy.ops.mocap_autolabel.label()
    # Written past the field's checks (raw storage, or a file from before them): the operators refuse it.
    settings["take"] = other
    _select(bpy, labeled_objects(coll)[0])
    for op in (bpy.ops.mocap_autolabel.label, bpy.ops.mocap_autolabel.resolve,
               bpy.ops.mocap_autolabel.next_uncertain):
        with pytest.raises(RuntimeError, match="'Props' is not an imported take"):
            op()


# --- bug 9: the Label operator's own properties win -------------------------------------------

def test_the_label_operators_own_properties_win_over_the_panels(empty_scene, bpy_module, tmp_path):
    """On a glove13 take (labeling it with han19 only warns; a han19 take labeled with glove13 is
    refused now, no glove13 hand in it, which this test used before)."""
    bpy = bpy_module
    coll = import_written(bpy, synthesize(load_layout("glove13"), 300, seed=4).take, tmp_path, "glove1")
    settings = bpy.context.scene.mocap_autolabel
    assert settings.layout == "han19"
    assert bpy.ops.mocap_autolabel.label(layout="glove13") == {"FINISHED"}
    assert state(coll).layout == "glove13"
    assert settings.layout == "han19"  # the operator's own layout did not change the panel's
    assert bpy.ops.mocap_autolabel.label(temporal="none") == {"FINISHED"}
    st = state(coll)
    assert (st.layout, st.temporal) == ("han19", "none")  # not given: the panel's layout
    # One click on the Review panel's "is this a glove13 take?" box runs Label with the suggested layout.
    doubt = st.labeling.info["layout_doubt"]
    assert doubt["better"] == "glove13"
    # (the button: ui/panels.py, MOCAPAL_PT_review)
    assert bpy.ops.mocap_autolabel.label(layout=doubt["better"], use_as_panel_layout=True) == {"FINISHED"}
    assert state(coll).layout == "glove13" and "layout_doubt" not in state(coll).labeling.info
    assert settings.layout == "glove13"  # the panel now says what the take is labeled with


# --- the missing pieces: shortcuts, selection after Assign, messages, progress ------------------

EDIT_KEYS = {"mocap_autolabel.assign_label": "A", "mocap_autolabel.swap_labels": "S",
             "mocap_autolabel.unlabel": "U", "mocap_autolabel.lock": "L"}


def test_shortcuts_for_the_edits_register_unregister_and_are_free(bpy_module):
    import sys

    import addon_utils

    bpy = bpy_module
    keymap = bpy.context.window_manager.keyconfigs.addon.keymaps["Frames"]

    def ours():
        return {(i.idname, i.type, i.shift, i.alt, i.ctrl) for i in keymap.keymap_items
                if i.idname.startswith("mocap_autolabel.")}

    assert {(op, key, True, True, False) for op, key in EDIT_KEYS.items()} <= ours()
    ui = ("MOCAPAL_PT_corrections", "MOCAPAL_UL_corrections")
    assert all(hasattr(bpy.types, n) for n in ui)
    addon_utils.disable("mocap_autolabel", default_set=True)
    try:
        assert not ours() and not any(hasattr(bpy.types, n) for n in ui)
    finally:
        addon_utils.enable("mocap_autolabel", default_set=True)
    assert len(ours()) == len(EDIT_KEYS) + 2  # no duplicates after a second registration
    # Blender's default keymap binds none of them where a reviewer works.
    sys.path.insert(0, str(Path(bpy.utils.resource_path("LOCAL")) / "scripts/presets/keyconfig/keymap_data"))
    try:
        import blender_default
    finally:
        sys.path.pop(0)
    where = {"Window", "Screen", "Frames", "Object Mode", "Object Non-modal", "3D View", "3D View Generic",
             "Dopesheet", "Dopesheet Generic", "Graph Editor", "Graph Editor Generic", "Animation", "Outliner"}
    taken = set()
    for name, _args, data in blender_default.generate_keymaps(blender_default.Params()):
        for _idname, event, _props in data.get("items", []):
            if name in where and isinstance(event, dict) and event.get("shift") and event.get("alt") \
                    and not event.get("ctrl") and not event.get("oskey"):
                taken.add(event.get("type"))
    assert not taken & (set(EDIT_KEYS.values()) | {"LEFT_ARROW", "RIGHT_ARROW"})


def test_assign_moves_the_selection_and_messages_name_marker_and_frame(labeled, capfd):
    bpy, coll = labeled
    scene = bpy.context.scene
    lab = state(coll).labeling
    a, b = lab.names.index("IndexTip"), lab.names.index("MiddleTip")
    seg = _long_segment(lab, a)
    frame = int(lab.start[seg]) + 3
    scene.frame_set(frame + 1)
    _select(bpy, labeled_objects(coll)[a])
    capfd.readouterr()
    assert bpy.ops.mocap_autolabel.assign_label(label=str(b)) == {"FINISHED"}
    out = capfd.readouterr().out
    assert bpy.context.active_object == labeled_objects(coll)[b]  # the selection followed the trajectory
    assert [o.name for o in bpy.context.selected_objects] == ["MiddleTip"]
    assert f"IndexTip (*{lab.slot[seg]}) labeled MiddleTip from frame {frame + 1}: 1 correction on the take" in out
    assert "slot" not in out
    # Unlabel: one trajectory, singular.
    capfd.readouterr()
    assert bpy.ops.mocap_autolabel.unlabel() == {"FINISHED"}
    assert "unlabeled from frame" in capfd.readouterr().out
    # Nothing selected: say so.
    _select(bpy)
    for op in (bpy.ops.mocap_autolabel.unlabel, bpy.ops.mocap_autolabel.lock, bpy.ops.mocap_autolabel.split):
        with pytest.raises(RuntimeError, match="no marker selected"):
            op()
    # A marker with no sample at the frame: named, with the frame as the scene shows it.
    per = state(coll).labeling.per_sample()
    c = lab.names.index("RingTip")
    missing = np.flatnonzero(~(per == c).any(axis=1))
    if len(missing):
        scene.frame_set(int(missing[0]) + 1)
        _select(bpy, labeled_objects(coll)[c])
        with pytest.raises(RuntimeError, match=f"RingTip has no sample at frame {int(missing[0]) + 1}"):
            bpy.ops.mocap_autolabel.lock()


def test_labeling_reports_its_true_stages_and_share_done(labeled):
    from mocap_autolabel.blender.review import prepare_label
    from mocap_autolabel.core.jobs import Job

    bpy, coll = labeled
    request = prepare_label(coll)
    heard = []
    job = Job(lambda say: request.run(lambda m: (heard.append((m, request.done)), say(m)), check_layout=True))
    job.start().wait(120)
    assert job.error is None and request.done == 1.0
    words = [m.split(" ")[0] for m, _ in heard]
    assert words[0] == "finding"
    firsts = [words.index(w) for w in ("finding", "packing", "scoring", "temporal", "checking")]
    assert firsts == sorted(firsts)  # the stages in their order, each heard
    shares = [d for _, d in heard]
    assert shares[0] == 0.0 and shares == sorted(shares)  # the share done never goes back
    scored = shares[words.index("temporal")]
    assert 0.5 < scored < shares[words.index("checking")] < 1.0  # the layout check is the last of the work
