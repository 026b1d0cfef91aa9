"""``layout --from LABELED -o my.toml``: a layout fitted from a labeled take (each marker's bone and place
on the template hand), so that a studio gets its layout by labeling one take instead of writing TOML."""

from __future__ import annotations

from .common import EXIT_OK, _fail
from .progress import _ProgressBar


def _layout(args) -> int:
    from ..core.hands.naming import HandNaming
    from ..core.layout_fit import write_fitted_layout
    from ..core.take import read_take

    bar = _ProgressBar.for_args(args)
    try:
        take = read_take(args.source)
        fit = write_fitted_layout(take, args.output, side=args.side,
                                  naming=HandNaming(args.hand_names) if args.hand_names else None,
                                  points=[p for p in args.points.split(",") if p] if args.points else None,
                                  name=args.name, frames=args.frames,
                                  progress=lambda share: bar("fitting the layout", share))
    except Exception as exc:
        bar.close()
        return _fail(args.source, exc)
    bar.close()
    print(f"wrote {args.output}: {len(fit.layout)} markers of a {fit.side} hand, calibration RMS "
          f"{1000 * fit.rms:.1f} mm")
    doubt = fit.doubt()
    if doubt:
        print(f"  warning  {doubt}")
    for marker in fit.layout.markers:
        where = (f"along {marker.along:.2f}, across {marker.across:+.2f}" if marker.bone == "palm" else
                 f"along {marker.along:.2f}, {marker.angle_deg:+.0f} deg")
        print(f"  {marker.name:<16} {marker.bone:<12} {where}")
    return EXIT_OK
