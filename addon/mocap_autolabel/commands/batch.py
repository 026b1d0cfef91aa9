"""``batch``: folders of takes labeled (and solved) headless, with progress and reports."""

from __future__ import annotations

import importlib.util
import os
import sys

from .common import EXIT_FAILED, EXIT_OK, EXIT_USAGE, FILL_METHODS, _allows_validation, _bpy_or_none, _fail


def _batch(args) -> int:
    from ..batch import BatchSettings, find_takes, format_table, run_batch

    try:
        settings = BatchSettings.from_toml(args.config) if args.config else BatchSettings()
    except (ValueError, TypeError) as exc:
        print(f"mocap_autolabel batch: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    for key in ("layout", "model", "method", "temporal", "validate", "confident", "solve_hand", "calibration",
                "fit", "blend", "fbx", "bvh", "jobs", "scheduler", "html", "force", "hands", "hand_names", "fill",
                "fill_method", "max_gap", "retarget", "bone_map", "retarget_wrist", "pinch", "bone_names"):
        value = getattr(args, key)
        if value is not None:
            setattr(settings, key, value)
    if settings.fit and not os.path.isfile(settings.fit):
        print(f"mocap_autolabel batch: error: --fit {settings.fit}: no such file (a labeled take of the performer)",
              file=sys.stderr)
        return EXIT_USAGE
    if not 1 <= settings.jobs <= 64:
        print("mocap_autolabel batch: error: --jobs must be 1 to 64", file=sys.stderr)
        return EXIT_USAGE
    if settings.fill_method not in FILL_METHODS or not settings.max_gap > 0:
        print(f"mocap_autolabel batch: error: fill_method must be one of {', '.join(FILL_METHODS)} and max_gap "
              f"positive seconds", file=sys.stderr)
        return EXIT_USAGE
    if settings.scheduler:
        from ..farm import MISSING, FarmError, parse_scheduler

        if args.jobs is not None and args.scheduler is not None:
            print("mocap_autolabel batch: error: give --jobs or --scheduler, not both", file=sys.stderr)
            return EXIT_USAGE
        try:
            parse_scheduler(settings.scheduler)
        except FarmError as exc:
            print(f"mocap_autolabel batch: error: {exc}", file=sys.stderr)
            return EXIT_USAGE
        if importlib.util.find_spec("distributed") is None:
            print(f"error: {MISSING}", file=sys.stderr)
            return EXIT_FAILED
    if settings.html and importlib.util.find_spec("matplotlib") is None:
        from ..html_report import MISSING as NO_MATPLOTLIB

        print(f"error: {NO_MATPLOTLIB}", file=sys.stderr)
        return EXIT_FAILED
    problem = _retarget_problem(settings)
    if problem:
        print(f"mocap_autolabel batch: error: {problem}", file=sys.stderr)
        return EXIT_USAGE
    if settings.validate and not _allows_validation(settings.temporal):
        print("mocap_autolabel batch: error: --validate needs --temporal vote", file=sys.stderr)
        return EXIT_USAGE
    if settings.needs_blender():
        bpy = _bpy_or_none("batch --blend/--fbx/--bvh")
        if bpy is None:
            return EXIT_FAILED
        if bpy.app.binary_path and settings.jobs > 1:  # inside Blender: workers would lack bpy
            print("  note     inside Blender, --blend/--fbx/--bvh run with one job", file=sys.stderr)
            settings.jobs = 1
    try:
        from ..core.layout import load_layout

        if settings.layout:
            load_layout(settings.layout)
    except Exception as exc:
        return _fail(settings.layout, exc)
    if settings.retarget:  # a bad character or bone map fails once, before any take
        from ..blender.export import check_character
        from ..core.quiet import silenced_stdout

        try:
            with silenced_stdout():  # Blender's "Read blend" line
                check_character(*settings.character(), settings.bone_map)
        except Exception as exc:
            return _fail(settings.character()[0], exc)
    missing = [i for i in args.inputs if not any(ch in i for ch in "*?[") and not os.path.exists(i)]
    if missing:
        print(f"mocap_autolabel batch: error: no such file or folder: {', '.join(missing)}", file=sys.stderr)
        return EXIT_USAGE
    if not find_takes(args.inputs):
        print(f"mocap_autolabel batch: error: no takes (.c3d, .trc, .tsv) in {' '.join(args.inputs)}", file=sys.stderr)
        return EXIT_USAGE
    progress = "none" if args.quiet else "json" if args.json_progress else "bar"
    from ..farm import FarmError

    try:
        summary = run_batch(args.inputs, args.output, settings, progress)
    except FarmError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except OSError as exc:  # even a take's report or the summary cannot be written (a full disk)
        print(f"error: {args.output}: cannot write ({exc.strerror or exc}); outputs written "
              f"before are whole, a rerun redoes the rest", file=sys.stderr)
        return EXIT_FAILED
    print(format_table(summary))
    print(f"  summary  {os.path.join(args.output, 'summary.csv')}, {os.path.join(args.output, 'summary.json')}")
    return EXIT_FAILED if summary["failed"] else EXIT_OK


def _retarget_problem(settings) -> str | None:
    """What is wrong with the batch's retarget and bone-name settings together, or None."""
    from .solve import BONE_NAME_CHOICES, WRIST_CHOICES, split_character

    if settings.bone_names not in BONE_NAME_CHOICES or settings.retarget_wrist not in WRIST_CHOICES:
        return (f"bone_names must be one of {', '.join(BONE_NAME_CHOICES)} and retarget_wrist one of "
                f"{', '.join(WRIST_CHOICES)}")
    if settings.retarget:
        try:
            split_character(settings.retarget)
        except ValueError as exc:
            return str(exc).replace("--retarget", "retarget")
        if not settings.needs_blender():
            return "retarget needs blend, fbx or bvh (what to write per take)"
    elif settings.bone_map or settings.pinch or settings.retarget_wrist != WRIST_CHOICES[0]:
        return "bone_map, retarget_wrist and pinch are for retarget = \"CHARACTER.blend\""
    if settings.bone_names != BONE_NAME_CHOICES[0] and not (settings.fbx or settings.bvh):
        return "bone_names is for fbx and bvh"
    return None
