"""``solve``: the rigged hand fitted to a labeled take (calibration, IK), and the Blender, FBX and BVH outputs,
also retargeted onto an animator's own character (``--retarget``), with engine bone names (``--bone-names``)."""

from __future__ import annotations

import argparse
import sys

from .common import EXIT_FAILED, EXIT_OK, EXIT_USAGE, _bpy_or_none, _fail, _outputs_refused, _write_report
from .progress import _ProgressBar

#: ``--bone-names``: the presets of ``blender.export.BONE_NAME_PRESETS`` (spelled out: ``--help`` loads no bpy;
#: a test keeps them equal).
BONE_NAME_CHOICES = ("ours", "ue5", "unity", "mixamo", "rigify")
#: ``--retarget-wrist``: ``core.retarget.transfer.WRIST_MODES``, the first the default.
WRIST_CHOICES = ("fingers", "rotation", "world")


def split_character(value: str) -> tuple[str, str | None]:
    """``CHARACTER.blend[:ARMATURE]`` -> ``(path, armature or None)``; ValueError where no .blend is named."""
    at = value.lower().rfind(".blend:")
    path, armature = (value[:at + 6], value[at + 7:]) if at >= 0 else (value, None)
    if not path.lower().endswith(".blend"):
        raise ValueError(f"--retarget takes CHARACTER.blend or CHARACTER.blend:ARMATURE, got {value!r}")
    return path, armature or None


def _retarget_arguments(parser: argparse.ArgumentParser, batch: bool = False) -> None:
    """``--retarget``, ``--bone-map``, ``--retarget-wrist``, ``--pinch`` and ``--bone-names`` of ``solve``
    and ``batch`` (batch's default None: the TOML's value, else the default, stands)."""
    parser.add_argument("--retarget", metavar="CHARACTER.blend[:ARMATURE]",
                        help="retarget the solved hand(s) onto this character's armature (the one with hand bones, "
                             "or the one named): "
                             + ("its .blend per take" if batch else "--blend saves the character's scene with them")
                             + ", --fbx and --bvh export its armature (its own bone names)")
    parser.add_argument("--bone-map", metavar="PRESET|MAP.json",
                        help="with --retarget: which bone is which (a preset saved from Blender's Retarget panel, "
                             "or a .json); default: the automatic map (Rigify, Mixamo, UE5, Unity, generic names)")
    parser.add_argument("--retarget-wrist", choices=WRIST_CHOICES, default=None if batch else WRIST_CHOICES[0],
                        help="with --retarget: move the fingers only (default), also turn the hand bone (rotation), "
                             "or also move it to our wrist (world)")
    parser.add_argument("--pinch", action="store_true", default=None if batch else False,
                        help="with --retarget: keep the thumb-to-fingertip contacts of the solved hand")
    parser.add_argument("--bone-names", choices=BONE_NAME_CHOICES, default=None if batch else BONE_NAME_CHOICES[0],
                        help="--fbx/--bvh bone names and the FBX's axes and units for an engine: ours (default; "
                             "Y up, metres), ue5 (Z up, centimetres), unity, mixamo, rigify (Y up, metres); one "
                             "animation stack, no leaf bones")


def _retarget_usage(args) -> str | None:
    """What is wrong with ``solve``'s retarget and export flags together, or None."""
    if args.retarget:
        try:
            split_character(args.retarget)
        except ValueError as exc:
            return str(exc)
        if not (args.blend or args.fbx or args.bvh):
            return "--retarget needs --blend, --fbx or --bvh (what to write)"
    elif args.bone_map or args.pinch or args.retarget_wrist != WRIST_CHOICES[0]:
        return "--bone-map, --retarget-wrist and --pinch are for --retarget CHARACTER.blend"
    if args.bone_names != BONE_NAME_CHOICES[0] and not (args.fbx or args.bvh):
        return "--bone-names is for --fbx and --bvh"
    return None


def _solve(args) -> int:
    from ..core.errors import MocapInputError
    from ..core.hand.calibrate import Calibration
    from ..core.hands import HandNaming, labeled_layout, sided_path, split_hands
    from ..core.layout import load_layout
    from ..core.process import Outputs, process_take
    from ..core.settings import LabelSettings
    from ..core.take import read_take

    outputs = (("--blend", args.blend, ".blend"), ("--fbx", args.fbx, ".fbx"), ("--bvh", args.bvh, ".bvh"))
    for flag, value, ext in outputs:
        if value and not value.lower().endswith(ext):
            print(f"mocap_autolabel solve: error: {flag} must name a {ext} file, got {value!r}", file=sys.stderr)
            return EXIT_USAGE
    problem = _retarget_usage(args)
    if problem:
        print(f"mocap_autolabel solve: error: {problem}", file=sys.stderr)
        return EXIT_USAGE
    reference = None
    if args.reference_frames:
        try:
            a, b = (int(v) for v in args.reference_frames.split(":"))
            if not 0 <= a < b:
                raise ValueError
        except ValueError:
            print(f"mocap_autolabel solve: error: --reference-frames must be A:B with 0 <= A < B, "
                  f"got {args.reference_frames!r}", file=sys.stderr)
            return EXIT_USAGE
        reference = range(a, b)
    contacts = []
    for item in filter(None, (args.contacts or "").split(",")):
        frame, _, finger = item.partition(":")
        if not frame.strip().isdigit() or finger.strip() not in ("index", "middle", "ring", "little"):
            print(f"mocap_autolabel solve: error: --contacts takes FRAME:FINGER items (finger index, middle, ring "
                  f"or little), got {item!r}", file=sys.stderr)
            return EXIT_USAGE
        contacts.append((int(frame), finger.strip()))
    # --save-calibration may rewrite the --calibration it read (the same performer's file, kept up to date).
    refused = _outputs_refused(args.file, [args.blend, args.fbx, args.bvh, args.report, args.save_calibration],
                               [args.file, args.layout])
    if refused is not None:
        return refused
    bpy = None
    if args.blend or args.fbx or args.bvh:
        bpy = _bpy_or_none("solve --blend/--fbx/--bvh")
        if bpy is None:
            return EXIT_FAILED
    bone_map = None
    if args.retarget:  # a bad character or bone map fails in a second, before the solve, not after it
        from ..blender.export import check_character, load_bone_map
        from ..core.quiet import silenced_stdout

        try:
            bone_map = load_bone_map(args.bone_map) if args.bone_map else None
            with silenced_stdout():  # Blender's "Read blend" line
                check_character(*split_character(args.retarget), bone_map)
        except Exception as exc:
            return _fail(args.file, exc)
    bar = _ProgressBar.for_args(args)
    try:
        layout = load_layout(args.layout) if args.layout else None
        calibrations = [Calibration.load(p) for p in args.calibration.split(",")] if args.calibration else []
        bar.stage(f"reading {args.file}")
        take = read_take(args.file)
        if reference is not None and reference.stop > take.n_frames:
            raise MocapInputError(args.file, f"has {take.n_frames} frames; --reference-frames ends at {reference.stop}")
        naming = HandNaming(args.hand_names) if args.hand_names else None
        layout = layout or labeled_layout(take, naming)
        sides = [side for side, _ in split_hands(take, layout, naming)]
        if len(sides) > 1 and args.side:
            raise MocapInputError(args.file, "holds two hands, named by side: --side is for a one-hand take")
        by_side = {("" if len(sides) == 1 and not sides[0] else c.side): c for c in calibrations}
        if len(calibrations) > len(sides) or len(by_side) < len(calibrations):
            raise MocapInputError(args.calibration, f"give one calibration per hand ({len(sides)} in the take)")
        bar.stage("calibrating and solving the hand" if len(by_side) < len(sides) else "solving the hand")
        options = {"calibrate_seconds": args.calibrate_seconds, "reference": reference, "contacts": contacts,
                   "side": args.side, "smooth_hz": args.smooth_hz}
        outputs = Outputs(label=False, solve=True, calibrations=by_side, solve_options=options)
        solved = process_take(take, layout, LabelSettings(naming=args.hand_names), outputs, progress=bar).solves
    except Exception as exc:
        bar.close()
        return _fail(args.file, exc)
    bar.close()
    reports = []
    for side, one in solved:
        report = one.report() | {"file": args.file} | ({"side": side} if side else {})
        reports.append(report)
        cal = one.calibration
        fps = take.n_frames / max(one.seconds["solve"], 1e-9)
        print(f"{args.file}: {cal.side} hand {cal.length * 1000:.1f} x {cal.breadth * 1000:.1f} mm on {layout.name}; "
              f"{report['solved_frames']} of {take.n_frames} frames solved in {one.seconds['solve']:.2f} s "
              f"({fps:,.0f} frames/s); marker RMS {report['marker_rms_mm']:.2f} mm, "
              f"{report['frames_over_gate']} frames over the {report['gate_mm']:g} mm gate")
        if side not in by_side:
            print(f"  calibrated on {len(cal.frames)} frames: RMS {cal.rms_before * 1000:.2f} -> "
                  f"{cal.rms_after * 1000:.2f} mm")
        if args.save_calibration:
            path = sided_path(args.save_calibration, side)
            cal.save(path)
            print(f"  calibration {path}")
    if bpy is not None:
        from ..blender.export import write_retargeted_scene, write_solved_scene
        from ..core.quiet import silenced_stdout

        try:  # the labeled markers beside the calibrated, animated rig(s); then .blend, FBX and BVH
            rigs = solved if solved[0][0] else solved[0][1]
            with silenced_stdout():  # Blender's and the exporters' own lines name the temporary files
                if args.retarget:
                    character, armature = split_character(args.retarget)
                    written, facts = write_retargeted_scene(
                        take, rigs, character, armature=armature, bone_map=bone_map, wrist=args.retarget_wrist,
                        pinch=args.pinch, blend=args.blend, fbx=args.fbx, bvh=args.bvh, bone_names=args.bone_names)
                else:
                    written = write_solved_scene(take, rigs, args.blend, args.fbx, args.bvh,
                                                 bone_names=args.bone_names)
            if args.retarget:
                print(f"  retarget {retarget_line(facts)}")
                for report in reports:
                    report["retarget"] = plain(facts)
            for kind, path in written.items():
                print(f"  {kind:8s} {path}")
        except Exception as exc:
            return _fail(args.file, exc)
    if args.report:
        try:
            _write_report(args.report, reports[0] if len(reports) == 1 else {"file": args.file, "hands": reports})
        except OSError as exc:
            return _fail(args.file, exc)
    return EXIT_OK


def retarget_line(facts: dict) -> str:
    """One line on a retargeting (:func:`..blender.retarget.retarget_character`'s facts)."""
    hands = "; ".join(f"{side} {len(f.get('bones', ()))} bones x {f.get('frames', 0)} frames"
                      for side, f in (facts.get("hands") or {}).items())
    return (f"onto {facts.get('armature')!r} ({facts.get('convention') or 'bone map'}): {hands}; action "
            f"{facts.get('action')!r} on NLA track {facts.get('track')!r}")


def plain(value):
    """``value`` with numpy numbers and arrays as Python's (for JSON)."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if hasattr(value, "tolist"):  # numpy scalars and arrays
        return value.tolist()
    return value
