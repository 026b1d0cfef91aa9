"""Make Layout's scene side: the labeled markers of a take in the scene, fitted and written by the core."""

from __future__ import annotations

from collections.abc import Callable

import bpy


def make_layout(scene: bpy.types.Scene, take_coll: bpy.types.Collection, path: str, *, side: str | None = None,
                points: list[str] | None = None, progress: Callable[[float], None] | None = None):
    """Fit a layout to the take's labeled markers (this tool's labels where it was labeled here, else the
    file's own point names), write it to ``path`` and put it in the panel's Layout File field.
    Returns the :class:`~mocap_autolabel.core.layout_fit.LayoutFit`."""
    from ..core.labeling import labeled_take
    from ..core.layout_fit import write_fitted_layout
    from .takes import current_take, has_review, load_state

    take = current_take(take_coll)
    if has_review(take_coll):
        take = labeled_take(take, load_state(take_coll).labeling)
    fit = write_fitted_layout(take, path, side=side, points=points, progress=progress)
    scene.mocap_autolabel.layout_file = path
    return fit
