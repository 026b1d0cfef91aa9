"""The package's import graph (tools/import_graph.py): no circles, no import from a lower layer to a
higher one, no function in core over 120 lines."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _tool():
    """tools/import_graph.py as a module (tools/ is no package)."""
    if "import_graph" not in sys.modules:
        spec = importlib.util.spec_from_file_location("import_graph", ROOT / "tools" / "import_graph.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules["import_graph"] = module  # dataclasses look their module up there
        spec.loader.exec_module(module)
    return sys.modules["import_graph"]


def test_no_import_circles():
    report = _tool().check()
    assert report.modules > 50
    assert report.circles == [], "\n".join(" -> ".join(c["cycle"]) for c in report.circles)


def test_no_upward_imports():
    report = _tool().check()
    assert report.upward == [], "\n".join(f"{u['importer']}:{u['line']} ({u['importer_layer']}) imports "
                                          f"{u['imported']} ({u['imported_layer']})" for u in report.upward)


def test_no_function_in_core_over_120_lines():
    report = _tool().check(with_long_functions=True)
    assert report.long_functions == [], "\n".join(f"{f['file']}:{f['line']} {f['function']} ({f['lines']} lines)"
                                                  for f in report.long_functions)


def test_the_tool_sees_function_level_submodule_and_upward_imports(tmp_path):
    """A small package: a circle closed by a function-level ``from . import b``, core importing the
    orchestrator and a front end, and a long function."""
    tool = _tool()
    pkg = tmp_path / "mocap_autolabel"
    files = {
        "__init__.py": "",
        "cli.py": "",
        "core/__init__.py": "",
        "core/pipeline.py": "",
        "core/a.py": "from .pipeline import run\nfrom . import b\n",
        "core/b.py": "def f():\n    from .sub.c import g\n",
        "core/sub/__init__.py": "",
        "core/sub/c.py": "def g():\n    from ... import cli\n    from ..a import x\n" + "    y = 1\n" * 120,
        "blender/__init__.py": "from ..core import a\n",
    }
    for name, text in files.items():
        (pkg / name).parent.mkdir(parents=True, exist_ok=True)
        (pkg / name).write_text(text)
    report = tool.check(pkg, with_long_functions=True)
    assert [c["modules"] for c in report.circles] == [["core.a", "core.b", "core.sub.c"]]
    assert report.circles[0]["cycle"] == ["core.a", "core.b", "core.sub.c", "core.a"]
    assert [(u["importer"], u["imported"]) for u in report.upward] == [("core.a", "core.pipeline"),
                                                                      ("core.sub.c", "cli")]
    assert [(f["file"], f["function"], f["lines"]) for f in report.long_functions] == [("core/sub/c.py", "g", 123)]
    assert tool.main(["--package", str(pkg)]) == 1

