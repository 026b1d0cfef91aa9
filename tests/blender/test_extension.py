"""End-to-end test of the packaged Blender extension.

Builds this platform's zip with ``tools/build_extension.py`` (once per session; an existing zip in
``dist/`` newer than every source file is reused), validates it, then in a fresh Python process with
the ``bpy`` module installs it as a user extension, enables it and imports a small C3D with the
add-on's operator. The fresh process keeps this process's ``bpy`` state clean, and the bpy module can
install and enable extensions cleanly only once per process.

Inside that process the venv's own ezc3d, c3d and onnxruntime are hidden, so the test proves that
the wheels bundled in the zip install and work with Blender's numpy.

Skipped when the ``bpy`` module is missing, on a platform the manifest does not list, or when the
wheels cannot be downloaded because the package index is unreachable; deselect with ``-k "not extension"``.
"""

from __future__ import annotations

import importlib.util
import json
import os
import platform
import subprocess
import sys
import tomllib
import urllib.request
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SOURCE_DIR = ROOT / "addon" / "mocap_autolabel"
BUILD_SCRIPT = ROOT / "tools" / "build_extension.py"
DIST_DIR = ROOT / "dist"
MANIFEST = tomllib.loads((SOURCE_DIR / "blender_manifest.toml").read_text(encoding="utf-8"))
ADDON_MODULE = f"bl_ext.user_default.{MANIFEST['id']}"
# Blender's platform names for this machine (as in the manifest's `platforms`).
HOST_PLATFORM = "{}-{}".format(
    {"darwin": "macos"}.get(sys.platform, "windows" if sys.platform == "win32" else "linux"),
    {"x86_64": "x64", "amd64": "x64", "aarch64": "arm64"}.get(platform.machine().lower(), platform.machine().lower()),
)

pytestmark = [
    pytest.mark.skipif(importlib.util.find_spec("bpy") is None, reason="the bpy module is not installed"),
    pytest.mark.skipif(
        HOST_PLATFORM not in MANIFEST.get("platforms", []), reason=f"the extension is not built for {HOST_PLATFORM}"
    ),
]

# Runs in a fresh interpreter: argv = zip, c3d path, add-on module. Prints one line "RESULT {json}".
INSTALL_AND_IMPORT = r"""
import importlib.abc, importlib.machinery, json, os, sys, sysconfig

# Hide the venv's copies of the bundled packages: only the extension's wheels may provide them.
VENV_PATHS = {os.path.realpath(sysconfig.get_paths()[k]) for k in ("purelib", "platlib")}
BUNDLED = {"ezc3d", "c3d", "onnxruntime", "scipy"}

class HideVenvCopies(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if path is not None or name not in BUNDLED:
            return None
        paths = [p for p in sys.path if os.path.realpath(p or ".") not in VENV_PATHS]
        spec = importlib.machinery.PathFinder.find_spec(name, paths)
        if spec is None:
            raise ModuleNotFoundError(f"No module named {name!r} outside the venv", name=name)
        return spec

sys.meta_path.insert(0, HideVenvCopies())

import bpy  # noqa: E402  (first: it puts Blender's modules such as addon_utils on sys.path)
import addon_utils

zip_path, c3d_path, module = sys.argv[1:4]
out = {}
out["install"] = sorted(bpy.ops.extensions.package_install_files(
    filepath=zip_path, repo="user_default", enable_on_install=True))
out["enabled"] = module in bpy.context.preferences.addons
out["loaded"] = bool(addon_utils.check(module)[1])

import numpy as np
import ezc3d
import c3d
import onnxruntime

out["numpy"] = np.__version__
out["numpy_file"] = np.__file__
out["bundled_files"] = {m.__name__: m.__file__ for m in (ezc3d, c3d, onnxruntime)}
out["onnxruntime"] = onnxruntime.__version__
value = onnxruntime.OrtValue.ortvalue_from_numpy(np.arange(3, dtype=np.float32))
out["onnxruntime_numpy_roundtrip"] = value.numpy().tolist()

# 3 points x 10 frames at 100 Hz, point B missing in frames 4-5.
points = np.zeros((4, 3, 10))
points[3] = 1.0
for p in range(3):
    points[0, p] = np.linspace(0.0, 90.0, 10) + 100.0 * p
    points[1, p] = 10.0 * p
    points[2, p] = 50.0
points[:3, 1, 4:6] = np.nan
writer = ezc3d.c3d()
writer["parameters"]["POINT"]["RATE"]["value"] = [100.0]
writer["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
writer["parameters"]["POINT"]["LABELS"]["value"] = ["A", "B", "C"]
writer["data"]["points"] = points
writer.write(c3d_path)
out["c3d_read_back_nan"] = int(np.isnan(ezc3d.c3d(c3d_path)["data"]["points"][:3]).any(axis=0).sum())

out["import"] = sorted(bpy.ops.mocap_autolabel.import_markers(filepath=c3d_path))
name = os.path.splitext(os.path.basename(c3d_path))[0]
collection = bpy.data.collections.get(name)
out["collection"] = collection is not None
objects = list(collection.all_objects) if collection else []
out["empties"] = sorted(o.name for o in objects if o.type == "EMPTY")
out["animated"] = sorted(o.name for o in objects
                         if o.animation_data is not None and o.animation_data.action is not None)
out["frame_ranges"] = {o.name: list(o.animation_data.action.frame_range) for o in objects
                       if o.animation_data is not None and o.animation_data.action is not None}
import importlib
layouts = importlib.import_module(module + ".core.layout")  # the TOML files ship inside the zip
out["layouts"] = layouts.builtin_layouts()
out["han19_markers"] = len(layouts.load_layout("han19"))
# Label a synthetic frame batch with the shipped set model through the extension's own copies
# of onnxruntime and scipy (the models ship inside the zip).
labelers = importlib.import_module(module + ".core.labelers")
frames = importlib.import_module(module + ".core.synth.frames")
han19 = layouts.load_layout("han19")
fr = frames.sample_frames(han19, 64, np.random.default_rng(0), frames.FrameConfig(drop=(0, 1), ghosts=(0, 0),
                                                                                   distractor_share=0.0))
labels, conf = labelers.make_labeler("set", han19).label_points(fr.points, fr.mask)
out["set_accuracy"] = float((labels[fr.mask] == fr.labels[fr.mask]).mean())
out["scipy_file"] = sys.modules["scipy"].__file__
print("RESULT " + json.dumps(out), flush=True)
"""


def _pypi_reachable() -> bool:
    """True if the package index answers (used to tell a broken manifest from being offline)."""
    try:
        with urllib.request.urlopen("https://pypi.org/simple/packaging/", timeout=15) as response:
            return response.status == 200
    except OSError:
        return False


def _newest_source_mtime() -> float:
    """Newest modification time under the extension source (caches excluded)."""
    return max(
        p.stat().st_mtime
        for p in SOURCE_DIR.rglob("*")
        if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc"
    )


def _build_extension_module():
    spec = importlib.util.spec_from_file_location("build_extension", BUILD_SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def extension_zip() -> Path:
    """This platform's extension zip, built unless dist/ has one newer than the sources."""
    zip_path = DIST_DIR / f"{MANIFEST['id']}-{MANIFEST['version']}-{HOST_PLATFORM.replace('-', '_')}.zip"
    if zip_path.is_file() and zip_path.stat().st_mtime > _newest_source_mtime():
        return zip_path
    result = subprocess.run(
        [sys.executable, str(BUILD_SCRIPT), "--output-dir", str(DIST_DIR), "--platform", HOST_PLATFORM],
        capture_output=True,
        text=True,
        timeout=1800,
    )
    if result.returncode == _build_extension_module().EXIT_DOWNLOAD_FAILED and not _pypi_reachable():
        pytest.skip(f"PyPI is unreachable, cannot fetch the wheels: {result.stderr.strip()}")
    assert result.returncode == 0, f"build failed:\n{result.stdout}\n{result.stderr}"
    assert zip_path.is_file(), result.stdout
    return zip_path


def test_zip_validates_and_holds_only_this_platform(extension_zip: Path) -> None:
    module = _build_extension_module()
    validate = subprocess.run(
        [sys.executable, str(module.find_blender_ext()), "validate", str(extension_zip)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert validate.returncode == 0, validate.stdout + validate.stderr

    with zipfile.ZipFile(extension_zip) as archive:
        names = archive.namelist()
        manifest = tomllib.loads(archive.read("blender_manifest.toml").decode("utf-8"))
    assert "__init__.py" in names
    assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc") or n.startswith("tests/")]
    wheels = sorted(n.removeprefix("wheels/") for n in names if n.startswith("wheels/"))
    assert manifest["build"]["generated"]["platforms"] == [HOST_PLATFORM]
    assert sorted(Path(w).name for w in manifest["build"]["generated"]["wheels"]) == wheels
    distributions = {w.split("-")[0].lower() for w in wheels}
    assert {"ezc3d", "c3d", "onnxruntime"} <= distributions
    assert "numpy" not in distributions and "scipy" in distributions  # Blender has numpy, not scipy


def test_install_enable_and_import_c3d(extension_zip: Path, tmp_path: Path) -> None:
    user_resources = tmp_path / "blender_user"
    env = {**os.environ, "BLENDER_USER_RESOURCES": str(user_resources)}
    c3d_path = tmp_path / "take.c3d"
    proc = subprocess.run(
        [sys.executable, "-c", INSTALL_AND_IMPORT, str(extension_zip), str(c3d_path), ADDON_MODULE],
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
        cwd=tmp_path,
    )
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, f"subprocess failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}"
    found = json.loads(lines[-1].removeprefix("RESULT "))

    assert found["install"] == ["FINISHED"]
    assert found["enabled"] and found["loaded"], found
    # The bundled wheels were installed under the temporary user resources and are the ones in use,
    # next to Blender's (here: the bpy module's) numpy.
    for name, file in found["bundled_files"].items():
        assert Path(file).resolve().is_relative_to(user_resources.resolve()), (name, file)
    assert not Path(found["numpy_file"]).resolve().is_relative_to(user_resources.resolve())
    assert found["onnxruntime_numpy_roundtrip"] == [0.0, 1.0, 2.0]
    assert found["c3d_read_back_nan"] == 2

    assert found["import"] == ["FINISHED"]
    assert found["collection"], found
    assert found["empties"] == ["A", "B", "C"]
    assert found["animated"] == ["A", "B", "C"]
    assert {"han19", "glove13", "tips3", "tips5", "tips10"} <= set(found["layouts"])
    assert found["han19_markers"] == 19
    assert found["set_accuracy"] > 0.8
    assert Path(found["scipy_file"]).resolve().is_relative_to(user_resources.resolve())
    for name, (start, end) in found["frame_ranges"].items():
        assert end - start >= 9 - 1e-6, (name, start, end)
