"""Make Layout in the bpy module: a layout fitted from a take labeled elsewhere, put in the Layout File
field, then used to label a raw take of the same marker set; a raw take gets one clear error."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import import_take
from mocap_autolabel.core.formats.c3d import write_c3d
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.synth.generate import synthesize
from mocap_autolabel.core.take import Take


@pytest.mark.slow
def test_make_layout_from_a_labeled_take_then_label_a_raw_one_with_it(empty_scene, bpy_module, tmp_path):
    bpy = bpy_module
    layout = load_layout("tips10_hand3")
    synth = synthesize(layout, 400, seed=11)
    labeled = Take(positions=synth.markers + np.random.default_rng(0).normal(0, 4e-4, synth.markers.shape),
                   names=list(layout.names), rate=120.0, source="studio_rom.c3d")
    (tmp_path / "src").mkdir()
    write_c3d(labeled, tmp_path / "src" / "studio_rom.c3d")
    import_take(bpy, tmp_path / "src" / "studio_rom.c3d", tmp_path)
    out = tmp_path / "studio.toml"
    assert bpy.ops.mocap_autolabel.make_layout(filepath=str(out)) == {"FINISHED"}
    settings = bpy.context.scene.mocap_autolabel
    assert settings.layout_file == str(out)
    fitted = load_layout(out)
    assert fitted.names == layout.names and fitted.name == "studio"
    assert sum(m.bone == "palm" for m in fitted.markers) >= 2  # the hand cluster lands on the hand
    # the next raw take of the set labels with it
    raw = tmp_path / "raw" / "take.c3d"
    raw.parent.mkdir()
    write_c3d(synthesize(layout, 400, seed=11).take, raw)  # the same performer, unlabeled
    import_take(bpy, raw, tmp_path)
    assert settings.layout_file == str(out)
    assert bpy.ops.mocap_autolabel.label() == {"FINISHED"}
    labels = {o.name.rsplit(":", 1)[-1] for o in settings.take["mocap_labeled"].objects}
    assert len(labels & set(layout.names)) >= len(layout) // 2


def test_make_layout_on_a_raw_take_says_what_is_missing_and_writes_nothing(empty_scene, bpy_module, tmp_path):
    bpy = bpy_module
    (tmp_path / "src").mkdir()
    write_c3d(synthesize(load_layout("tips5"), 200, seed=3).take, tmp_path / "src" / "raw.c3d")
    import_take(bpy, tmp_path / "src" / "raw.c3d", tmp_path)
    out = tmp_path / "nothing.toml"
    try:
        result = bpy.ops.mocap_autolabel.make_layout(filepath=str(out))
    except RuntimeError as exc:  # the operator's error report, raised by bpy.ops from a script
        assert "no labeled point" in str(exc) and "label the take first" in str(exc)
    else:
        assert result == {"CANCELLED"}
    assert not out.exists() and not any(tmp_path.glob(".nothing*"))
