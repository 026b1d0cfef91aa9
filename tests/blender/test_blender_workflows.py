"""Whole workflows in one bpy session, as a new user goes (issue 33): two takes in one scene (the demo
take and the real glove recording), a bad file imported in between, switching with the Take field,
save, reopen, export each; and the Layout picked from the file's point names."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import data_path
from helpers import review_state as _state
from helpers import save_and_reopen
from helpers import select as _select
from mocap_autolabel.core.labeling import EMPTY, NULL

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "samples" / "demo_take.c3d"


def _glove():
    return data_path("hands", "qualisys_glove13", "recording_part1.tsv")


def _import(bpy, path, folder):
    path = shutil.copy(path, folder / Path(path).name)
    assert bpy.ops.mocap_autolabel.import_markers(filepath=str(path)) == {"FINISHED"}
    return bpy.context.scene.mocap_autolabel.take


def _correct(bpy, coll, name, op):
    """``op`` (Lock, Unlabel...) on the longest segment of the labeled marker ``name``, two frames in."""
    from mocap_autolabel.blender.review import first_frame

    lab = _state(coll).labeling
    label = lab.names.index(name)
    seg = np.flatnonzero(lab.label == label)
    seg = int(seg[np.argmax(lab.stop[seg] - lab.start[seg])])
    bpy.context.scene.frame_set(int(lab.start[seg]) + 2 + first_frame(coll))
    _select(bpy, next(o for o in coll["mocap_labeled"].objects if o["mocap_label"] == label))
    assert op() == {"FINISHED"}


def _holds(coll):
    """Every correction of the take is honoured by its labeling."""
    st = _state(coll)
    per = st.labeling.per_sample()
    for c in st.review.constraints:
        got = per[c.start:c.stop, c.slot]
        assert (got[got != EMPTY] == c.label).all(), c
    return st


def test_the_layout_is_picked_from_the_files_point_names(empty_scene, bpy_module, tmp_path, capfd):
    """The glove recording names every glove13 marker: its import sets the panel's Layout to glove13
    and says so; the demo take names none and leaves it. The Layout field follows the Take field, and
    a layout the user chose for a take wins over the pick when the take comes back."""
    bpy = bpy_module
    settings = empty_scene.mocap_autolabel
    demo = _import(bpy, DEMO, tmp_path)
    assert settings.layout == "han19" and "Layout set" not in capfd.readouterr().out
    settings.layout_file = str(tmp_path / "my_layout.toml")  # a layout file in the panel: the pick clears it
    glove = _import(bpy, _glove(), tmp_path)
    out = capfd.readouterr().out
    assert settings.layout == "glove13" and settings.layout_file == ""
    assert "Layout set to glove13: the file names every glove13 marker" in out
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}  # labels with the picked layout
    assert _state(glove).layout == "glove13"
    # Back and forth with the Take field: the Layout shows each take's own (the demo's, the file chosen
    # while it was in the Take field).
    settings.take = demo
    assert settings.layout_file == str(tmp_path / "my_layout.toml")
    settings.take = glove
    assert settings.layout == "glove13" and settings.layout_file == ""
    # The user chooses han19 for the glove take: it stays the glove's choice.
    settings.layout = "han19"
    settings.take = demo
    settings.take = glove
    assert settings.layout == "han19"
    # A second import of the same file is a new take: it gets the pick again.
    again = _import(bpy, _glove(), tmp_path)
    assert again != glove and settings.layout == "glove13"
    # A take that names no layout's markers does not inherit another take's pick: it gets the layout
    # the user chose last (han19, for the glove take above).
    (tmp_path / "b").mkdir()
    demo2 = _import(bpy, DEMO, tmp_path / "b")
    assert settings.layout == "han19"
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"} and _state(demo2).layout == "han19"
    settings.layout = "glove13"  # chosen by the user: the next take that names nothing gets it
    (tmp_path / "c").mkdir()
    _import(bpy, DEMO, tmp_path / "c")
    assert settings.layout == "glove13"


def test_two_takes_in_one_scene_a_bad_file_between_save_reopen_export(empty_scene, bpy_module, tmp_path, capfd):
    from mocap_autolabel.core.take import read_take

    bpy = bpy_module
    scene = empty_scene
    settings = scene.mocap_autolabel
    ops = bpy.ops.mocap_autolabel
    demo = _import(bpy, DEMO, tmp_path)
    assert ops.label() == {"FINISHED"}
    _correct(bpy, demo, "ThumbTip", ops.lock)
    _correct(bpy, demo, "IndexTip", ops.unlabel)

    # A bad file (the demo take cut short) in between: one clear error, nothing changes.
    bad = tmp_path / "bad" / "cut.c3d"
    bad.parent.mkdir()
    bad.write_bytes(DEMO.read_bytes()[:30000])
    before = (len(bpy.data.collections), len(bpy.data.objects), settings.take, bpy.context.active_object,
              scene.frame_start, scene.frame_end, scene.render.fps, scene.render.fps_base)
    capfd.readouterr()
    with pytest.raises(RuntimeError, match=r"cut\.c3d: file is truncated"):
        ops.import_markers(filepath=str(bad))
    assert capfd.readouterr().out.count("Error:") == 1
    assert (len(bpy.data.collections), len(bpy.data.objects), settings.take, bpy.context.active_object,
            scene.frame_start, scene.frame_end, scene.render.fps, scene.render.fps_base) == before

    glove = _import(bpy, _glove(), tmp_path)
    assert settings.layout == "glove13"
    assert ops.label() == {"FINISHED"}
    _correct(bpy, glove, "index_tip", ops.lock)
    _correct(bpy, glove, "thumb_tip", ops.unlabel)
    demo_review, glove_review = _state(demo).review, _state(glove).review
    assert len(demo_review.constraints) == len(glove_review.constraints) == 2

    # Switch with the Take field: the Review panel's lists and tools follow it.
    settings.take = demo
    assert settings.layout == "han19" and len(settings.corrections) == 2
    assert settings.corrections[0].text.startswith("ThumbTip on *")
    # Worst Frames is the Review panel's: it goes to the panel's take even with a glove marker selected.
    _select(bpy, glove["mocap_labeled"].objects["index_tip"])
    capfd.readouterr()
    assert ops.jump_to_worst() == {"FINISHED"}
    out = capfd.readouterr().out
    from mocap_autolabel.blender.review import take_collection

    assert take_collection(bpy.context.active_object) == demo
    assert " 1 labels" not in out and " 1 uncertain samples" not in out
    # Label again from the panel: the demo, with han19, its corrections kept; the glove untouched.
    assert ops.label() == {"FINISHED"}
    assert _holds(demo).review == demo_review and _state(demo).layout == "han19"
    assert _state(glove).review == glove_review and _state(glove).layout == "glove13"
    settings.take = glove
    assert settings.layout == "glove13" and [c.kind for c in settings.corrections] == ["label", "ghost"]
    assert ops.resolve() == {"FINISHED"}
    _holds(glove)

    # Save, reopen: both reviews and both takes' corrections; continue on each.
    save_and_reopen(bpy, tmp_path / "two_takes.blend")
    scene = bpy.context.scene
    settings = scene.mocap_autolabel
    demo, glove = bpy.data.collections["demo_take"], bpy.data.collections["recording_part1"]
    assert settings.take in (demo, glove)
    assert _state(demo).review == demo_review and _state(glove).review == glove_review
    for coll, layout in ((demo, "han19"), (glove, "glove13")):
        settings.take = coll
        assert settings.layout == layout
        assert ops.resolve() == {"FINISHED"}
        _holds(coll)

    # Export each: names, frames, every sample once.
    for coll in (demo, glove):
        settings.take = coll
        out = tmp_path / f"{coll.name}_labeled.c3d"
        assert ops.export_labeled(filepath=str(out)) == {"FINISHED"}
        src, back = read_take(coll["mocap_source"]), read_take(out)
        lab = _state(coll).labeling
        m = len(lab.names)
        assert back.names[:m] == lab.names
        assert sorted(back.names[m:]) == sorted(o.name for o in coll["mocap_unlabeled"].objects)
        assert (back.first_frame, back.n_frames) == (src.first_frame, src.n_frames)
        assert int(back.valid.sum()) == int(src.valid.sum())
        per = lab.per_sample()
        f, s = np.nonzero(per >= 0)
        np.testing.assert_allclose(back.positions[f, per[f, s]], src.positions[f, s], atol=1e-4)
        assert (per[~src.valid] == EMPTY).all() and ((per == NULL) | (per >= 0))[src.valid].all()
    # The glove's named body and pillow points keep their names in the export.
    assert {"right_elbow", "pillow_top"} <= set(read_take(tmp_path / "recording_part1_labeled.c3d").names)


def test_the_layout_is_picked_from_the_takes_shape_when_nobody_chose_one(empty_scene, bpy_module, tmp_path):
    """An unnamed glove13 take, labeled with the default layout (nobody chose one): the take's shape
    picks glove13, and Label says so; a layout the user chose is kept (and only warned about)."""
    from helpers import import_written
    from mocap_autolabel.core.layout import load_layout
    from mocap_autolabel.core.synth.generate import synthesize

    bpy = bpy_module
    coll = import_written(bpy, synthesize(load_layout("glove13"), 600, seed=21).take, tmp_path, "gloveless")
    settings = bpy.context.scene.mocap_autolabel
    assert settings.layout == "han19" and not settings.get("user_layout")
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    assert _state(coll).layout == "glove13" and settings.layout == "glove13"
    assert _state(coll).labeling.summary()["confident_share"] > 0.5
    # Chosen by the user, han19 stays: refused or warned, never replaced.
    settings.layout = "han19"
    try:
        result = bpy.ops.mocap_autolabel.label()
    except RuntimeError as exc:  # no han19 hand in a glove13 take
        assert "no hand found" in str(exc)
        assert _state(coll).layout == "glove13"
    else:
        assert result == {"FINISHED"} and _state(coll).layout == "han19"


def test_a_takes_layout_file_comes_back_with_the_take(empty_scene, bpy_module, tmp_path):
    """The Layout File a take was labeled with was cleared when the Take field came back to the take
    (even set to the same take), and Label then used han19 (a new user's trial)."""
    bpy = bpy_module
    settings = empty_scene.mocap_autolabel
    studio = tmp_path / "studio.toml"
    studio.write_text((ROOT / "addon" / "mocap_autolabel" / "core" / "layouts" / "han19.toml").read_text()
                      .replace('name = "han19"', 'name = "studio"'))
    demo = _import(bpy, DEMO, tmp_path)
    settings.layout_file = str(studio)
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"} and _state(demo).layout == str(studio)
    settings.take = demo  # the same take again
    assert settings.layout_file == str(studio)
    (tmp_path / "b").mkdir()
    other = _import(bpy, DEMO, tmp_path / "b")
    settings.layout_file = ""
    settings.layout = "glove13"  # the other take's own choice
    settings.take = demo
    assert settings.layout_file == str(studio)
    settings.take = other
    assert settings.layout_file == "" and settings.layout == "glove13"
    name = demo.name
    settings.take = other
    save_and_reopen(bpy, tmp_path / "scene.blend")
    settings = bpy.context.scene.mocap_autolabel
    settings.take = bpy.data.collections[name]
    assert settings.layout_file == str(studio)
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    assert _state(settings.take).layout == str(studio)
