"""``info``: a summary of each take file (C3D, TRC, Qualisys TSV), as text or JSON."""

from __future__ import annotations

import json

from .common import EXIT_OK, _fail


def _info(args) -> int:
    from ..core.take import read_take

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
    from ..core.hands import hands_in_names
    from ..core.layout import builtin_layouts, load_layout

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
