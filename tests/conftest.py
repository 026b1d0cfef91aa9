"""Shared fixtures: the real data folder (tests skip without it), the bpy module, the han19 layout."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "addon"))
# The tests live in tests/core (never import bpy) and tests/blender (use the bpy module); the shared
# modules stay here (helpers.py, fuzzing.py, this conftest), importable by name from either folder.
sys.path.insert(0, str(Path(__file__).resolve().parent))

#: ../shared/data beside the repository; MOCAP_DATA overrides.
DATA = Path(os.environ.get("MOCAP_DATA", ROOT.parent / "shared" / "data"))


def data_path(*parts: str) -> Path:
    """A path under the shared data folder; skips the test when it is absent."""
    path = DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"real data not available: {path}")
    return path


@pytest.fixture(scope="session")
def bpy_module():
    """The bpy module with the add-on enabled; skips when bpy is not installed."""
    bpy = pytest.importorskip("bpy", reason="the bpy module (pip install bpy==5.0.1) is not installed")
    import addon_utils

    addon_utils.enable("mocap_autolabel", default_set=True)
    return bpy


@pytest.fixture
def empty_scene(bpy_module):
    import addon_utils

    bpy_module.ops.wm.read_homefile(use_empty=True)
    if "mocap_autolabel" not in bpy_module.context.preferences.addons:  # factory settings (a CLI run) drop it
        addon_utils.enable("mocap_autolabel", default_set=True)
    return bpy_module.context.scene


@pytest.fixture(scope="session")
def han19():
    """The built-in han19 layout (one hand, 19 markers)."""
    from mocap_autolabel.core.layout import load_layout

    return load_layout("han19")
