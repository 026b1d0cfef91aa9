"""Action names (issue 48): labeling, labeling again, relabeling and solving twice never give an action a
``.001`` name, and leave no action orphaned. The raw empties' actions are ``<take>|<point> (raw)``, the
labeled and unlabeled empties' ``<take>|<name>``: a take whose file numbers its points ``*N`` (as the
unlabeled empties are named) or names them as the layout does (the glove recording) clashes no more."""

from __future__ import annotations

import re

import pytest
from conftest import data_path
from helpers import import_take
from helpers import select as _select
from mocap_autolabel.core.formats.c3d import write_c3d
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.synth.generate import synthesize

NUMBERED = re.compile(r"\.\d{3}$")


def _check(bpy, when: str) -> None:
    numbered = [a.name for a in bpy.data.actions if NUMBERED.search(a.name)]
    orphans = [a.name for a in bpy.data.actions if a.users == 0]
    assert not numbered, (when, numbered)
    assert not orphans, (when, orphans)
    from mocap_autolabel.blender.takes import take_collection

    for obj in bpy.data.objects:  # every take empty's action is named after its take
        action = obj.animation_data.action if obj.animation_data else None
        take = take_collection(obj)
        if action is not None and take is not None:
            assert action.name.startswith(f"{take.name}|"), (when, obj.name, action.name)


@pytest.fixture(scope="module")
def raw(tmp_path_factory):
    folder = tmp_path_factory.mktemp("names")
    path = folder / "s1.c3d"
    write_c3d(synthesize(load_layout("han19"), 300, seed=1).take, path)  # *0 .. *N, ghosts among them
    return path


def test_label_relabel_and_solve_twice_name_no_action_001(empty_scene, bpy_module, raw, tmp_path):
    from mocap_autolabel.blender.scene import raw_action_name

    bpy = bpy_module
    coll = import_take(bpy, raw, tmp_path)
    _check(bpy, "import")
    assert bpy.data.actions.get(raw_action_name(coll.name, "*0")) is not None
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    unlabeled = list(coll["mocap_unlabeled"].objects)
    assert unlabeled, "the synthetic take has ghosts: unlabeled *N empties, named as the raw points were"
    assert all(o.animation_data.action.name == f"{coll.name}|{o.name}" for o in unlabeled)
    assert {o.name for o in unlabeled} <= {o["mocap_point"] for o in coll["mocap_raw"].objects}
    _check(bpy, "label")
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    _check(bpy, "label again")
    labeled = {int(o["mocap_label"]): o for o in coll["mocap_labeled"].all_objects}
    _select(bpy, labeled[0])
    assert bpy.ops.mocap_autolabel.unlabel() == {"FINISHED"}  # its samples become unlabeled *N empties
    _check(bpy, "unlabel")
    assert bpy.ops.mocap_autolabel.resolve() == {"FINISHED"}
    _check(bpy, "re-solve")
    for _ in range(2):
        assert bpy.ops.mocap_autolabel.solve_hand() == {"FINISHED"}
        _check(bpy, "solve")
    assert bpy.data.objects["Hand"].animation_data.action.name == "HandAction"


def test_a_scene_imported_before_the_raw_names_labels_without_001(empty_scene, bpy_module, raw, tmp_path):
    """Raw actions named ``<take>|<point>`` (as imports named them before) take their raw name when a
    labeled or unlabeled empty needs the plain one; an orphan action holding it goes."""
    bpy = bpy_module
    coll = import_take(bpy, raw, tmp_path)
    for obj in coll.objects:
        obj.animation_data.action.name = f"{coll.name}|{obj['mocap_point']}"
    # And an action no one uses holds a labeled empty's name (its empty deleted by hand): it goes.
    orphan = bpy.data.actions.new(f"{coll.name}|IndexTip")
    assert orphan.users == 0
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    _check(bpy, "label")
    assert bpy.data.objects["IndexTip"].animation_data.action.name == f"{coll.name}|IndexTip"
    shown = {o.name for key in ("mocap_labeled", "mocap_unlabeled") for o in coll[key].all_objects}
    moved = [o for o in coll["mocap_raw"].objects if o["mocap_point"] in shown]
    assert moved  # the ghosts' *N: the raw actions that held their names now have their raw names
    for obj in moved:
        assert obj.animation_data.action.name == f"{coll.name}|{obj['mocap_point']} (raw)"


def test_the_glove_recording_labels_without_001(empty_scene, bpy_module, tmp_path):
    """The real glove recording names its points as glove13 does (``back_left`` ...)."""
    bpy = bpy_module
    path = data_path("hands", "qualisys_glove13", "recording_part1.tsv")
    coll = import_take(bpy, path, tmp_path)
    points = {o["mocap_point"] for o in coll.objects}
    assert points & set(load_layout("glove13").names)
    bpy.context.scene.mocap_autolabel.layout = "glove13"
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    labeled = [o for o in coll["mocap_labeled"].all_objects if o.name in points]
    assert labeled and all(o.animation_data.action.name == f"{coll.name}|{o.name}" for o in labeled)
    _check(bpy, "label")
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    _check(bpy, "label again")


def test_raw_suffix_is_reviews(bpy_module):
    """The raw actions end as the raw empties' names do once labeled."""
    from mocap_autolabel.blender import review, scene

    assert scene.RAW_SUFFIX == review.RAW_SUFFIX
