"""Labelers: one protocol (:class:`~.base.Labeler`), five methods in one registry, one assignment step.

========  =========================================================  ===================
method    what it is                                                 needs
========  =========================================================  ===================
set       ours: attention over the point set + Sinkhorn (ONNX)       nothing (any layout)
perm      Ghorbani 2019: PCA slots, residual MLP, Sinkhorn (ONNX)    a model for the layout
cnn       Han 2018: depth image, VGG-style CNN, matching (ONNX)      a model for the layout
gmm       Alexanderson 2016: per-marker GMMs in the hand frame        ``fit`` on a labeled take
nearest   Feit 2016: nearest-neighbour tracking with gates            a labeled first frame
========  =========================================================  ===================

:data:`LABELERS` maps each name to a :class:`LabelerMethod` class whose attributes say what the
method can do; the pipeline asks those attributes and never compares method names.
"""

from __future__ import annotations

import os
from typing import ClassVar

import numpy as np

from ..errors import MocapInputError
from ..layout import Layout
from .assign import assign
from .base import NULL, FrameBatch, Labeler, frames_from_take, pack_frames


class LabelerMethod:
    """A labeling method of the registry: capabilities as class attributes, :meth:`build` makes
    the labeler for a take.

    Attributes:
        name: the method's name (CLI ``--method``, batch TOML, the panel).
        onnx: scores come from an ONNX model for the layout (shipped, or ``model=``).
        labels_two_hands: labels two hands jointly (each hand's points scored on their own).
        strided: may score every ``stride``-th frame of a trajectory (ours); the published methods
            score every frame, as their papers do.
        low_probability: its per-frame probabilities are low even where right: its segments are
            believed by calibrated confidence (the no-hand rule).
        sure_of_itself: its probabilities (or calibrated confidences) tell a hand from a body or a
            prop, so the no-hand rule counts only labels it believes; False (``gmm``, ``nearest``):
            the rule asks only whether its labels form a hand, so that it never silences them.
        whole_take: labels a take from its first frame on (no windows, no local re-solve).
        relabels_locally: a reviewer's re-solve may label only the frames around a change.
        fits_performer: fitted on a labeled take of the performer (``fit``), else on the layout's
            synthetic range of motion.
        starts_from_frame: tracks from a labeled first frame (``start``).
        any_layout_model: for ``onnx`` methods, the shipped model that labels any layout (its
            labels' vectors computed from the layout's geometry), used where no model was trained
            for the layout itself; None where the method needs a model per layout.
    """

    name: ClassVar[str]
    onnx: ClassVar[bool] = False
    labels_two_hands: ClassVar[bool] = False
    strided: ClassVar[bool] = False
    low_probability: ClassVar[bool] = False
    sure_of_itself: ClassVar[bool] = True
    whole_take: ClassVar[bool] = False
    relabels_locally: ClassVar[bool] = True
    fits_performer: ClassVar[bool] = False
    starts_from_frame: ClassVar[bool] = False
    any_layout_model: ClassVar[str | None] = None

    @classmethod
    def refusal(cls, layout: Layout, *, labeler: bool = False, fit: bool = False, start: bool = False) -> str | None:
        """Why this method cannot label ``layout`` given what the caller brings (a ready ``labeler``,
        a labeled ``fit`` take, a labeled ``start`` frame), in one line; None where it can."""
        return None

    @classmethod
    def make(cls, layout: Layout, model: str | os.PathLike | None = None, cache=None, **options) -> Labeler:
        """The labeler for ``layout`` with no take at hand (``options`` go to the constructor)."""
        raise NotImplementedError

    @classmethod
    def build(cls, layout: Layout, batch: FrameBatch, *, model: str | None = None, fit: np.ndarray | None = None,
              start: np.ndarray | None = None, cache=None) -> Labeler:
        """The labeler for one take packed as ``batch``: ``fit`` ``(F, M, 3)`` labeled positions of the
        performer, ``start`` ``(M, 3)`` a labeled first frame, where the method uses them; ``cache``
        (a :class:`..cache.RunCache`) keeps what costs seconds to make (loaded models, fits)."""
        return cls.make(layout, model)


class _OnnxMethod(LabelerMethod):
    onnx = True
    labels_two_hands = True
    low_probability = True

    @classmethod
    def build(cls, layout: Layout, batch: FrameBatch, *, model: str | None = None, fit: np.ndarray | None = None,
              start: np.ndarray | None = None, cache=None) -> Labeler:
        return cls.make(layout, model, cache=cache)

    @classmethod
    def make(cls, layout: Layout, model: str | os.PathLike | None = None, cache=None, **options) -> Labeler:
        from .onnx_labeler import shipped_model

        path = os.fspath(model) if model is not None else shipped_model(cls.name, layout.name)
        if model is None and not os.path.isfile(path) and cls.any_layout_model:
            path = shipped_model(cls.name, cls.any_layout_model)
        if model is None and not os.path.isfile(path):
            raise MocapInputError(path, f"'{cls.name}' needs a model trained for each layout, and none ships for "
                                        f"'{layout.name}': label it with method set (any layout), or train one "
                                        f"with: python -m mocap_autolabel train --layout ... -o model.onnx")
        labeler = _loaded_onnx(path, layout, cache)
        if labeler.name != cls.name:
            raise MocapInputError(path, f"model is a '{labeler.name}' model, not '{cls.name}'")
        return labeler


class SetMethod(_OnnxMethod):
    name = "set"
    strided = True
    any_layout_model = "any"
    low_probability = False  # a han19 take labeled with glove13 has calibrated confidences of 0.5 on wrong labels


class PermMethod(_OnnxMethod):
    name = "perm"


class CnnMethod(_OnnxMethod):
    name = "cnn"


class GmmMethod(LabelerMethod):
    name = "gmm"
    relabels_locally = False
    fits_performer = True
    sure_of_itself = False
    #: Markers on the back of the hand or wrist (bone ``palm``) its hand frame is built from.
    HAND_MARKERS = 3

    @classmethod
    def refusal(cls, layout: Layout, *, labeler: bool = False, fit: bool = False, start: bool = False) -> str | None:
        hand = sum(m.bone == "palm" for m in layout.markers)
        if labeler or hand >= cls.HAND_MARKERS:
            return None
        return (f"gmm (Alexanderson 2016) builds its hand frame from {cls.HAND_MARKERS} markers on the back of the "
                f"hand or wrist (bone \"palm\"), and layout '{layout.name}' has {hand}: label it with method set, "
                "which needs none")

    @classmethod
    def make(cls, layout: Layout, model: str | os.PathLike | None = None, cache=None, **options) -> Labeler:
        from .gmm import GmmLabeler

        return GmmLabeler(layout, **options)

    @classmethod
    def build(cls, layout: Layout, batch: FrameBatch, *, model: str | None = None, fit: np.ndarray | None = None,
              start: np.ndarray | None = None, cache=None) -> Labeler:
        from .gmm import fitted_to_take, range_of_motion_gmm

        if fit is None:  # no take of the performer: the layout's synthetic range of motion stands in
            rom = cache.remember("rom_gmm", (layout.name, repr(layout.names)),
                                 lambda: range_of_motion_gmm(layout)) if cache is not None else \
                range_of_motion_gmm(layout)
            return fitted_to_take(rom, batch)
        labeler = cls.make(layout)
        try:
            labeler.fit(fit)
        except ValueError as exc:  # the fitting take lacks what the GMMs need (the rigid triangle, samples)
            raise MocapInputError("--fit", f"cannot fit gmm on this labeled take: {exc}") from None
        return labeler


class NearestMethod(LabelerMethod):
    name = "nearest"
    whole_take = True
    sure_of_itself = False
    relabels_locally = False
    starts_from_frame = True

    @classmethod
    def make(cls, layout: Layout, model: str | os.PathLike | None = None, cache=None, **options) -> Labeler:
        from .nearest import NearestLabeler

        return NearestLabeler(layout, **options)

    @classmethod
    def build(cls, layout: Layout, batch: FrameBatch, *, model: str | None = None, fit: np.ndarray | None = None,
              start: np.ndarray | None = None, cache=None) -> Labeler:
        if start is None:  # seed the tracker with our own labels of the first frame that has points
            first = int(np.argmax(batch.mask.any(axis=1)))
            seed = SetMethod.make(layout, cache=cache)
            labels, _ = assign(seed.scores(batch.points[first:first + 1], batch.mask[first:first + 1]),
                               batch.mask[first:first + 1])
            start = np.full((len(layout), 3), np.nan)
            ok = labels[0] >= 0
            start[labels[0][ok]] = batch.points[first][ok]
        else:
            cls._check_start(start, batch)
        return cls.make(layout, start=start)

    @staticmethod
    def _check_start(start: np.ndarray, batch: FrameBatch) -> None:
        """A given first frame must be this take's: the tracker takes each label's point within a
        millimetre of it, so another recording's first frame labels nothing (and the no-hand rule then
        blamed the take)."""
        given = np.isfinite(start).all(axis=1)
        points = batch.points[0][batch.mask[0]].astype(np.float64)
        if not given.any():
            raise MocapInputError("--fit", "the labeled take names none of the layout's markers in its first frame")
        found = 0
        if len(points):
            d = np.linalg.norm(points[:, None] - start[None, given], axis=2)  # (points, labeled markers)
            found = int((d.min(axis=0) < 1e-3).sum())
        if found * 2 < int(given.sum()):
            raise MocapInputError("--fit", f"nearest starts from the labeled first frame of this very take, and this "
                                           f"one's first frame holds only {found} of its {int(given.sum())} labeled "
                                           f"markers within a millimetre (another recording?): give this take "
                                           f"labeled (label it, correct its first frame, and pass that file), or use "
                                           f"--method gmm, which fits on any take of the performer")


#: The labeling methods by name, in the order the UI lists them; the first is the default.
LABELERS: dict[str, type[LabelerMethod]] = {m.name: m for m in (SetMethod, PermMethod, CnnMethod, GmmMethod,
                                                                  NearestMethod)}
METHODS = tuple(LABELERS)
ONNX_METHODS = tuple(name for name, m in LABELERS.items() if m.onnx)


def labeler_method(name: str) -> type[LabelerMethod]:
    """The registry's class for ``name``; a ValueError naming the choices for an unknown one."""
    try:
        return LABELERS[name]
    except KeyError:
        raise ValueError(f"unknown labeling method {name!r}; choose one of {', '.join(LABELERS)}") from None


def _loaded_onnx(path: str, layout: Layout, cache=None) -> Labeler:
    """Loading a model (checksum, session) costs more than labeling a short take: ``cache`` keeps the
    loaded ones, keyed by file identity and layout, so a batch of takes loads each model once."""
    from .onnx_labeler import OnnxLabeler

    if cache is None:
        return OnnxLabeler(path, layout)
    try:
        st = os.stat(path)
    except OSError:
        return OnnxLabeler(path, layout)  # reports the missing file
    key = (os.path.abspath(path), st.st_mtime_ns, st.st_size, layout.name, layout.markers, layout.glove)
    return cache.remember("onnx", key, lambda: OnnxLabeler(path, layout))


def make_labeler(method: str, layout: Layout, model: str | os.PathLike | None = None, cache=None,
                 **options) -> Labeler:
    """A labeler by name.

    Args:
        method: one of :data:`METHODS`.
        layout: the marker layout to label.
        model: ONNX model for ``set`` / ``perm`` / ``cnn``; default: the shipped model for the layout.
        cache: a :class:`..cache.RunCache` that keeps loaded models (None: load afresh).
        options: passed to the ``gmm`` / ``nearest`` constructors.
    """
    return labeler_method(method).make(layout, model, cache=cache, **options)


__all__ = ["LABELERS", "METHODS", "NULL", "FrameBatch", "Labeler", "LabelerMethod", "assign", "frames_from_take",
           "labeler_method", "make_labeler", "pack_frames"]
