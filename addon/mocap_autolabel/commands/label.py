"""``label``: a raw take's labels (per-frame scores, then a temporal decision per tracklet), and what
goes with them: the labeled C3D, fills, the solved hand, the review .blend, reports and an HTML page."""

from __future__ import annotations

import importlib.util
import io
import os
import sys

from .common import (
    DEFAULT_MAX_GAP,
    EXIT_FAILED,
    EXIT_OK,
    EXIT_USAGE,
    FILL_METHODS,
    _allows_validation,
    _bpy_or_none,
    _fail,
    _outputs_refused,
    _write_report,
)
from .fill import _fill_line, _print_open_gaps
from .progress import _ProgressBar


def _label(args) -> int:
    import numpy as np

    from ..core.atomic import atomic_output
    from ..core.labelers import labeler_method
    from ..core.labeling import unlabeled_point_names
    from ..core.layout import load_layout
    from ..core.process import Outputs, occlusion_note, performer_inputs, process_take, work_limit_warning
    from ..core.quiet import silenced_stdout
    from ..core.stages.decide import RAW as RAW_CONFIDENCE
    from ..core.synth.truth import load_truth, truth_labels, truth_path
    from ..core.take import read_take

    if args.output and not args.output.lower().endswith(".c3d"):
        print(f"mocap_autolabel label: error: -o must name a .c3d file, got {args.output!r}", file=sys.stderr)
        return EXIT_USAGE
    if not (1 <= args.n_best <= 100 and args.p > 0):
        print("mocap_autolabel label: error: --n-best must be 1 to 100 and --p positive", file=sys.stderr)
        return EXIT_USAGE
    if args.validate and not _allows_validation(args.temporal):
        print("mocap_autolabel label: error: --validate needs --temporal vote", file=sys.stderr)
        return EXIT_USAGE
    if args.blend and not args.blend.lower().endswith(".blend") or args.solve_hand and not args.blend:
        print("mocap_autolabel label: error: --blend must name a .blend file, and --solve-hand needs --blend",
              file=sys.stderr)
        return EXIT_USAGE
    if args.fill and not args.output:
        print("mocap_autolabel label: error: --fill needs -o OUT.c3d (the filled, labeled take)", file=sys.stderr)
        return EXIT_USAGE
    if not args.fill and (args.fill_method != FILL_METHODS[0] or args.max_gap != DEFAULT_MAX_GAP):
        print("mocap_autolabel label: error: --fill-method and --max-gap are for --fill (add it to fill the gaps)",
              file=sys.stderr)
        return EXIT_USAGE
    if args.html:
        from ..html_report import MISSING as NO_MATPLOTLIB

        if not args.html.lower().endswith((".html", ".htm")):
            print(f"mocap_autolabel label: error: --html must name a .html file, got {args.html!r}", file=sys.stderr)
            return EXIT_USAGE
        if importlib.util.find_spec("matplotlib") is None:
            print(f"error: {NO_MATPLOTLIB}", file=sys.stderr)
            return EXIT_FAILED
    if args.blend and _bpy_or_none("label --blend") is None:
        return EXIT_USAGE
    refused = _outputs_refused(args.file, [args.output, args.report, args.html, args.labels, args.blend],
                               [args.file, args.fit, args.calibration, args.layout])
    if refused is not None:
        return refused
    bar = _ProgressBar.for_args(args)
    try:
        layout = load_layout(args.layout)
        bar(f"reading {args.file}")
        take = read_take(args.file)
        performer = performer_inputs(args.fit, layout, args.method)
        outputs = Outputs(solve=args.solve_hand, fill=args.fill_method if args.fill else None,
                          max_gap=args.max_gap)
        result = process_take(take, layout, _label_settings(args, layout), outputs, progress=bar, **performer)
        labeling, doubt = result.labeling, result.doubt
        missed = [f"{side} hand: {check}" for side, check in result.checks if not check.found]
        if args.output:
            from ..core.formats.c3d import write_c3d

            bar(f"writing {args.output}")
            write_c3d(result.output_take, args.output)
        filled, solved = result.filled, result.rig() if args.solve_hand else None
        if args.blend:
            from ..blender.export import write_review_scene

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
    if labeling.info.get("never_confident") == "uncalibrated":
        print(f"  note     {args.method} has no confidence calibration for {layout.name}: its probabilities were never "
              f"measured against the truth there, so no segment is rated confident and every one is left for review")
    elif labeling.info.get("confidence") == RAW_CONFIDENCE and args.method == "set":
        print(f"  note     set has no confidence calibration for {layout.name} (a layout it was never calibrated on): "
              f"its confidences are the network's raw probabilities, which seldom reach the bar of confident, so "
              f"the confident share says little of how many labels are right; review the uncertain segments")
    elif labeling.info.get("never_confident"):
        print(f"  note     {args.method} + {args.temporal} never rates a segment confident on {layout.name}: on "
              f"synthetic validation takes none of its segments were right 99.9 % of the time, so all are left "
              f"for review (set is the method whose confident segments can be skipped)")
    if doubt:
        print(f"  warning  {doubt} (--layout {doubt.better})")
    hurried = work_limit_warning(labeling)
    if hurried:
        print(f"  warning  {hurried}")
    occluded = occlusion_note(labeling)
    if occluded:
        print(f"  note     {occluded}")
    tpath = truth_path(args.file)
    if os.path.isfile(tpath):
        from ..core.metrics import score_labeling

        sidecar = load_truth(tpath)
        per = truth_labels(labeling, sidecar["info"].get("names", labeling.names))
        if per is None:
            print(f"  truth    {tpath}: not scored: it names {len(sidecar['info']['names'])} labels "
                  f"({sidecar['info']['names'][0]}...), this labeling {len(labeling.names)} ({labeling.names[0]}...)")
        else:
            score = score_labeling(per, sidecar["labels"], take.valid, len(labeling.names))
            report["truth"] = score.as_dict()
            print(f"  truth    {tpath}: {100 * score.accuracy:.2f} % correct, {100 * score.frame_accuracy:.2f} % of "
                  f"frames all correct ({score.erroneous} erroneous, {score.false_marker} false marker, "
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
            packed = io.BytesIO()  # a zip is sought back and forth: built in memory, so a device takes it too
            np.savez_compressed(packed, labels=labeling.per_sample(), confidence=labeling.per_sample_confidence(),
                                names=np.array(labeling.names))
            with atomic_output(args.labels) as tmp, open(tmp, "wb") as fh:
                fh.write(packed.getvalue())
            print(f"  labels   {args.labels}")
    except OSError as exc:
        return _fail(args.file, exc)
    if not (args.output or args.blend or args.report or args.labels):
        print("  output   none written: give -o OUT.c3d for the labeled take (or --report, --labels, --blend)")
    return EXIT_OK


def _label_page(args, report: dict, labeling, first_frame: int, filled, solved) -> None:
    """``label --html``: the take's report as one HTML page (as batch writes per take), atomically."""
    from ..core.atomic import atomic_output
    from ..core.overview import label_classes, label_fills
    from ..html_report import take_page

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


def _hand_options(args) -> dict:
    """The settings' hand fields from --hands / --sides / --hand-names (ValueError on a bad value)."""
    from ..core.hands import SIDES, HandNaming

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
    from ..core.settings import LabelSettings

    hand = None
    if args.calibration:
        from ..core.hand.calibrate import Calibration

        hand = Calibration.load(args.calibration)
        hand.check(layout, args.calibration)
    return LabelSettings(method=args.method, temporal=args.temporal, model=args.model, vote_score=args.vote,
                         power_p=args.p, power_q=args.q, n_best=args.n_best, validate=args.validate,
                         validate_hand=hand, **_hand_options(args))


def _hands_line(labeling, first_frame: int = 0, confident: float = 0.95) -> str | None:
    """One line per take on the hands found and their sides (frames numbered from ``first_frame``),
    or None for a plain one-hand take."""
    from ..core.hands import traded_text

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
