"""Small builders shared by the tests."""

from __future__ import annotations

import numpy as np
from mocap_autolabel.core.take import Take


def small_take(frames: int = 50, points: int = 4, seed: int = 0, gaps: bool = True) -> Take:
    """A take of points moving smoothly (metres), with a few gaps of each convention already as NaN."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames, dtype=np.float32)[:, None, None] / 100.0
    base = rng.uniform(-0.5, 0.5, (1, points, 3)).astype(np.float32)
    positions = (base + 0.1 * np.sin(2 * np.pi * t + np.arange(points)[None, :, None])).astype(np.float32)
    if gaps:
        positions[5:9, 0] = np.nan
        positions[20:21, 1] = np.nan
        positions[frames - 3:, points - 1] = np.nan
    return Take(positions=positions, names=[f"*{i}" for i in range(points)], rate=100.0, source="small.c3d")


# --- the Blender tests' shared steps (bpy is passed in: these helpers import nothing of Blender) ---

def import_take(bpy, path, tmp_path):
    """Import a copy of ``path`` (a test may delete it) with the add-on's operator; the new take."""
    import shutil
    from pathlib import Path

    path = shutil.copy(path, tmp_path / Path(path).name)
    assert bpy.ops.mocap_autolabel.import_markers(filepath=str(path)) == {"FINISHED"}
    return bpy.context.scene.mocap_autolabel.take


def review_state(coll):
    """The review stored on a take's collection."""
    from mocap_autolabel.blender.review import load_state

    return load_state(coll)


def select(bpy, *objs):
    """Select exactly ``objs``, the first one active (none: nothing selected, no active object)."""
    for o in bpy.context.selected_objects:
        o.select_set(False)
    for o in objs:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objs[0] if objs else None
