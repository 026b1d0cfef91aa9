"""The command line's Blender outputs: import into a .blend (empties or a point cloud), label --blend."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from conftest import ROOT
from helpers import small_take
from mocap_autolabel.cli import main
from mocap_autolabel.core.formats.c3d import write_c3d


def test_import_writes_blend_and_summary(tmp_path, bpy_module):
    src = tmp_path / "take.c3d"
    write_c3d(small_take(frames=120, points=5), src)
    blend, summary = tmp_path / "out" / "take.blend", tmp_path / "out" / "summary.json"
    assert main(["import", str(src), "--blend", str(blend), "--summary", str(summary)]) == 0
    info = json.loads(summary.read_text())
    assert info["empties"] == 5 and info["frames"] == 120 and info["scene_fps"] == pytest.approx(100.0)
    assert sorted(os.listdir(blend.parent)) == ["summary.json", "take.blend"]  # no partial files left
    bpy_module.ops.wm.open_mainfile(filepath=str(blend))
    assert len(bpy_module.data.collections["take"].objects) == 5
    bpy_module.ops.wm.read_homefile(use_empty=True)


def test_import_as_point_cloud_writes_one_object(tmp_path, bpy_module, capsys):
    src = tmp_path / "take.c3d"
    write_c3d(small_take(frames=120, points=5), src)
    blend, summary = tmp_path / "take.blend", tmp_path / "summary.json"
    assert main(["import", str(src), "--blend", str(blend), "--point-cloud", "--names", "*", "--summary",
                 str(summary)]) == 0
    info = json.loads(summary.read_text())
    assert info["empties"] == 0 and info["point_cloud"]["markers"] == 5
    assert "5 point-cloud markers x 120 frames" in capsys.readouterr().out
    bpy_module.ops.wm.open_mainfile(filepath=str(blend))
    objs = bpy_module.data.collections["take"].objects
    assert len(objs) == 1 and objs[0].type == "MESH" and len(objs[0].data.vertices) == 120 * 5
    bpy_module.ops.wm.read_homefile(use_empty=True)


def test_import_failure_writes_nothing(tmp_path, capsys):
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(b"\x02\x50" + b"\x00" * 600)
    blend = tmp_path / "never.blend"
    assert main(["import", str(bad), "--blend", str(blend)]) == 1
    assert not blend.exists() and capsys.readouterr().err.startswith(f"error: {bad}: ")


def test_import_refuses_a_scale_of_zero_and_a_file_of_no_frames_in_one_line(tmp_path, bpy_module, capsys):
    """Both raised a traceback out of the import command."""
    src, blend = tmp_path / "take.c3d", tmp_path / "never.blend"
    write_c3d(small_take(frames=20, points=3), src)
    assert main(["import", str(src), "--blend", str(blend), "--scale", "0"]) == 1
    assert capsys.readouterr().err.strip() == "error: Scale must be above 0 (got 0); nothing imported"
    empty = tmp_path / "empty.tsv"
    empty.write_text("NO_OF_FRAMES\t0\nNO_OF_MARKERS\t1\nFREQUENCY\t100\nMARKER_NAMES\ta\n")
    assert main(["import", str(empty), "--blend", str(blend)]) == 1
    assert capsys.readouterr().err.strip() == f"error: {empty}: the file holds no frames (no data rows or " \
                                              f"samples); nothing imported"
    assert sorted(os.listdir(tmp_path)) == ["empty.tsv", "take.c3d"]


def test_blenders_own_save_lines_stay_out_of_the_output(tmp_path):
    """bpy's 'Info: Saved copy as ".x.1a2b.partial.blend"' named a temporary file the user never sees."""
    pytest.importorskip("bpy", reason="the bpy module (pip install bpy==5.0.1) is not installed")
    env = dict(os.environ, PYTHONPATH=str(ROOT / "addon"))
    blend = tmp_path / "review.blend"
    done = subprocess.run([sys.executable, "-m", "mocap_autolabel", "label", str(ROOT / "samples" / "demo_take.c3d"),
                           "--blend", str(blend)], capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr
    assert blend.is_file() and f"  review   {blend}" in done.stdout
    assert "partial" not in done.stdout + done.stderr and "Saved copy" not in done.stdout + done.stderr
