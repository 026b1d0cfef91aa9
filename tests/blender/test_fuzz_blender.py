"""The fuzzer's cases through Blender's import operator (tests/fuzzing.py; tests/core/test_fuzz.py reads them).

The operator reports what it cannot import instead of raising out of Blender, and builds nothing then.
"""

from __future__ import annotations

import fuzzing
import pytest

#: tests/core/test_fuzz.py's master seed; the cases here come from the next one.
MASTER_SEED = 35


def _seeds():
    seeds = fuzzing.load_seeds()
    if not seeds:
        pytest.skip(f"real data not available: {fuzzing.DATA}")
    return seeds


def test_the_import_operator_reports_every_mutated_file_it_cannot_import(empty_scene, bpy_module, tmp_path):
    small = [s for s in _seeds() if len(s.data) <= 200_000]
    imported = refused = 0
    for case in fuzzing.cases(small, 100, MASTER_SEED + 1, systematic=False):
        path = tmp_path / f"case{case.index}{case.seed.ext}"
        path.write_bytes(case.data)
        collections = len(bpy_module.data.collections)
        try:
            assert bpy_module.ops.mocap_autolabel.import_markers(filepath=str(path)) == {"FINISHED"}, case.label
            imported += 1
        except RuntimeError as exc:  # the operator's ERROR report, as bpy.ops shows it to a script
            message = str(exc)
            assert path.name in message, (case.label, message)
            assert "unexpected error" not in message and "Traceback" not in message, (case.label, message)
            assert len(bpy_module.data.collections) == collections, case.label  # nothing half-built
            refused += 1
    assert imported > 5 and refused > 5, (imported, refused)
