#!/usr/bin/env python3
"""Build the Mocap Autolabel Blender extension: one validated zip per platform.

    python tools/build_extension.py [--output-dir dist] [--platform linux-x64 ...]

1. Reads ``wheels`` from ``addon/mocap_autolabel/blender_manifest.toml`` and fetches each missing
   wheel of the chosen platforms into ``addon/mocap_autolabel/wheels/`` (git-ignored) with
   ``pip download --no-deps --only-binary=:all:`` for the exact version and tags in its file name.
2. Copies the extension to a temporary folder (only the wheels of the chosen platforms, the manifest's
   ``platforms`` cut down to them) and runs Blender's own extension tool, which ships inside the
   ``bpy`` module: ``blender_ext.py build --split-platforms``, then ``blender_ext.py validate`` on
   each zip. No Blender binary is needed and ``bpy`` is never imported.

Exit status: 0 on success, 1 on any error, 3 when a wheel could not be downloaded (e.g. no network).
"""

from __future__ import annotations

import argparse
import importlib.util
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from collections.abc import Callable, Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SOURCE_DIR = ROOT / "addon" / "mocap_autolabel"
MANIFEST_NAME = "blender_manifest.toml"
# Blender 4.2 through 5.0 bundle CPython 3.11: wheels are fetched for that interpreter.
BLENDER_PYTHON = "3.11"
# Wheels of packages that Blender itself ships; bundling them would shadow Blender's copy.
NEVER_BUNDLE = frozenset({"numpy"})
EXIT_DOWNLOAD_FAILED = 3


class BuildError(Exception):
    """A build step failed; the message is one line for the user."""

    exit_code = 1


class DownloadError(BuildError):
    """A wheel could not be downloaded (no network, or no such file on the index)."""

    exit_code = EXIT_DOWNLOAD_FAILED


def find_blender_ext() -> Path:
    """Locate ``blender_ext.py`` inside the installed ``bpy`` package without importing ``bpy``."""
    spec = importlib.util.find_spec("bpy")
    if spec is None:
        raise BuildError("the bpy module is not installed (pip install bpy): it provides Blender's extension tool")
    if spec.submodule_search_locations:
        package_dirs = [Path(p) for p in spec.submodule_search_locations]
    else:
        package_dirs = [Path(spec.origin or "").parent]
    for package_dir in package_dirs:
        found = sorted(package_dir.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
        if found:
            return found[-1]
    raise BuildError(f"blender_ext.py not found in the bpy package at {package_dirs[0]}")


def load_platform_mapper(blender_ext: Path) -> Callable[[str], list[str]]:
    """Return Blender's own wheel-platform-tag to Blender-platform mapping (e.g. ``win_amd64`` -> ``windows-x64``).

    Using the tool's function guarantees that wheels are assigned to platforms exactly as
    ``--split-platforms`` assigns them. The module has no side effects on import.
    """
    spec = importlib.util.spec_from_file_location("_blender_ext", blender_ext)
    if spec is None or spec.loader is None:
        raise BuildError(f"cannot load {blender_ext}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.blender_platforms_from_wheel_platform


def wheel_tags(filename: str) -> tuple[str, str, str, str, str]:
    """Split a wheel file name into (distribution, version, python tag, abi tag, platform tag)."""
    parts = filename.removesuffix(".whl").split("-")
    if not filename.endswith(".whl") or len(parts) not in (5, 6):
        raise BuildError(f"not a wheel file name: {filename}")
    return parts[0], parts[1], parts[-3], parts[-2], parts[-1]


def wheel_platforms(filename: str, mapper: Callable[[str], list[str]]) -> set[str] | None:
    """Blender platforms a wheel is for, or None for a pure-Python (``any``) wheel."""
    platform_tag = wheel_tags(filename)[4]
    if platform_tag == "any":
        return None
    return {platform for tag in platform_tag.split(".") for platform in mapper(tag)}


def pip_download(filename: str, wheels_dir: Path) -> None:
    """Fetch exactly ``filename`` from the package index into ``wheels_dir``."""
    name, version, _python_tag, abi_tag, platform_tag = wheel_tags(filename)
    command = [
        sys.executable,
        "-m",
        "pip",
        "download",
        "--quiet",
        "--disable-pip-version-check",
        "--no-deps",
        "--only-binary=:all:",
        "--implementation",
        "cp",
        "--python-version",
        BLENDER_PYTHON,
        f"{name}=={version}",
    ]
    command += [arg for abi in abi_tag.split(".") if abi != "none" for arg in ("--abi", abi)]
    command += [arg for tag in platform_tag.split(".") if tag != "any" for arg in ("--platform", tag)]
    with tempfile.TemporaryDirectory() as tmp:
        result = subprocess.run([*command, "--dest", tmp], capture_output=True, text=True)
        fetched = Path(tmp) / filename
        if result.returncode != 0 or not fetched.is_file():
            got = ", ".join(p.name for p in Path(tmp).iterdir()) or "nothing"
            errors = [line for line in result.stderr.splitlines() if line.startswith("ERROR")]
            reason = errors[-1] if errors else f"got {got}"
            raise DownloadError(f"pip download of {filename} failed: {reason}")
        wheels_dir.mkdir(parents=True, exist_ok=True)
        shutil.move(fetched, wheels_dir / filename)


def run_tool(blender_ext: Path, *args: str) -> None:
    """Run ``blender_ext.py`` with ``args``; raise with its last output line if it fails."""
    result = subprocess.run([sys.executable, str(blender_ext), *args], capture_output=True, text=True)
    if result.returncode != 0:
        lines = (result.stdout + result.stderr).strip().splitlines() or ["(no output)"]
        raise BuildError(f"blender_ext.py {args[0]} failed: {lines[-1]}")


def stage_source(source: Path, dest: Path, wheels: Sequence[str], platforms: Sequence[str]) -> None:
    """Copy the extension to ``dest`` with only ``wheels`` and the manifest's platforms set to ``platforms``."""
    shutil.copytree(source, dest, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "wheels"))
    for wheel in wheels:
        (dest / wheel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(source / wheel, dest / wheel)
    manifest = dest / MANIFEST_NAME
    platforms_toml = "platforms = [" + ", ".join(f'"{p}"' for p in platforms) + "]"
    text, count = re.subn(r"(?m)^platforms\s*=\s*\[[^\]]*\]", platforms_toml, manifest.read_text(encoding="utf-8"))
    if count != 1 or tomllib.loads(text).get("platforms") != list(platforms):
        raise BuildError(f"cannot restrict 'platforms' in {MANIFEST_NAME} to {', '.join(platforms)}")
    manifest.write_text(text, encoding="utf-8")


def build(output_dir: Path, platforms: Sequence[str] | None = None) -> list[Path]:
    """Fetch the wheels and build and validate one zip per platform; return the zips."""
    blender_ext = find_blender_ext()
    mapper = load_platform_mapper(blender_ext)
    manifest = tomllib.loads((SOURCE_DIR / MANIFEST_NAME).read_text(encoding="utf-8"))
    declared: list[str] = manifest.get("platforms", [])
    chosen = [p for p in declared if not platforms or p in platforms]
    unknown = sorted(set(platforms or ()) - set(declared))
    if unknown or not chosen:
        raise BuildError(f"platform(s) {', '.join(unknown) or '-'} not in the manifest's {declared}")

    wheels = []
    for wheel in manifest.get("wheels", []):
        name = Path(wheel).name
        if wheel_tags(name)[0].lower() in NEVER_BUNDLE:
            raise BuildError(f"{name}: Blender already ships this package, do not bundle it")
        targets = wheel_platforms(name, mapper)
        if targets is None or targets & set(chosen):
            wheels.append(wheel)
            if not (SOURCE_DIR / wheel).is_file():
                print(f"downloading {name}", flush=True)
                pip_download(name, (SOURCE_DIR / wheel).parent)

    output_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        stage = Path(tmp) / SOURCE_DIR.name
        stage_source(SOURCE_DIR, stage, wheels, chosen)
        run_tool(blender_ext, "build", "--source-dir", str(stage), "--output-dir", str(output_dir), "--split-platforms")
    zips = [output_dir / f"{manifest['id']}-{manifest['version']}-{p.replace('-', '_')}.zip" for p in chosen]
    for zip_path in zips:
        if not zip_path.is_file():
            raise BuildError(f"blender_ext.py did not produce {zip_path}")
        run_tool(blender_ext, "validate", str(zip_path))
    return zips


def main(argv: Sequence[str] | None = None) -> int:
    """Command line entry point; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--output-dir", type=Path, default=ROOT / "dist", help="where the zips go (default: dist)")
    parser.add_argument(
        "--platform",
        action="append",
        dest="platforms",
        metavar="PLATFORM",
        help="build only this platform, e.g. linux-x64 (repeatable; default: all in the manifest)",
    )
    args = parser.parse_args(argv)
    start = time.perf_counter()
    try:
        zips = build(args.output_dir.resolve(), args.platforms)
    except BuildError as error:
        print(f"error: {error}", file=sys.stderr)
        return error.exit_code
    for zip_path in zips:
        print(f"{zip_path}  {zip_path.stat().st_size / 1e6:.1f} MB")
    print(f"built and validated {len(zips)} zip(s) in {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
