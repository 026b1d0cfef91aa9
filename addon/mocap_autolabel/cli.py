"""Command line: ``python -m mocap_autolabel COMMAND ...`` or, inside Blender,
``blender -b --python-exit-code 1 -P addon/mocap_autolabel/cli.py -- COMMAND ...``.

Exit codes: 0 success, 1 a file failed, 2 bad usage. Errors are one line naming the file.
Only the standard library is imported at module level, so this file also runs as a script.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys

EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):
        self.print_usage(sys.stderr)
        raise _UsageError(f"{self.prog}: error: {message}")


class _UsageError(Exception):
    pass


class _ProgressBar:
    """Progress of one long command (``label``, ``solve``) on stderr: stage, share done, seconds.

    Drawn on a terminal, or anywhere when asked (``--progress``), never with ``--quiet``; it
    appears only once the work has run for :attr:`DELAY` seconds, so short takes print nothing
    extra. On a terminal one line is redrawn in place and wiped at the end (stdout keeps only the
    results); elsewhere (a log) a line is written per stage and per tenth of the work.

    Call it as ``bar(message)`` at each stage (``label_take(progress=...)``), ``bar.share(x)``
    with the share done, 0 to 1 (``label_take(done=...)``), or ``bar(message, share)``.
    """

    DELAY = 1.0  # seconds before anything is drawn
    WIDTH = 24

    def __init__(self, shown: bool, stream=None) -> None:
        import time

        self.stream = stream or sys.stderr
        self.shown = shown
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.clock = time.perf_counter
        self.start = self.clock()
        self.message, self.done = "", None
        self.drawn_at = -1.0
        self.logged: tuple[str, int] | None = None
        self.visible = False

    @classmethod
    def for_args(cls, args) -> _ProgressBar:
        return cls(not args.quiet and (args.progress or sys.stderr.isatty()))

    def __call__(self, message: str, share: float | None = None) -> None:
        self.message = message
        if share is not None:
            self.done = share
        self._draw(force=True)

    def stage(self, message: str, share: float | None = None) -> None:
        """A new stage whose share done is ``share`` (None: not known, only the seconds show)."""
        self.done = None
        self(message, share)

    def share(self, share: float) -> None:
        self.done = share
        self._draw()

    def _draw(self, force: bool = False) -> None:
        now = self.clock()
        elapsed = now - self.start
        if not self.shown or elapsed < self.DELAY or (not force and now - self.drawn_at < 0.1):
            return
        self.drawn_at = now
        part = min(max(self.done or 0.0, 0.0), 1.0)
        filled = int(self.WIDTH * part)
        bar = f"[{'#' * filled}{'.' * (self.WIDTH - filled)}] {100 * part:3.0f} %" if self.done is not None else ""
        line = f"{bar}  {self.message}  {elapsed:.1f} s".strip()
        if self.tty:
            self.stream.write("\r" + line[:119].ljust(119))
            self.visible = True
        else:
            key = (self.message, int(10 * part))
            if key == self.logged:
                return
            self.logged = key
            self.stream.write(line + "\n")
        self.stream.flush()

    def close(self) -> None:
        """Wipe the bar's line (a terminal) so that the results start on a clean line."""
        if self.visible:
            self.stream.write("\r" + " " * 119 + "\r")
            self.stream.flush()
            self.visible = False


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
    imp.add_argument("--frame-offset", type=int, default=0, help="added to the file's frame numbers")
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
    lab.add_argument("--method", default="set", choices=("set", "perm", "cnn", "gmm", "nearest"),
                     help="per-frame labeler (default: set, ours)")
    lab.add_argument("--temporal", default="vote", choices=("vote", "viterbi", "none"),
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
    _progress_flags(sol)

    bat = sub.add_parser("batch", help="label (and solve) folders of takes headless, with progress and reports")
    bat.add_argument("inputs", nargs="+", metavar="INPUT", help="take files, folders (searched recursively) or globs")
    bat.add_argument("-o", "--output", required=True, metavar="OUT_DIR", help="folder for outputs and the summary")
    bat.add_argument("--config", metavar="SETTINGS.toml",
                     help="settings file (the keys of the flags below, e.g. layout = \"han19\"); flags override it")
    bat.add_argument("--layout", help="built-in layout name or a layout .toml (default han19)")
    bat.add_argument("--model", metavar="MODEL.onnx", help="ONNX model (default: the shipped one)")
    bat.add_argument("--method", choices=("set", "perm", "cnn", "gmm", "nearest"),
                     help="per-frame labeler (default set; gmm fits on the layout's synthetic range of motion)")
    bat.add_argument("--temporal", choices=("vote", "viterbi", "none"), help="temporal mode (default vote)")
    bat.add_argument("--validate", action="store_true", default=None, help="IK validation of the labels")
    bat.add_argument("--confident", type=float, help="confidence counted as confident in reports (default 0.95)")
    bat.add_argument("--solve-hand", action="store_true", default=None, help="also fit the hand; RMS in the report")
    bat.add_argument("--calibration", metavar="CALIB.json", help="performer calibration for every take")
    bat.add_argument("--blend", action="store_true", default=None,
                     help="also write a .blend per take (solves the hand)")
    bat.add_argument("--fbx", action="store_true", default=None, help="also write an FBX per take (solves the hand)")
    bat.add_argument("--bvh", action="store_true", default=None, help="also write a BVH per take (solves the hand)")
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

    trn = sub.add_parser("train", help="train a 'set' model for a marker layout from synthetic data (needs PyTorch)")
    trn.add_argument("--layout", required=True, help="built-in layout name or a layout .toml")
    trn.add_argument("-o", "--output", required=True, metavar="OUT.onnx", help="the model; its card goes beside it")
    trn.add_argument("--steps", type=int, help="training steps (default: the shipped recipe's)")
    trn.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    return parser


FOUND_LAYOUT = "built-in layout name or a layout .toml (default: the built-in layout the file's names carry)"
#: Seconds: the default --max-gap (core.fill.MAX_GAP).
DEFAULT_MAX_GAP = 1.0
#: The fill methods (core.fill.METHODS; written out here so that the parser loads no numpy).
FILL_METHODS = ("auto", "spline", "rigid", "hand", "pca", "pose")


def _fill_arguments(parser: argparse.ArgumentParser, flag: str | None = None) -> None:
    """--method/--max-gap of ``fill``; with ``flag`` (``label --fill``) the switch and --fill-method."""
    if flag:
        parser.add_argument(flag, action="store_true", help="also fill the labeled markers' gaps in -o's C3D "
                                                            "(marked as computed; see the fill command)")
    parser.add_argument("--fill-method" if flag else "--method", dest="fill_method", default="auto",
                        choices=FILL_METHODS,
                        help="auto (default: per gap the method with the lowest expected error of hand, pose "
                             "and spline), spline, rigid, hand (the calibrated, solved hand), pca, or pose (read "
                             "off the other markers in the hand's frame)")
    parser.add_argument("--max-gap", type=float, default=DEFAULT_MAX_GAP, metavar="SECONDS",
                        help="gaps longer than this are left open (default 1 s)")


def _fill_line(result) -> str:
    """One line on a fill: gaps filled by method, and those left open."""
    report = result.report()
    methods = ", ".join(f"{n} {k}" for k, n in sorted(report["methods"].items()))
    return (f"{report['filled']} of {report['gaps']} gaps filled ({methods or 'none'}; "
            f"{report['filled_samples']} samples), {report['open']} left open")


def _print_open_gaps(result) -> None:
    """One line per reason gaps were left open, with how many."""
    reasons: dict[str, int] = {}
    for gap in result.gaps:
        if not gap.filled:
            key = gap.reason.split(" (")[0]
            reasons[key] = reasons.get(key, 0) + 1
    for reason, n in sorted(reasons.items()):
        print(f"  open     {n} {'gap' if n == 1 else 'gaps'} {reason}")


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


def _hand_options(args) -> dict:
    """The settings' hand fields from --hands / --sides / --hand-names (ValueError on a bad value)."""
    from .core.hands import SIDES, HandNaming

    sides = None
    if args.sides:
        sides = [v.strip().lower() for v in args.sides.split(",")]
        if any(v not in SIDES for v in sides):
            raise ValueError(f"--sides takes left/right per hand, got {args.sides!r}")
    if args.hand_names:
        HandNaming(args.hand_names)  # a bad pattern: its one-line error
    return {"hand_count": args.hands, "sides": sides, "naming": args.hand_names or None}


def _label_settings(args, layout):
    """The :class:`.core.settings.LabelSettings` of ``label``'s flags."""
    from .core.hand.calibrate import Calibration
    from .core.settings import LabelSettings

    hand = None
    if args.calibration:
        hand = Calibration.load(args.calibration)
        hand.check(layout, args.calibration)
    return LabelSettings(method=args.method, temporal=args.temporal, model=args.model, vote_score=args.vote,
                         power_p=args.p, power_q=args.q, n_best=args.n_best, validate=args.validate,
                         validate_hand=hand, **_hand_options(args))


def _hands_line(labeling, first_frame: int = 0, confident: float = 0.95) -> str | None:
    """One line per take on the hands found and their sides (frames numbered from ``first_frame``),
    or None for a plain one-hand take."""
    from .core.hands import traded_text

    facts = labeling.info.get("hands", {})
    count = facts.get("count", 1)
    if count < 2 and "sides" not in facts:
        if facts.get("warning"):
            return f"1 hand\n  warning  {facts['warning']}"
        return "one hand of two forced was found" if facts.get("forced") == 2 else None
    parts = []
    for h, side in enumerate(facts.get("sides", [])):
        m = len(labeling.names) // max(count, 1)
        part = labeling.label_range(h * m, (h + 1) * m) if count == 2 else labeling
        hand = part.summary(confident)
        parts.append(f"{side} {hand['labeled_segments']} segments, {100 * hand['confident_share']:.1f} % "
                     f"confident")
    forced = " (two forced, one found)" if facts.get("forced") == 2 else ""
    line = (f"{count} hand{'s' if count > 1 else ''}{forced}: " + "; ".join(parts)
            + f" (sides {100 * facts.get('confidence', 0):.0f} % sure)")
    if facts.get("swaps"):  # where the hands touched, the tracker had them the wrong way round
        line += "; " + traded_text(facts["swaps"], first_frame)
    if facts.get("warning"):
        line += f"\n  warning  {facts['warning']}"
    return line


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
               "fill": _fill, "batch": _batch, "train": _train}[args.command]
    return command(args)


def _fail(path: str, exc: BaseException) -> int:
    from .core.errors import MocapInputError

    if isinstance(exc, MocapInputError):
        print(f"error: {exc}", file=sys.stderr)
    elif isinstance(exc, OSError) and exc.strerror:  # a file that cannot be read or written: say which
        print(f"error: {exc.filename or path}: {exc.strerror}", file=sys.stderr)
    else:
        print(f"error: {path}: unexpected {type(exc).__name__}: {exc}", file=sys.stderr)
    return EXIT_FAILED


def _info(args) -> int:
    from .core.take import read_take

    status = EXIT_OK
    for path in args.files:
        try:
            take = read_take(path)
        except Exception as exc:
            status = _fail(path, exc)
            continue
        summary = take.summary()
        if args.json:
            print(json.dumps(summary))
            continue
        names = ("all labeled" if not summary["unlabeled_points"] else
                 "unlabeled (*N)" if not summary["labeled_points"] else
                 f"{summary['labeled_points']} labeled, {summary['unlabeled_points']} unlabeled (*N)")
        print(f"{path}\n"
              f"  vendor   {summary['vendor']}\n"
              f"  points   {summary['points']} ({names})\n"
              f"  frames   {summary['frames']} from {summary['first_frame']} at {summary['rate']:g} Hz "
              f"({summary['duration_s']:g} s)\n"
              f"  units    {summary['units']}\n"
              f"  missing  {summary['missing_percent']:.2f} %")
        if summary["filled_samples"]:
            print(f"  filled   {summary['filled_samples']} samples marked as computed (gap fills)")
        hands = _named_hands(take)
        if hands:
            print(f"  hands    {hands}")
        for warning in summary["warnings"]:
            print(f"  warning  {warning}")
    return status


def _named_hands(take) -> str | None:
    """The hands a labeled take's names hold, per built-in layout (``left and right han19 hands``),
    or None."""
    from .core.hands import hands_in_names
    from .core.layout import builtin_layouts, load_layout

    found = {}
    for name in builtin_layouts():
        layout = load_layout(name)
        sides = [s for s in hands_in_names(take.names, layout) if s]
        if sides:
            found[name] = (set(layout.names), sides)
    # A layout whose markers another found layout holds too (tips5 in han19) says nothing more.
    kept = [n for n, (names, _) in found.items() if not any(names < other for other, _ in found.values())]
    return ", ".join(f"{' and '.join(found[n][1])} {n} hand{'s' if len(found[n][1]) > 1 else ''}"
                     for n in kept) or None


def _bpy_or_none(what: str):
    """The bpy module, or None after telling the user how to get it."""
    try:
        import bpy
    except ImportError:
        print(f"error: {what} needs Blender: install the bpy module (pip install bpy==5.0.1) "
              "or run blender -b --python-exit-code 1 -P addon/mocap_autolabel/cli.py -- ...", file=sys.stderr)
        return None
    return bpy


def _import(args) -> int:
    bpy = _bpy_or_none("the import command")
    if bpy is None:
        return EXIT_FAILED
    from .blender.export import save_blend
    from .blender.scene import ImportOptions, build_take
    from .core.atomic import atomic_output
    from .core.quiet import silenced_stdout
    from .core.take import read_take

    try:
        take = read_take(args.file)
    except Exception as exc:
        return _fail(args.file, exc)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    options = ImportOptions(scale=args.scale, frame_offset=args.frame_offset, name_filter=args.names,
                            as_point_cloud=args.point_cloud)
    collection = build_take(take, scene, options)
    with silenced_stdout():
        save_blend(args.blend)
    from .blender.pointcloud import CLOUD, is_cloud

    cloud = next((o for o in collection.objects if is_cloud(o)), None)
    summary = take.summary() | {
        "blend": os.path.abspath(args.blend),
        "collection": collection.name,
        "empties": len(collection.objects) if cloud is None else 0,
        "point_cloud": None if cloud is None else {"object": cloud.name, "markers": int(cloud[CLOUD])},
        "scene_frames": [scene.frame_start, scene.frame_end],
        "scene_fps": scene.render.fps / scene.render.fps_base,
    }
    if args.summary:
        with atomic_output(args.summary) as tmp, open(tmp, "w") as fh:
            json.dump(summary, fh, indent=2)
    shown = summary["empties"] if cloud is None else f"{summary['point_cloud']['markers']} point-cloud"
    print(f"{args.file}: {shown} markers x {take.n_frames} frames -> {args.blend}")
    for warning in take.warnings:
        print(f"  warning  {warning}")
    return EXIT_OK


def _label(args) -> int:
    import numpy as np

    from .core.atomic import atomic_output
    from .core.labelers import labeler_method
    from .core.labeling import layout_markers, unlabeled_point_names
    from .core.layout import load_layout
    from .core.process import Outputs, process_take, time_limit_warning
    from .core.quiet import silenced_stdout
    from .core.synth.generate import load_truth, truth_path
    from .core.take import read_take

    if args.output and not args.output.lower().endswith(".c3d"):
        print(f"mocap_autolabel label: error: -o must name a .c3d file, got {args.output!r}", file=sys.stderr)
        return EXIT_USAGE
    if not (1 <= args.n_best <= 100 and args.p > 0):
        print("mocap_autolabel label: error: --n-best must be 1 to 100 and --p positive", file=sys.stderr)
        return EXIT_USAGE
    if args.validate and args.temporal != "vote":
        print("mocap_autolabel label: error: --validate needs --temporal vote", file=sys.stderr)
        return EXIT_USAGE
    if args.blend and not args.blend.lower().endswith(".blend") or args.solve_hand and not args.blend:
        print("mocap_autolabel label: error: --blend must name a .blend file, and --solve-hand needs --blend",
              file=sys.stderr)
        return EXIT_USAGE
    if args.fill and not args.output:
        print("mocap_autolabel label: error: --fill needs -o OUT.c3d (the filled, labeled take)", file=sys.stderr)
        return EXIT_USAGE
    if not args.fill and (args.fill_method != "auto" or args.max_gap != DEFAULT_MAX_GAP):
        print("mocap_autolabel label: error: --fill-method and --max-gap are for --fill (add it to fill the gaps)",
              file=sys.stderr)
        return EXIT_USAGE
    if args.html:
        from .html_report import MISSING as NO_MATPLOTLIB

        if not args.html.lower().endswith((".html", ".htm")):
            print(f"mocap_autolabel label: error: --html must name a .html file, got {args.html!r}", file=sys.stderr)
            return EXIT_USAGE
        if importlib.util.find_spec("matplotlib") is None:
            print(f"error: {NO_MATPLOTLIB}", file=sys.stderr)
            return EXIT_FAILED
    if args.blend and _bpy_or_none("label --blend") is None:
        return EXIT_USAGE
    bar = _ProgressBar.for_args(args)
    try:
        layout = load_layout(args.layout)
        bar(f"reading {args.file}")
        take = read_take(args.file)
        labeled = layout_markers(read_take(args.fit), layout) if args.fit else None
        method = labeler_method(args.method)
        outputs = Outputs(solve=args.solve_hand, fill=args.fill_method if args.fill else None,
                          max_gap=args.max_gap)
        result = process_take(take, layout, _label_settings(args, layout), outputs,
                              fit=labeled if labeled is not None and method.fits_performer else None,
                              start=labeled[0] if labeled is not None and method.starts_from_frame else None,
                              progress=bar)
        labeling, doubt = result.labeling, result.doubt
        missed = [f"{side} hand: {check}" for side, check in result.checks if not check.found]
        if args.output:
            from .core.formats.c3d import write_c3d

            bar(f"writing {args.output}")
            write_c3d(result.output_take, args.output)
        filled, solved = result.filled, result.rig() if args.solve_hand else None
        if args.blend:
            from .blender.export import write_review_scene

            bar(f"writing {args.blend}")
            with silenced_stdout():  # Blender's "Saved copy as .partial.blend": we say what we wrote
                write_review_scene(take, args.layout, labeling, args.blend, args.method, args.temporal, solved)
    except Exception as exc:
        bar.close()
        return _fail(args.file, exc)
    bar.close()
    # Frames as the file (and Blender, on import) numbers them; points as the labeled C3D names them.
    summary = labeling.summary(first_frame=take.first_frame, points=unlabeled_point_names(take.names, layout.names))
    seconds = labeling.info["seconds"]["total"]
    print(f"{args.file}: {args.method} + {args.temporal} on {layout.name}, {take.n_frames} frames in {seconds:.2f} s "
          f"({take.n_frames / max(seconds, 1e-9):,.0f} frames/s); {summary['labeled_segments']} segments labeled, "
          f"{summary['null_segments']} null; {100 * summary['confident_share']:.1f} % of labeled samples confident, "
          f"{len(summary['uncertain_segments'])} uncertain segments")
    report = {"file": args.file, "info": labeling.info, "summary": summary}
    hands = _hands_line(labeling, take.first_frame)
    if hands:
        print(f"  hands    {hands}")
    for prop in labeling.info.get("props", []):
        print(f"  prop     a rigid prop ({prop['trajectories']} trajectories, frames {prop['frames'][0]}-"
              f"{prop['frames'][1] - 1}) took hand labels: kept out of the hands, its points left unlabeled")
    for line in missed:
        print(f"  warning  {line}")
    if labeler_method(args.method).fits_performer and not args.fit:
        print(f"  note     gmm fitted on the {layout.name} synthetic range of motion: give --fit LABELED, a labeled "
              f"take of the performer, for a fit to their hand")
    if labeling.info.get("never_confident"):
        print(f"  note     {args.method} + {args.temporal} never rates a segment confident on {layout.name}: on "
              f"synthetic validation takes none of its segments were right 99.9 % of the time, so all are left "
              f"for review (set is the method whose confident segments can be skipped)")
    if doubt:
        print(f"  warning  {doubt} (--layout {doubt.better})")
    hurried = time_limit_warning(labeling)
    if hurried:
        print(f"  warning  {hurried}")
    tpath = truth_path(args.file)
    if os.path.isfile(tpath):
        from .core.metrics import score_labeling

        truth = load_truth(tpath)["labels"]
        score = score_labeling(labeling.per_sample(), truth, take.valid, len(labeling.names))
        report["truth"] = score.as_dict()
        print(f"  truth    {tpath}: {100 * score.accuracy:.2f} % correct, {100 * score.frame_accuracy:.2f} % of frames "
              f"all correct ({score.erroneous} erroneous, {score.false_marker} false marker, "
              f"{score.false_occlusion} false occlusion)")
    if filled is not None:
        report["fill"] = filled.report()
        print(f"  filled   {_fill_line(filled)}")
        _print_open_gaps(filled)
    if args.output:
        print(f"  labeled  {args.output}")
    if args.blend:
        if isinstance(solved, list):
            hand = " and the solved hands (marker RMS " + ", ".join(
                f"{side} {one.fit.overall_rms() * 1000:.2f} mm" for side, one in solved) + ")"
        else:
            hand = f" and the solved hand (marker RMS {solved.fit.overall_rms() * 1000:.2f} mm)" if solved else ""
        print(f"  review   {args.blend}: labeled markers coloured by confidence{hand}")
    try:
        if args.report:
            _write_report(args.report, report)
        if args.html:
            _label_page(args, report, labeling, take.first_frame, filled, solved)
            print(f"  page     {args.html}")
        if args.labels:
            with atomic_output(args.labels) as tmp, open(tmp, "wb") as fh:
                np.savez_compressed(fh, labels=labeling.per_sample(), confidence=labeling.per_sample_confidence(),
                                    names=np.array(labeling.names))
            print(f"  labels   {args.labels}")
    except OSError as exc:
        return _fail(args.file, exc)
    if not (args.output or args.blend or args.report or args.labels):
        print("  output   none written: give -o OUT.c3d for the labeled take (or --report, --labels, --blend)")
    return EXIT_OK


def _label_page(args, report: dict, labeling, first_frame: int, filled, solved) -> None:
    """``label --html``: the take's report as one HTML page (as batch writes per take), atomically."""
    from .core.atomic import atomic_output
    from .core.overview import label_classes, label_fills
    from .html_report import take_page

    fills = None if filled is None else label_fills(labeling.names, filled.take)
    rigs = solved if isinstance(solved, list) else ([("", solved)] if solved is not None else [])
    rms = [one.report()["per_frame_rms_mm"] for _, one in rigs]
    here = os.path.dirname(os.path.abspath(args.html))
    outputs = {k: os.path.relpath(os.path.abspath(v), here).replace(os.sep, "/")
               for k, v in (("labeled", args.output), ("report", args.report), ("blend", args.blend)) if v}
    page_report = report | {"name": os.path.splitext(os.path.basename(args.file))[0], "layout": labeling.info["layout"],
                            "frames": labeling.n_frames, "hands": labeling.info.get("hands", {}).get("count"),
                            "outputs": outputs,
                            "hand": {"marker_rms_mm": max(one.fit.overall_rms() for _, one in rigs) * 1000} if rigs
                            else None}
    page = take_page(page_report, label_classes(labeling, 0.95, fills), labeling.names, first_frame,
                     rms_mm=rms or None, rms_labels=[f"{side} hand" if side else "hand" for side, _ in rigs])
    with atomic_output(args.html) as tmp, open(tmp, "w", encoding="utf-8") as f:
        f.write(page)


def _solve_progress(bar: _ProgressBar) -> dict:
    """``solve_take``'s progress argument where it has one (stage and share done, 0 to 1)."""
    import inspect

    from .core.process import solve_take

    return {"progress": bar} if "progress" in inspect.signature(solve_take).parameters else {}


def _solve(args) -> int:
    from .core.errors import MocapInputError
    from .core.hand.calibrate import Calibration
    from .core.hands import HandNaming, labeled_layout, sided_path, split_hands
    from .core.layout import load_layout
    from .core.process import solve_hands
    from .core.take import read_take

    outputs = (("--blend", args.blend, ".blend"), ("--fbx", args.fbx, ".fbx"), ("--bvh", args.bvh, ".bvh"))
    for flag, value, ext in outputs:
        if value and not value.lower().endswith(ext):
            print(f"mocap_autolabel solve: error: {flag} must name a {ext} file, got {value!r}", file=sys.stderr)
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
    bpy = None
    if args.blend or args.fbx or args.bvh:
        bpy = _bpy_or_none("solve --blend/--fbx/--bvh")
        if bpy is None:
            return EXIT_FAILED
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
        solved = solve_hands(take, layout, naming, by_side, calibrate_seconds=args.calibrate_seconds,
                             reference=reference, contacts=contacts, side=args.side, smooth_hz=args.smooth_hz,
                             **_solve_progress(bar))
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
        from .blender.export import write_solved_scene
        from .core.quiet import silenced_stdout

        try:  # the labeled markers beside the calibrated, animated rig(s); then .blend, FBX and BVH
            rigs = solved if solved[0][0] else solved[0][1]
            with silenced_stdout():  # Blender's and the exporters' own lines name the temporary files
                written = write_solved_scene(take, rigs, args.blend, args.fbx, args.bvh)
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


def _fill(args) -> int:
    from .core.errors import MocapInputError
    from .core.fill import fill_gaps, fill_method
    from .core.formats.c3d import write_c3d
    from .core.hand.calibrate import Calibration
    from .core.hands import HandNaming, labeled_layout, split_hands
    from .core.layout import load_layout
    from .core.take import read_take

    bar = _ProgressBar.for_args(args)
    try:
        layout = load_layout(args.layout) if args.layout else None
        bar.stage(f"reading {args.file}")
        take = read_take(args.file)
        naming = HandNaming(args.hand_names) if args.hand_names else None
        layout = layout or labeled_layout(take, naming)
        sides = [side for side, _ in split_hands(take, layout, naming)]
        calibrations = {}
        for path in filter(None, (args.calibration or "").split(",")):
            cal = Calibration.load(path)
            cal.check(layout, path)
            calibrations["" if sides == [""] else cal.side] = cal
        if len(calibrations) > len(sides):
            raise MocapInputError(args.calibration, f"give one calibration per hand ({len(sides)} in the take)")
        if fill_method(args.fill_method).uses_hand:
            bar.stage("calibrating and solving the hand" if len(calibrations) < len(sides) else "solving the hand")
        else:
            bar.stage("filling gaps")
        # With auto or hand, fill_gaps solves each hand first (its seconds["solve"]).
        result = fill_gaps(take, layout, args.fill_method, args.max_gap, naming=naming, calibrations=calibrations,
                           **_solve_progress(bar))
        bar.stage(f"writing {args.output}")
        write_c3d(result.take, args.output)
    except Exception as exc:
        bar.close()
        return _fail(args.file, exc)
    bar.close()
    report = result.report()
    took = report["seconds"]
    how = "calibrated and solved" if len(calibrations) < len(sides) else "solved"
    solved = f" (the hand {how} in {took['solve']:.1f} s)" if "solve" in took else ""
    print(f"{args.file}: {args.fill_method} fill on {layout.name}, max gap {args.max_gap:g} s: {_fill_line(result)} "
          f"in {took['fill']:.2f} s{solved}")
    _print_open_gaps(result)
    print(f"  filled   {args.output}")
    if args.report:
        try:
            _write_report(args.report, report)
        except OSError as exc:
            return _fail(args.file, exc)
    return EXIT_OK


def _write_report(path: str, report: dict) -> None:
    """``report`` as JSON at ``path``, whole or not at all (a folder or unwritable path raises OSError)."""
    from .core.atomic import atomic_output

    if os.path.isdir(path):  # else the rename fails with a confusing temporary name in the message
        raise IsADirectoryError(21, "is a folder; give a file name for the report", path)
    with atomic_output(path) as tmp, open(tmp, "w", encoding="utf-8") as fh:
        json.dump(report, fh, indent=1)
    print(f"  report   {path}")


def _batch(args) -> int:
    from .batch import BatchSettings, find_takes, format_table, run_batch

    try:
        settings = BatchSettings.from_toml(args.config) if args.config else BatchSettings()
    except (ValueError, TypeError) as exc:
        print(f"mocap_autolabel batch: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    for key in ("layout", "model", "method", "temporal", "validate", "confident", "solve_hand", "calibration",
                "blend", "fbx", "bvh", "jobs", "scheduler", "html", "force", "hands", "hand_names", "fill",
                "fill_method", "max_gap"):
        value = getattr(args, key)
        if value is not None:
            setattr(settings, key, value)
    if not 1 <= settings.jobs <= 64:
        print("mocap_autolabel batch: error: --jobs must be 1 to 64", file=sys.stderr)
        return EXIT_USAGE
    if settings.fill_method not in FILL_METHODS or not settings.max_gap > 0:
        print(f"mocap_autolabel batch: error: fill_method must be one of {', '.join(FILL_METHODS)} and max_gap "
              f"positive seconds", file=sys.stderr)
        return EXIT_USAGE
    if settings.scheduler:
        from .farm import MISSING, FarmError, parse_scheduler

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
        from .html_report import MISSING as NO_MATPLOTLIB

        print(f"error: {NO_MATPLOTLIB}", file=sys.stderr)
        return EXIT_FAILED
    if settings.validate and settings.temporal != "vote":
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
        from .core.layout import load_layout

        if settings.layout:
            load_layout(settings.layout)
    except Exception as exc:
        return _fail(settings.layout, exc)
    missing = [i for i in args.inputs if not any(ch in i for ch in "*?[") and not os.path.exists(i)]
    if missing:
        print(f"mocap_autolabel batch: error: no such file or folder: {', '.join(missing)}", file=sys.stderr)
        return EXIT_USAGE
    if not find_takes(args.inputs):
        print(f"mocap_autolabel batch: error: no takes (.c3d, .trc, .tsv) in {' '.join(args.inputs)}", file=sys.stderr)
        return EXIT_USAGE
    progress = "none" if args.quiet else "json" if args.json_progress else "bar"
    from .farm import FarmError

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


def _train(args) -> int:
    from .core.layout import load_layout

    try:
        layout = load_layout(args.layout)
    except Exception as exc:
        return _fail(args.layout, exc)
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    if os.path.isdir(os.path.join(root, "training")) and root not in sys.path:
        sys.path.insert(0, root)  # a source checkout: training/ sits beside addon/
    try:
        from training.recipes import recipe
        from training.train import export, train
    except ImportError as exc:
        print(f"error: training needs PyTorch and the training package of a source checkout "
              f"(pip install torch==2.13.0; run from the repository): {exc}", file=sys.stderr)
        return EXIT_FAILED
    import dataclasses

    r = recipe("set", layout.name)
    r = dataclasses.replace(r, seed=args.seed, steps=args.steps or r.steps)
    print(f"training a set model for {layout.name} ({len(layout)} markers) on synthetic frames: {r.steps} steps",
          file=sys.stderr)
    net, metrics = train(layout, r)
    try:
        export(net, layout, r, metrics, args.output)
    except OSError as exc:
        print(f"error: {args.output}: cannot write ({exc.strerror or exc})", file=sys.stderr)
        return EXIT_FAILED
    v = metrics["synthetic_validation"]
    print(f"{args.output}: synthetic validation {100 * v['accuracy']:.2f} % correct, card "
          f"{os.path.splitext(args.output)[0]}.json")
    return EXIT_OK


def _synth(args) -> int:
    import dataclasses

    from .core.layout import load_layout
    from .core.synth.generate import GHOST, SynthConfig, clean_config, save_synth, synthesize

    try:
        layout = load_layout(args.layout)
    except Exception as exc:
        return _fail(args.layout, exc)
    if args.hands == 2:
        return _synth_two(args, layout)
    if args.prop:
        print("mocap_autolabel synth: error: --prop needs --hands 2", file=sys.stderr)
        return EXIT_USAGE
    config = dataclasses.replace(clean_config() if args.clean else SynthConfig(), rate=args.rate, side=args.side)
    synth = synthesize(layout, args.frames, seed=args.seed, config=config)
    try:
        take_path, truth_path = save_synth(synth, args.output)
    except OSError as exc:
        print(f"error: {args.output}: cannot write ({exc.strerror or exc})", file=sys.stderr)
        return EXIT_FAILED
    labels = synth.labels
    print(f"{take_path}: {layout.name} ({len(layout)} markers), {args.frames} frames at {args.rate:g} Hz, "
          f"{synth.hand.side} hand {synth.hand.length * 1000:.0f} x {synth.hand.breadth * 1000:.0f} mm, "
          f"{synth.take.n_points} slots, {100 * synth.take.missing_fraction:.1f} % of slot samples empty, "
          f"{(labels == GHOST).sum() / args.frames:.2f} ghosts per frame")
    print(f"  truth    {truth_path}")
    if args.blend:
        return _synth_blend(synth, args.blend)
    return EXIT_OK


def _synth_two(args, layout) -> int:
    """``synth --hands 2``: two interacting hands (left and right, sizes of their own)."""
    from .core.synth.generate import GHOST
    from .core.synth.two_hands import TwoHandConfig, save_two_hands, two_hand_take

    if args.clean or args.side or args.blend:
        print("mocap_autolabel synth: error: --hands 2 takes no --clean, --side or --blend", file=sys.stderr)
        return EXIT_USAGE
    if args.frames < 1:
        print(f"mocap_autolabel synth: error: --frames must be positive, got {args.frames}", file=sys.stderr)
        return EXIT_USAGE
    if args.prop and not 3 <= args.prop <= 6:
        print(f"mocap_autolabel synth: error: --prop takes 3 to 6 markers, got {args.prop}", file=sys.stderr)
        return EXIT_USAGE
    config = TwoHandConfig(prop_markers=args.prop)
    two = two_hand_take(layout, args.frames, seed=args.seed, config=config, rate=args.rate)
    try:
        take_path, truth = save_two_hands(two, args.output, config)
    except OSError as exc:
        print(f"error: {args.output}: cannot write ({exc.strerror or exc})", file=sys.stderr)
        return EXIT_FAILED
    sizes = ", ".join(f"{h.hand.side} {h.hand.length * 1000:.0f} x {h.hand.breadth * 1000:.0f} mm" for h in two.hands)
    print(f"{take_path}: two hands of {layout.name} ({2 * len(layout)} markers), {args.frames} frames at "
          f"{args.rate:g} Hz ({sizes}), hands within 5 cm in {100 * (two.gap < 0.05).mean():.0f} % of frames, "
          f"{two.take.n_points} slots, {(two.labels == GHOST).sum() / args.frames:.2f} ghosts per frame")
    if len(two.prop_slots):
        print(f"  prop     {len(two.prop_slots)} markers in the left hand, slots "
              f"{', '.join(two.take.names[s] for s in two.prop_slots)} (ghosts in the truth)")
    print(f"  truth    {truth}")
    return EXIT_OK


def _synth_blend(synth, path: str) -> int:
    """The raw take as empties beside the hand that made it, keyed over the same frames."""
    bpy = _bpy_or_none("synth --blend")
    if bpy is None:
        return EXIT_FAILED
    from .blender.armature import build_hand, key_poses
    from .blender.export import save_blend
    from .blender.scene import ImportOptions, build_take
    from .core.quiet import silenced_stdout

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    build_take(synth.take, scene, ImportOptions())
    truth = bpy.data.collections.new("Truth")
    scene.collection.children.link(truth)
    objs = build_hand(synth.hand, name="TrueHand", collection=truth, layout=synth.layout)
    key_poses(objs["armature"], synth.hand, synth.poses, first_frame=synth.take.first_frame)
    with silenced_stdout():
        save_blend(path)
    print(f"  blend    {path}")
    return EXIT_OK


def _argv_after_double_dash(argv: list[str]) -> list[str]:
    return argv[argv.index("--") + 1:] if "--" in argv else []


if __name__ == "__main__":
    # Run as a script (blender -b -P .../cli.py -- ARGS): import the package from beside us.
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    from mocap_autolabel.cli import main as _main

    sys.exit(_main(_argv_after_double_dash(sys.argv)))
