"""samples/make_character.py, the demo's stand-in character: it writes a .blend with Rigify's meta-rig."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")


def test_the_demo_character_is_made(tmp_path):
    pytest.importorskip("bpy")
    out = tmp_path / "character.blend"
    done = subprocess.run([sys.executable, os.path.join(ROOT, "samples", "make_character.py"), str(out)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert out.is_file() and "armature 'Character'" in done.stdout
    assert [p.name for p in tmp_path.iterdir()] == ["character.blend"]  # no partial file left
