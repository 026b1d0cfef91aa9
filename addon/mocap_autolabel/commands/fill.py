"""``fill``: the gaps of a labeled take filled (fills marked as computed in the C3D); the lines on a fill
that ``label --fill`` prints too."""

from __future__ import annotations

from .common import EXIT_OK, _fail, _outputs_refused, _write_report
from .progress import _ProgressBar


def _fill(args) -> int:
    from ..core.errors import MocapInputError
    from ..core.formats.c3d import write_c3d
    from ..core.hand.calibrate import Calibration
    from ..core.hands import HandNaming, labeled_layout, split_hands
    from ..core.layout import load_layout
    from ..core.process import Outputs, process_take
    from ..core.settings import LabelSettings
    from ..core.take import read_take

    refused = _outputs_refused(args.file, [args.output, args.report],
                               [args.file, args.layout, *(args.calibration or "").split(",")])
    if refused is not None:
        return refused
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
        bar.stage("filling gaps")
        # A fill that uses the hand solves it first (its seconds["solve"]), as the progress says.
        outputs = Outputs(label=False, fill=args.fill_method, max_gap=args.max_gap, calibrations=calibrations)
        result = process_take(take, layout, LabelSettings(naming=args.hand_names), outputs,
                              progress=bar).filled
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
