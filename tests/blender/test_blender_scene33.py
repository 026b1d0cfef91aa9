"""Issue 33, scene side (bpy module): a take's scale, frame offset, units and names hold in everything
built for it (labels, rig, exports); counts agree with the CLI; analog-only files create nothing."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
from conftest import data_path
from mocap_autolabel.core.formats.c3d import write_c3d
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.synth.generate import synthesize
from mocap_autolabel.core.take import read_take

FRAMES = 400
FIRST = 101  # the file's own first frame


@pytest.fixture(scope="module")
def take_file(tmp_path_factory):
    take = synthesize(load_layout("han19"), FRAMES, seed=3).take
    take = dataclasses.replace(take, first_frame=FIRST)
    path = tmp_path_factory.mktemp("scene33") / "syn.c3d"
    write_c3d(take, path)
    return path


def _import_and_label(bpy, scene, path, layout="han19", **options):
    assert bpy.ops.mocap_autolabel.import_markers(filepath=str(path), **options) == {"FINISHED"}
    bpy.context.view_layer.objects.active = None  # label the take in the panel (the new one)
    scene.mocap_autolabel.layout = layout
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    return scene.mocap_autolabel.take


def _select(bpy, obj):
    for other in bpy.context.selected_objects:
        other.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def _no_numbered_duplicates(bpy):
    """Names Blender made unique by appending .001 (a clash between two takes)."""
    ids = list(bpy.data.objects) + list(bpy.data.collections) + list(bpy.data.armatures)
    return [i.name for i in ids if re.search(r"\.\d{3}$", i.name)]


# --- bug 3: Solve Hand ignores the import Scale ------------------------------------------------------

@pytest.mark.slow
def test_solve_hand_lives_in_the_takes_scale_and_frames(empty_scene, bpy_module, take_file):
    """Imported at Scale 100 with a Frame Offset, labeled and solved: the rig's markers sit on the labeled
    empties (in Blender units, at the same Blender frames), not 100x smaller at the file's frames."""
    bpy = bpy_module
    coll = _import_and_label(bpy, empty_scene, take_file, scale=100.0, frame_offset=-100)
    labeled = {o.name: o for o in coll["mocap_labeled"].objects}
    _select(bpy, labeled["IndexTip"])
    assert bpy.ops.mocap_autolabel.solve_hand() == {"FINISHED"}
    arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
    markers = next(o for o in bpy.data.objects if "marker_names" in o)
    from mocap_autolabel.blender import animio

    keyed = animio.read_keys(animio.fcurves_of(arm)[0])[0]
    assert keyed[0] == FIRST - 100  # the take's Blender frames, offset included
    errors = []
    for frame in (FIRST - 100 + 50, FIRST - 100 + 250):
        bpy.context.scene.frame_set(frame)
        mesh = markers.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
        world = np.array([markers.matrix_world @ v.co for v in mesh.vertices])
        markers.to_mesh_clear()
        for i, name in enumerate(markers["marker_names"]):
            obj = labeled[name]
            if not obj.hide_viewport:
                errors.append(np.linalg.norm(world[i] - np.array(obj.matrix_world.translation)))
    # 100 Blender units per metre: the fit's few millimetres are well under 2 units.
    assert errors and np.median(errors) < 2.0


# --- bug 12: analog-only files ----------------------------------------------------------------------

@pytest.mark.parametrize("name", ["Kistler.c3d", "C3DRotationExample.c3d"])
def test_an_analog_only_file_creates_nothing(empty_scene, bpy_module, name):
    bpy = bpy_module
    path = data_path("c3d", "ezc3d-testFiles", name)
    scene = empty_scene
    scene.render.fps, scene.render.fps_base, scene.frame_start, scene.frame_end = 24, 1.0, 1, 250
    with pytest.raises(RuntimeError, match=f"{name}.*no marker"):
        bpy.ops.mocap_autolabel.import_markers(filepath=str(path))
    assert len(bpy.data.collections) == 0 and len(bpy.data.objects) == 0
    assert (scene.render.fps, scene.render.fps_base, scene.frame_start, scene.frame_end) == (24, 1.0, 1, 250)


def test_a_file_without_a_valid_sample_creates_nothing(empty_scene, bpy_module, tmp_path):
    from helpers import small_take

    take = small_take(frames=20, points=3)
    take.positions[:] = np.nan
    path = tmp_path / "blank.c3d"
    write_c3d(take, path)
    with pytest.raises(RuntimeError, match="blank.c3d.*no imported point has a single valid sample"):
        bpy_module.ops.mocap_autolabel.import_markers(filepath=str(path))
    assert len(bpy_module.data.collections) == 0 and len(bpy_module.data.objects) == 0


def test_a_name_filter_that_matches_nothing_creates_nothing(empty_scene, bpy_module, take_file):
    bpy = bpy_module
    with pytest.raises(RuntimeError, match="no point matches"):
        bpy.ops.mocap_autolabel.import_markers(filepath=str(take_file), name_filter="Nothing*")
    assert len(bpy.data.collections) == 0


# --- bug 13: export shifts frames -------------------------------------------------------------------

def test_export_keeps_the_files_frames_units_and_samples(empty_scene, bpy_module, take_file, tmp_path):
    """Import with Frame Offset and Scale, label, export: the labeled C3D starts at the file's own first
    frame, in its units, every sample at its place in metres."""
    bpy = bpy_module
    coll = _import_and_label(bpy, empty_scene, take_file, scale=100.0, frame_offset=-100)
    assert empty_scene.frame_start == FIRST - 100
    out = tmp_path / "labeled.c3d"
    assert bpy.ops.mocap_autolabel.export_labeled(filepath=str(out)) == {"FINISHED"}
    back, raw = read_take(out), read_take(take_file)
    assert back.first_frame == FIRST and back.n_frames == FRAMES and back.source_units == raw.source_units
    assert back.valid.sum() == raw.valid.sum()
    # Every input sample once, at its place: compare sorted per-frame sample sets.
    for f in (0, 123, FRAMES - 1):
        a = np.sort(raw.positions[f][raw.valid[f]], axis=0)
        b = np.sort(back.positions[f][back.valid[f]], axis=0)
        np.testing.assert_allclose(a, b, atol=2e-5)
    assert coll.name == "syn"


# --- bug 10: names are lost -------------------------------------------------------------------------

def test_named_points_keep_their_names_and_star_numbers_match(empty_scene, bpy_module, tmp_path):
    """The glove recording's body and pillow points that no label takes keep their file names in the
    scene and in the exported C3D; the exported *N points are the scene's *N empties."""
    bpy = bpy_module
    path = data_path("hands", "qualisys_glove13", "recording_part1.tsv")
    coll = _import_and_label(bpy, empty_scene, path, layout="glove13")
    layout = load_layout("glove13")
    raw = read_take(path)
    unlabeled = {o.name: int(o["mocap_null"]) for o in coll["mocap_unlabeled"].objects}
    body = [n for n in raw.names if n not in layout.names]
    kept = [n for n in unlabeled if n in body]
    assert "right_elbow" in kept and "pillow_top" in kept, sorted(unlabeled)
    assert all(raw.names[slot] == name for name, slot in unlabeled.items() if not name.startswith("*"))
    out = tmp_path / "glove_labeled.c3d"
    assert bpy.ops.mocap_autolabel.export_labeled(filepath=str(out)) == {"FINISHED"}
    back = read_take(out)
    assert back.names[:len(layout)] == layout.names
    assert sorted(back.names[len(layout):]) == sorted(unlabeled)


def test_star_numbers_in_the_export_are_the_scenes(empty_scene, bpy_module, take_file, tmp_path):
    bpy = bpy_module
    coll = _import_and_label(bpy, empty_scene, take_file)
    out = tmp_path / "labeled.c3d"
    assert bpy.ops.mocap_autolabel.export_labeled(filepath=str(out)) == {"FINISHED"}
    back = read_take(out)
    scene_nulls = {o.name: int(o["mocap_null"]) for o in coll["mocap_unlabeled"].objects}
    exported = back.names[19:]
    assert exported and sorted(exported) == sorted(scene_nulls)
    assert all(name == f"*{slot}" for name, slot in scene_nulls.items())
    # The samples of each exported *N are those its scene empty is keyed with.
    from mocap_autolabel.blender import animio

    obj = next(o for o in coll["mocap_unlabeled"].objects if o.name == exported[0])
    frames, _ = animio.read_keys(animio.find_fcurve(obj, "location", 0))
    np.testing.assert_array_equal(np.flatnonzero(back.valid[:, 19]) + FIRST, frames.astype(int))


@pytest.mark.slow
def test_two_takes_in_one_scene_never_clash(empty_scene, bpy_module, take_file, tmp_path):
    """A second take (here the same file again) labeled and solved beside the first gets its own names,
    documented as "<take>:<name>", never Blender's ".001"."""
    import shutil

    bpy = bpy_module
    first = _import_and_label(bpy, empty_scene, take_file)
    _select(bpy, next(iter(first["mocap_labeled"].objects)))
    assert bpy.ops.mocap_autolabel.solve_hand() == {"FINISHED"}
    other = shutil.copy(take_file, tmp_path / "second.c3d")
    second = _import_and_label(bpy, empty_scene, other)
    assert second != first
    _select(bpy, next(iter(second["mocap_labeled"].objects)))
    assert bpy.ops.mocap_autolabel.solve_hand() == {"FINISHED"}
    assert _no_numbered_duplicates(bpy) == []
    names = {o.name for o in second["mocap_labeled"].objects}
    assert "second:IndexTip" in names
    assert {o.name for o in first["mocap_labeled"].objects} >= {"IndexTip"}
    assert len([o for o in bpy.data.objects if o.type == "ARMATURE"]) == 2


# --- bug 11: counts disagree ------------------------------------------------------------------------

def test_uncertain_counts_agree_with_the_cli_and_unlabeled_ones_are_reviewable(empty_scene, bpy_module,
                                                                              take_file, tmp_path):
    """The panel's uncertain count is the CLI's (uncertain unlabeled segments included); such a segment is
    in the list and Next/jump select its *N empty; the report gives the take's own frame numbers."""
    import json

    from mocap_autolabel.blender.review import load_state
    from mocap_autolabel.cli import main

    bpy = bpy_module
    coll = _import_and_label(bpy, empty_scene, take_file)
    settings = empty_scene.mocap_autolabel
    lab = load_state(coll).labeling
    report = tmp_path / "report.json"
    assert main(["label", str(take_file), "--layout", "han19", "--report", str(report)]) == 0
    cli = json.loads(report.read_text())["summary"]["uncertain_segments"]
    assert settings.uncertain_total + settings.uncertain_hidden == len(cli) == \
        len(lab.summary(settings.sure)["uncertain_segments"])
    # The panel lists the review queue (issue 48), as the report's page ranks the report's segments.
    from mocap_autolabel.core.review import queue_entries

    assert [(i.slot, i.frame_start) for i in settings.uncertain] == \
        [(s["slot"], s["frame_start"]) for s in queue_entries(cli)]
    settings.queue_min_frames = 1  # every uncertain unlabeled piece, however short
    assert settings.uncertain_total == len(cli)
    nulls = [i for i, item in enumerate(settings.uncertain) if item.label.startswith("*")]
    assert nulls, "an uncertain unlabeled segment must be in the list"
    item = settings.uncertain[nulls[0]]
    assert bpy.ops.mocap_autolabel.jump_to_segment(index=nulls[0]) == {"FINISHED"}
    assert bpy.context.active_object.name == item.label and "mocap_null" in bpy.context.active_object
    assert empty_scene.frame_current == item.frame_start
    # The report's frames are the take's own (first frame 101), as Blender shows them on import.
    starts = {(s["point"], s["frame_start"]) for s in cli}
    assert (item.label, item.frame_start) in starts
    assert min(s["frame_start"] for s in cli) >= FIRST


# --- Solve Hand runs like Label: progress, Esc cancels and leaves the scene as it was --------------

@pytest.mark.slow
def test_solve_hand_reports_progress_and_a_cancel_leaves_the_scene_unchanged(empty_scene, bpy_module, take_file):
    """The modal Solve Hand runs SolveRequest.run on a Job (headless Blender has no window for the modal
    loop itself): the shares it reports rise to 1, and a cancel stops the solve with nothing built."""
    import time

    from mocap_autolabel.core.jobs import Job
    from mocap_autolabel.operators.solve_hand import MOCAPAL_OT_solve_hand, SolveRequest

    bpy = bpy_module
    coll = _import_and_label(bpy, empty_scene, take_file)
    _select(bpy, next(iter(coll["mocap_labeled"].objects)))
    found = MOCAPAL_OT_solve_hand._labeled(type("Props", (), {"filepath": "", "layout_file": "",
                                                              "layout": "han19"})(), bpy.context)
    request = SolveRequest(*found)
    shares, messages = [], []

    def say(message):
        shares.append(request.share)
        messages.append(message)

    start = time.perf_counter()
    solved = request.run(say)
    seconds = time.perf_counter() - start
    assert messages[0] == "calibrating the hand" and "solving frames (100 %)" in messages
    assert shares == sorted(shares) and shares[-1] == pytest.approx(1.0) and len(shares) >= 8
    assert solved.first_frame == FIRST and seconds < 30
    # Cancelled as soon as the frames' solve starts: the Job ends cancelled and nothing was added.
    objects = len(bpy.data.objects)
    request = SolveRequest(*found)
    job = Job(lambda say: request.run(lambda m: (job.cancel() if m.startswith("solving") else None, say(m))))
    assert job.start().wait(60) and job.cancelled
    assert len(bpy.data.objects) == objects and not [o for o in bpy.data.objects if o.type == "ARMATURE"]


def test_the_raw_collection_is_toggled_with_the_outliners_eye(empty_scene, bpy_module, take_file):
    """Raw is hidden with the eye (the view layer's layer collection), not the monitor flag the Outliner
    does not show by default; the eye shows it again, and a later edit (a re-solve) leaves it as set."""
    bpy = bpy_module
    coll = _import_and_label(bpy, empty_scene, take_file)
    raw = coll["mocap_raw"]
    layer = bpy.context.view_layer.layer_collection.children[coll.name].children[raw.name]
    obj = raw.objects[0]
    assert not raw.hide_viewport and layer.hide_viewport and not obj.visible_get()
    layer.hide_viewport = False  # the reviewer clicks the eye
    bpy.context.scene.frame_set(bpy.context.scene.frame_start + 200)
    assert any(o.visible_get() for o in raw.objects)
    assert bpy.ops.mocap_autolabel.resolve() == {"FINISHED"}
    assert not layer.hide_viewport


# --- the bad-frames overview, and the Import button ------------------------------------------------

def test_bad_frames_are_marked_on_the_timeline_and_jump_to_worst_goes_there(empty_scene, bpy_module, take_file):
    from mocap_autolabel.blender.review import load_state
    from mocap_autolabel.core.review import bad_runs, frame_trouble

    bpy = bpy_module
    scene = empty_scene
    scene.timeline_markers.new("mine", frame=5)  # the user's own marker stays
    coll = _import_and_label(bpy, scene, take_file)
    lab = load_state(coll).labeling
    runs = bad_runs(lab, scene.mocap_autolabel.sure)
    ours = sorted((m.frame, m.name) for m in scene.timeline_markers if m.name.startswith("?syn:"))
    assert runs and len(ours) == min(20, len(runs))
    assert sorted(f for f, _ in ours) == sorted(r.start + FIRST for r in runs[:20])
    assert "mine" in scene.timeline_markers
    uncertain, missing = frame_trouble(lab, scene.mocap_autolabel.sure)
    assert bpy.ops.mocap_autolabel.jump_to_worst() == {"FINISHED"}
    worst = runs[0]
    peak = scene.frame_current - FIRST
    assert worst.start <= peak < worst.stop
    assert (uncertain + missing)[peak] == (uncertain + missing)[worst.start:worst.stop].max() > 0
    # A re-solve replaces the take's markers instead of adding more.
    assert bpy.ops.mocap_autolabel.resolve() == {"FINISHED"}
    assert len([m for m in scene.timeline_markers if m.name.startswith("?syn:")]) == len(ours)


def test_the_markers_of_a_take_no_longer_in_the_scene_go_with_it(empty_scene, bpy_module, take_file, tmp_path):
    import shutil

    bpy = bpy_module
    scene = empty_scene
    scene.timeline_markers.new("mine", frame=5)
    scene.timeline_markers.new("?mine: not a take's", frame=6)  # the user's, though it starts with '?'
    first = _import_and_label(bpy, scene, take_file)
    _import_and_label(bpy, scene, shutil.copy(take_file, tmp_path / "other.c3d"))
    assert any(m.name.startswith("?syn:") for m in scene.timeline_markers)
    scene.collection.children.unlink(first)  # the reviewer deletes the first take
    assert bpy.ops.mocap_autolabel.resolve() == {"FINISHED"}  # an edit of the other one
    names = [m.name for m in scene.timeline_markers]
    assert not any(n.startswith("?syn:") for n in names) and any(n.startswith("?other:") for n in names)
    assert "mine" in names and "?mine: not a take's" in names
    # Markers left by a take deleted before the file was saved go when it is opened again.
    scene.timeline_markers.new("?gone: 3 uncertain, 1 missing", frame=7)
    path = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    names = [m.name for m in bpy.context.scene.timeline_markers]
    assert "?gone: 3 uncertain, 1 missing" not in names and any(n.startswith("?other:") for n in names)
    assert "mine" in names


def test_the_label_panel_has_an_import_button(empty_scene, bpy_module):
    """The Mocap tab's Label panel draws the Import operator first (checked on the panel's source: a
    headless Blender draws no panels)."""
    import inspect

    from mocap_autolabel.ui.panels import MOCAPAL_PT_label

    assert '"mocap_autolabel.import_markers"' in inspect.getsource(MOCAPAL_PT_label.draw)
