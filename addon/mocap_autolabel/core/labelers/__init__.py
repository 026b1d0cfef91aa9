"""Labelers: one protocol (:class:`~.base.Labeler`), five methods, one assignment step.

========  =========================================================  ===================
method    what it is                                                 needs
========  =========================================================  ===================
set       ours: attention over the point set + Sinkhorn (ONNX)       a model for the layout
perm      Ghorbani 2019: PCA slots, residual MLP, Sinkhorn (ONNX)    a model for the layout
cnn       Han 2018: depth image, VGG-style CNN, matching (ONNX)      a model for the layout
gmm       Alexanderson 2016: per-marker GMMs in the hand frame        ``fit`` on a labeled take
nearest   Feit 2016: nearest-neighbour tracking with gates            a labeled first frame
========  =========================================================  ===================
"""

from __future__ import annotations

import os

from ..errors import MocapInputError
from ..layout import Layout
from .assign import assign
from .base import NULL, FrameBatch, Labeler, frames_from_take, pack_frames

#: Methods in the order the UI lists them; the first is the default.
METHODS = ("set", "perm", "cnn", "gmm", "nearest")
ONNX_METHODS = ("set", "perm", "cnn")


_LOADED: dict[tuple, Labeler] = {}


def _cached_onnx(path: str, layout: Layout) -> Labeler:
    """Loading a model (checksum, session) costs more than labeling a short take: keep the last
    few, keyed by file identity and layout, so a batch of takes loads each model once."""
    from .onnx_labeler import OnnxLabeler

    try:
        st = os.stat(path)
        key = (os.path.abspath(path), st.st_mtime_ns, st.st_size, layout.name, tuple(layout.names))
    except OSError:
        return OnnxLabeler(path, layout)  # reports the missing file
    if key not in _LOADED:
        if len(_LOADED) >= 8:
            _LOADED.pop(next(iter(_LOADED)))
        _LOADED[key] = OnnxLabeler(path, layout)
    return _LOADED[key]


def make_labeler(method: str, layout: Layout, model: str | os.PathLike | None = None, **options) -> Labeler:
    """A labeler by name.

    Args:
        method: one of :data:`METHODS`.
        layout: the marker layout to label.
        model: ONNX model for ``set`` / ``perm`` / ``cnn``; default: the shipped model for the layout.
        options: passed to the ``gmm`` / ``nearest`` constructors.
    """
    if method in ONNX_METHODS:
        from .onnx_labeler import shipped_model

        path = os.fspath(model) if model is not None else shipped_model(method, layout.name)
        if model is None and not os.path.isfile(path):
            raise MocapInputError(path, f"no shipped '{method}' model for layout '{layout.name}'; "
                                        f"train one with: python -m mocap_autolabel train --layout ... -o model.onnx")
        labeler = _cached_onnx(path, layout)
        if labeler.name != method:
            raise MocapInputError(path, f"model is a '{labeler.name}' model, not '{method}'")
        return labeler
    if method == "gmm":
        from .gmm import GmmLabeler

        return GmmLabeler(layout, **options)
    if method == "nearest":
        from .nearest import NearestLabeler

        return NearestLabeler(layout, **options)
    raise ValueError(f"unknown labeling method {method!r}; choose one of {', '.join(METHODS)}")


__all__ = ["METHODS", "NULL", "FrameBatch", "Labeler", "assign", "frames_from_take", "make_labeler", "pack_frames"]
