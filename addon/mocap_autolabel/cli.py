"""Command line: ``python -m mocap_autolabel COMMAND ...`` or, inside Blender,
``blender -b --python-exit-code 1 -P addon/mocap_autolabel/cli.py -- COMMAND ...``.

Exit codes: 0 success, 1 a file failed, 2 bad usage. Errors are one line naming the file.
This file is the command line itself: the parser, the checks of flags across commands and the
dispatch; each command's work is in its module under ``commands/``. Only the standard library and
``commands/`` (whose modules import core inside their functions) are imported at module level, so
``--help`` loads no numpy; run as a script (no package: ``__package__`` is empty), only the standard
library, and the bottom of the file imports the package from beside it.
"""

from __future__ import annotations

import argparse
import os
import sys

if __package__:  # else run as a script (Blender's -P, or re-run by multiprocessing's workers): see the bottom
    # Each command's function, and the shared names that moved to commands/ (importable from here too).
    from .commands.batch import _batch
    from .commands.common import (  # noqa: F401 (re-exported)
        DEFAULT_MAX_GAP,
        EXIT_FAILED,
        EXIT_OK,
        EXIT_USAGE,
        FILL_METHODS,
        LABEL_METHODS,
        TEMPORAL_MODES,
        _bpy_or_none,
        _fail,
        _write_report,
    )
    from .commands.fill import _fill
    from .commands.import_scene import _import
    from .commands.info import _info
    from .commands.label import _label
    from .commands.layout import _layout
    from .commands.progress import _ProgressBar  # noqa: F401 (re-exported)
    from .commands.solve import _retarget_arguments, _solve
    from .commands.synth import _synth
    from .commands.train import _train


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):
        self.print_usage(sys.stderr)
        raise _UsageError(f"{self.prog}: error: {message}")


class _UsageError(Exception):
    pass


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="mocap_autolabel", description="Automatic labeling of optical hand motion capture.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    info = sub.add_parser("info", help="summarise take files (C3D, TRC, Qualisys TSV)")
    info.add_argument("files", nargs="+", metavar="FILE")
    info.add_argument("--json", action="store_true", help="one JSON object per file")

    imp = sub.add_parser("import", help="import a take into a new .blend (needs Blender or the bpy module)")
    imp.add_argument("file", metavar="FILE")
    imp.add_argument("--blend", required=True, metavar="OUT.blend", help="the .blend file to write")
    imp.add_argument("--scale", type=float, default=1.0, help="factor on positions in metres (default 1)")
    imp.add_argument("--frame-offset", type=int, default=0,
                     help="added to the file's frame numbers; the take must stay on scene frames 0 or later")
    imp.add_argument("--names", default="*", metavar="PATTERN",
                     help="import only points whose name matches (* and ? wildcards)")
    imp.add_argument("--point-cloud", action="store_true",
                     help="the raw markers as one point cloud driven by geometry nodes (no keys: for very "
                          "long takes, about a tenth of the time and memory)")
    imp.add_argument("--summary", metavar="OUT.json", help="also write a JSON summary of the import")

    syn = sub.add_parser("synth", help="generate a synthetic raw take of a procedural hand, with its ground truth")
    syn.add_argument("--layout", default="han19", help="built-in layout name or a layout .toml file (default han19)")
    syn.add_argument("--frames", type=int, default=2000, help="number of frames (default 2000)")
    syn.add_argument("--seed", type=int, default=0, help="random seed; the same seed gives the same bytes")
    syn.add_argument("--rate", type=float, default=120.0, help="frames per second (default 120)")
    syn.add_argument("--side", choices=("left", "right"), help="hand side (default: drawn at random)")
    syn.add_argument("--clean", action="store_true", help="no noise, occlusion, ghosts or merges")
    syn.add_argument("--hands", type=int, choices=(1, 2), default=1,
                     help="2: a left and a right hand that touch, clap, interlace and cross (default 1)")
    syn.add_argument("--prop", type=int, default=0, metavar="N",
                     help="with --hands 2: a rigid prop of N (3-6) markers held in the left hand (default none)")
    syn.add_argument("-o", "--output", required=True, metavar="OUT.c3d",
                     help="the take to write; the truth goes beside it as OUT.truth.npz")
    syn.add_argument("--blend", metavar="OUT.blend",
                     help="also write a .blend with the raw markers and the true hand (armature, skin, markers)")

    lab = sub.add_parser("label", help="label a raw take: per-frame scores, then a temporal decision per tracklet")
    lab.add_argument("file", metavar="FILE", help="the raw take (C3D, TRC or Qualisys TSV)")
    lab.add_argument("-o", "--output", metavar="OUT.c3d",
                     help="labeled C3D: the layout's points by name, then the unassigned samples as *N points")
    lab.add_argument("--method", default=LABEL_METHODS[0], choices=LABEL_METHODS,
                     help="per-frame labeler (default: set, ours)")
    lab.add_argument("--temporal", default=TEMPORAL_MODES[0], choices=TEMPORAL_MODES,
                     help="vote: one label per tracklet segment (default); viterbi: N-best + Kalman (Alexanderson); "
                          "none: per-frame labels")
    lab.add_argument("--vote", default="likelihood", choices=("likelihood", "power"),
                     help="segment score for --temporal vote: summed log-probability (default) or Ghorbani's "
                          "|T|^q (sum c^p)^(1/p)")
    lab.add_argument("--p", type=float, default=2.0, help="p of the power vote (default 2)")
    lab.add_argument("--q", type=float, default=-0.5, help="q of the power vote (default -0.5)")
    lab.add_argument("--n-best", type=int, default=5, help="hypotheses per frame for --temporal viterbi (default 5)")
    lab.add_argument("--layout", default="han19", help="built-in layout name or a layout .toml (default han19)")
    lab.add_argument("--model", metavar="MODEL.onnx", help="ONNX model for set/perm/cnn (default: the shipped one)")
    lab.add_argument("--fit", metavar="LABELED",
                     help="a labeled take of the subject: gmm fits on it; nearest starts from its first frame "
                          "(defaults: gmm fits on the layout's synthetic range of motion, nearest starts from "
                          "set's labels of the first frame)")
    lab.add_argument("--validate", action="store_true",
                     help="IK validation: fit the hand to the labels, vote again with the fit's evidence, and "
                          "downgrade segments the hand cannot explain (vote only; slower: it calibrates a hand)")
    lab.add_argument("--calibration", metavar="CALIB.json",
                     help="the performer's hand calibration for --validate (default: calibrated on this take)")
    _hand_arguments(lab)
    lab.add_argument("--report", metavar="REPORT.json", help="write counts, confidence, uncertain segments, timings")
    lab.add_argument("--html", metavar="PAGE.html",
                     help="also the take's report as one HTML page: labels x frames coloured by confidence (fills "
                          "shown), the hand's RMS over time with --solve-hand, uncertain segments (needs matplotlib)")
    lab.add_argument("--labels", metavar="OUT.npz", help="write labels and confidences per frame and point slot")
    lab.add_argument("--blend", metavar="OUT.blend",
                     help="write a review scene: the raw take, labeled and unlabeled markers keyed by confidence "
                          "(open it in Blender with the add-on: Mocap tab > Review); needs Blender or bpy")
    lab.add_argument("--solve-hand", action="store_true",
                     help="also fit the hand to the labels and put the keyed rig in --blend (one rig per hand, "
                          "Hand_L and Hand_R, for a take of two hands)")
    _fill_arguments(lab, "--fill")
    _progress_flags(lab)

    fil = sub.add_parser("fill", help="fill the gaps of a labeled take: from the solved hand, rigid partners, PCA or "
                                      "splines; fills are marked as computed in the C3D")
    fil.add_argument("file", metavar="LABELED", help="a labeled take (C3D, TRC or TSV) with the layout's marker names")
    fil.add_argument("-o", "--output", required=True, metavar="FILLED.c3d", help="the filled take")
    fil.add_argument("--layout", help=FOUND_LAYOUT)
    _fill_arguments(fil)
    fil.add_argument("--calibration", metavar="CALIB.json",
                     help="the performer's calibration for the hand fill, one per hand as left.json,right.json "
                          "(default: calibrated on this take)")
    fil.add_argument("--hand-names", metavar="CONVENTION",
                     help="how two hands' labels carry their side (default: any known convention; see label)")
    fil.add_argument("--report", metavar="REPORT.json",
                     help="every gap: marker, frames, method, expected error, or why it was left open")
    _progress_flags(fil)

    sol = sub.add_parser("solve", help="fit the rigged hand to a labeled take: calibration, IK, Blender/FBX/BVH")
    sol.add_argument("file", metavar="FILE", help="a labeled take (C3D, TRC or TSV) with the layout's marker names")
    sol.add_argument("--layout", help=FOUND_LAYOUT)
    sol.add_argument("--blend", metavar="OUT.blend", help="write the markers and the animated hand rig")
    sol.add_argument("--fbx", metavar="OUT.fbx", help="export the animated rig as FBX (Blender's exporter)")
    sol.add_argument("--bvh", metavar="OUT.bvh", help="export the animated rig as BVH (Blender's exporter)")
    sol.add_argument("--calibration", metavar="CALIB.json",
                     help="reuse this performer calibration (default: calibrate on this take)")
    sol.add_argument("--save-calibration", metavar="CALIB.json", help="write the calibration used, for other takes")
    sol.add_argument("--calibrate-seconds", type=float, metavar="S",
                     help="calibrate on the first S seconds only (e.g. a range-of-motion start)")
    sol.add_argument("--reference-frames", metavar="A:B",
                     help="frames A to B-1 (0-based) hold a flat hand: calibration then also measures the "
                          "marker offsets that a joint-angle bias would otherwise absorb")
    sol.add_argument("--contacts", metavar="FRAME:FINGER,...",
                     help="pinch frames (0-based) for the calibration, e.g. 120:index,300:middle: there the "
                          "thumb's pad touches that finger's pad")
    sol.add_argument("--side", choices=("left", "right"), help="hand side of a one-hand take (default: detected)")
    sol.add_argument("--hand-names", metavar="CONVENTION",
                     help="how the labels carry their hand's side (default: any of prefix L_ThumbTip, suffix "
                          "ThumbTip_L, vicon LeftHand:ThumbTip); see label --hand-names")
    sol.add_argument("--smooth-hz", type=float, default=10.0, help="low-pass cut-off of the pose track (0: off)")
    sol.add_argument("--report", metavar="REPORT.json", help="per-frame and overall marker RMS (mm), calibration")
    _retarget_arguments(sol)
    _progress_flags(sol)

    bat = sub.add_parser("batch", help="label (and solve) folders of takes headless, with progress and reports")
    bat.add_argument("inputs", nargs="+", metavar="INPUT", help="take files, folders (searched recursively) or globs")
    bat.add_argument("-o", "--output", required=True, metavar="OUT_DIR", help="folder for outputs and the summary")
    bat.add_argument("--config", metavar="SETTINGS.toml",
                     help="settings file (the keys of the flags below, e.g. layout = \"han19\"); flags override it")
    bat.add_argument("--layout", help="built-in layout name or a layout .toml (default han19)")
    bat.add_argument("--model", metavar="MODEL.onnx", help="ONNX model (default: the shipped one)")
    bat.add_argument("--method", choices=LABEL_METHODS,
                     help="per-frame labeler (default set; gmm fits on the layout's synthetic range of motion)")
    bat.add_argument("--temporal", choices=TEMPORAL_MODES, help="temporal mode (default vote)")
    bat.add_argument("--validate", action="store_true", default=None, help="IK validation of the labels")
    bat.add_argument("--confident", type=float, help="confidence counted as confident in reports (default 0.95)")
    bat.add_argument("--solve-hand", action="store_true", default=None, help="also fit the hand; RMS in the report")
    bat.add_argument("--calibration", metavar="CALIB.json", help="performer calibration for every take")
    bat.add_argument("--fit", metavar="LABELED",
                     help="a labeled take of the performer for every take: gmm fits on it, nearest starts from its "
                          "first frame (as label --fit)")
    bat.add_argument("--blend", action="store_true", default=None,
                     help="also write a .blend per take (solves the hand)")
    bat.add_argument("--fbx", action="store_true", default=None, help="also write an FBX per take (solves the hand)")
    bat.add_argument("--bvh", action="store_true", default=None, help="also write a BVH per take (solves the hand)")
    _retarget_arguments(bat, batch=True)
    bat.add_argument("--fill", action="store_true", default=None,
                     help="also fill the labeled markers' gaps in the labeled C3D (marked as computed)")
    bat.add_argument("--fill-method", choices=FILL_METHODS, help="fill method (default auto)")
    bat.add_argument("--max-gap", type=float, metavar="SECONDS", help="longest gap filled (default 1 s)")
    bat.add_argument("--jobs", type=int, help="takes processed side by side (default 1)")
    bat.add_argument("--scheduler", metavar="tcp://HOST:8786|local:N",
                     help="each take a task on a Dask cluster: a farm's scheduler, or N local workers "
                          "(pip install \"mocap_autolabel[farm]\")")
    bat.add_argument("--hands", choices=("auto", "1", "2"), help="hands per take: found (auto, default) or forced")
    bat.add_argument("--hand-names", metavar="CONVENTION", help="how two hands' labels carry their side "
                                                                "(see label --hand-names; default prefix, L_ThumbTip)")
    bat.add_argument("--html", action="store_true", default=None,
                     help="also an HTML page per take with pictures, and index.html linking them (needs matplotlib)")
    bat.add_argument("--force", action="store_true", default=None, help="redo takes whose outputs are complete")
    shown = bat.add_mutually_exclusive_group()
    shown.add_argument("--quiet", action="store_true", help="no progress, only the summary and errors")
    shown.add_argument("--json-progress", action="store_true", help="progress as JSON lines on stderr (farm logs)")

    lay = sub.add_parser("layout", help="fit a layout TOML from a labeled take: each marker's bone and place on the "
                                        "template hand (no TOML to write, no training)")
    lay.add_argument("--from", dest="source", required=True, metavar="LABELED",
                     help="a labeled take (C3D, TRC, TSV) of one hand, or of two with --side")
    lay.add_argument("-o", "--output", required=True, metavar="OUT.toml", help="the layout file")
    lay.add_argument("--name", help="the layout's name (default: the file's name)")
    lay.add_argument("--side", choices=("left", "right"),
                     help="fit this hand's points (named by --hand-names; their side token is taken off)")
    lay.add_argument("--hand-names", metavar="CONVENTION", help="how names carry the side (default prefix: L_ThumbTip)")
    lay.add_argument("--points", metavar="PATTERN,...",
                     help="only the points whose names match (* and ? wildcards), e.g. to leave body markers out")
    lay.add_argument("--frames", type=int, default=40, help="frames the hand is calibrated on (default 40)")
    _progress_flags(lay)

    trn = sub.add_parser("train", help="train a 'set' model for a marker layout from synthetic data (needs PyTorch)")
    trn.add_argument("--layout", required=True, help="built-in layout name or a layout .toml")
    trn.add_argument("-o", "--output", required=True, metavar="OUT.onnx", help="the model; its card goes beside it")
    trn.add_argument("--steps", type=int, help="training steps (default: the shipped recipe's)")
    trn.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    trn.add_argument("--device", default="cpu", choices=["cpu", "cuda"],
                     help="where the training steps run: cpu (default) or cuda, a CUDA GPU (minutes instead of "
                          "about half an hour on 2 cores)")
    return parser


FOUND_LAYOUT = "built-in layout name or a layout .toml (default: the built-in layout the file's names carry)"


def _fill_arguments(parser: argparse.ArgumentParser, flag: str | None = None) -> None:
    """--method/--max-gap of ``fill``; with ``flag`` (``label --fill``) the switch and --fill-method."""
    if flag:
        parser.add_argument(flag, action="store_true", help="also fill the labeled markers' gaps in -o's C3D "
                                                            "(marked as computed; see the fill command)")
    parser.add_argument("--fill-method" if flag else "--method", dest="fill_method", default=FILL_METHODS[0],
                        choices=FILL_METHODS,
                        help="auto (default: per gap the method with the lowest expected error of hand, pose "
                             "and spline), spline, rigid, hand (the calibrated, solved hand), pca, or pose (read "
                             "off the other markers in the hand's frame)")
    parser.add_argument("--max-gap", type=float, default=DEFAULT_MAX_GAP, metavar="SECONDS",
                        help="gaps longer than this are left open (default 1 s)")


def _hand_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--hands", default="auto", choices=("auto", "1", "2"),
                        help="hands of the layout in the take: found (auto, default) or forced")
    parser.add_argument("--sides", metavar="SIDE,SIDE",
                        help="override the detected sides, one per hand in the order of their mean x "
                             "(e.g. left,right)")
    parser.add_argument("--hand-names", metavar="CONVENTION",
                        help="how labels carry their hand's side: prefix (L_ThumbTip, the default for two "
                             "hands), suffix (ThumbTip_L), vicon (LeftHand:ThumbTip) or a pattern with {name} and "
                             "{S}, {side} or {Side}; one hand keeps plain names unless given")


def _progress_flags(parser: argparse.ArgumentParser) -> None:
    shown = parser.add_mutually_exclusive_group()
    shown.add_argument("--progress", action="store_true",
                       help="show the progress bar (stderr) also when it is not a terminal")
    shown.add_argument("--quiet", action="store_true", help="no progress bar")


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the process exit code."""
    try:
        args = build_parser().parse_args(argv)
    except _UsageError as exc:
        print(exc, file=sys.stderr)
        return EXIT_USAGE
    except SystemExit as exc:  # --help
        return int(exc.code or 0)
    if args.command in ("import", "synth") and args.blend and not args.blend.lower().endswith(".blend"):
        print(f"mocap_autolabel import: error: --blend must name a .blend file, got {args.blend!r}", file=sys.stderr)
        return EXIT_USAGE
    if args.command == "synth" and not args.output.lower().endswith(".c3d"):
        print(f"mocap_autolabel synth: error: -o must name a .c3d file, got {args.output!r}", file=sys.stderr)
        return EXIT_USAGE
    if args.command == "synth" and not (1 <= args.frames <= 10_000_000 and 1 <= args.rate <= 10_000):
        print("mocap_autolabel synth: error: --frames must be 1 to 10,000,000 and --rate 1 to 10,000", file=sys.stderr)
        return EXIT_USAGE
    if args.command == "layout" and not args.output.lower().endswith(".toml"):
        print(f"mocap_autolabel layout: error: -o must name a .toml file, got {args.output!r}", file=sys.stderr)
        return EXIT_USAGE
    if args.command == "train" and not args.output.lower().endswith(".onnx"):
        print(f"mocap_autolabel train: error: -o must name a .onnx file, got {args.output!r}", file=sys.stderr)
        return EXIT_USAGE
    if args.command in ("fill", "label", "batch") and getattr(args, "max_gap", None) is not None \
            and not args.max_gap > 0:
        print(f"mocap_autolabel {args.command}: error: --max-gap must be positive seconds", file=sys.stderr)
        return EXIT_USAGE
    if args.command == "fill" and not args.output.lower().endswith(".c3d"):
        print(f"mocap_autolabel fill: error: -o must name a .c3d file, got {args.output!r}", file=sys.stderr)
        return EXIT_USAGE
    command = {"info": _info, "import": _import, "synth": _synth, "label": _label, "solve": _solve,
               "fill": _fill, "batch": _batch, "train": _train, "layout": _layout}[args.command]
    return command(args)


def _argv_after_double_dash(argv: list[str]) -> list[str]:
    return argv[argv.index("--") + 1:] if "--" in argv else []


if __name__ == "__main__":
    # Run as a script (blender -b -P .../cli.py -- ARGS): import the package from beside us.
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    from mocap_autolabel.cli import main as _main

    sys.exit(_main(_argv_after_double_dash(sys.argv)))
