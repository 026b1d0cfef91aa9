"""Labelers backed by an ONNX model and its JSON card (``set``, ``perm``, ``cnn``).

The card names the layout the model was trained for and its input convention; the code that
prepares inputs for each convention lives in :mod:`.inputs`, never next to the training code.
"""

from __future__ import annotations

import hashlib
import json
import os
import threading
from collections.abc import Callable

import numpy as np

from ..errors import MocapInputError
from ..layout import Layout, marker_descriptors
from ..threads import side_by_side, worker_threads
from .base import Labeler
from .inputs import prepare_inputs, scores_from_outputs

#: Where the shipped models live: ``<method>_<layout>.onnx`` beside ``<method>_<layout>.json``.
MODELS_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "models")


def card_path(model_path: str | os.PathLike) -> str:
    return os.path.splitext(os.fspath(model_path))[0] + ".json"


def shipped_model(method: str, layout_name: str) -> str:
    """Path of the shipped model of ``method`` for a built-in layout (may not exist)."""
    return os.path.join(MODELS_DIR, f"{method}_{layout_name}.onnx")


def load_card(model_path: str | os.PathLike) -> dict:
    """Read and check a model's card; the error names the model file."""
    path = os.fspath(model_path)
    if not os.path.isfile(path):
        raise MocapInputError(path, "model file not found")
    cpath = card_path(path)
    try:
        with open(cpath, encoding="utf-8") as f:
            card = json.load(f)
    except FileNotFoundError:
        raise MocapInputError(path, f"model card {os.path.basename(cpath)} is missing beside the model") from None
    except (OSError, ValueError) as e:
        raise MocapInputError(path, f"model card {os.path.basename(cpath)} is unreadable ({e})") from None
    for key in ("method", "layout", "input", "sha256"):
        if key not in card:
            raise MocapInputError(path, f"model card has no '{key}'")
    return card


#: The fewest observation columns a model is run with (padding is masked out): exported graphs
#: fix the k of their k-nearest-neighbour step (8 in ``set``).
MIN_WIDTH = 16


class OnnxLabeler(Labeler):
    """Scores from an ONNX model, run in batches with onnxruntime.

    A model whose card says ``input.layout_conditioned`` labels any layout: it is fed the layout's
    :func:`..layout.marker_descriptors` and needs ``layout``.

    Args:
        model_path: the ``.onnx`` file; its card ``.json`` must lie beside it.
        layout: if given, the model must have been trained for exactly these label names (or be
            layout-conditioned).
        batch: frames per inference call (bounded memory; a few hundred keeps tensors in cache).
    """

    def __init__(self, model_path: str | os.PathLike, layout: Layout | None = None, batch: int = 128):
        import onnxruntime as ort

        self.path = os.fspath(model_path)
        self.card = load_card(self.path)
        self.name = self.card["method"]
        names = list(self.card["layout"].get("labels", []))
        self.extra_feeds: dict[str, np.ndarray] = {}
        self.layout_conditioned = bool(self.card["input"].get("layout_conditioned"))
        if self.layout_conditioned:
            if layout is None:
                raise MocapInputError(self.path, "this model labels any layout: name the layout to label")
            names = layout.names
            self.card = {**self.card, "layout": {"name": layout.name, "labels": names}}
            self.extra_feeds["layout"] = marker_descriptors(layout)
        if layout is not None and names != layout.names:
            raise MocapInputError(self.path, f"model is for layout '{self.card['layout'].get('name')}' "
                                             f"({len(names)} labels), not for '{layout.name}' ({len(layout)} labels)")
        self.layout = layout  # None: trust the card's label names
        self.labels = names
        with open(self.path, "rb") as f:
            blob = f.read()
        if hashlib.sha256(blob).hexdigest() != self.card["sha256"]:
            raise MocapInputError(self.path, "model file is corrupt or was changed (checksum differs from its card)")
        options = ort.SessionOptions()
        options.log_severity_level = 3
        # One thread per run, and batches run side by side: these graphs are many small ops, which
        # parallelise better across batches than inside one.
        self.workers = worker_threads()
        options.intra_op_num_threads = 1
        try:
            self.session = ort.InferenceSession(blob, options, providers=["CPUExecutionProvider"])
        except Exception as e:  # onnxruntime raises its own types for bad graphs
            raise MocapInputError(self.path, f"not a usable ONNX model ({str(e).splitlines()[0]})") from None
        self.batch = batch
        #: Called with the share of frames scored (0 to 1) after each batch, if set: progress bars.
        self.on_batch: Callable[[float], None] | None = None

    def scores(self, points: np.ndarray, mask: np.ndarray) -> np.ndarray:
        frames, k, _ = points.shape
        out = np.zeros((frames, k, len(self.labels) + 1), dtype=np.float32)
        # Batches of frames with like numbers of observations, each cut to its own widest frame:
        # a take's K is its most crowded frame (a 10,000-frame synthetic han19 take: K 23, median
        # 19 points; 1.23x faster). Padding never changes a real observation's scores.
        mask = np.asarray(mask, dtype=bool)
        counts = mask.sum(axis=1)
        order = np.argsort(counts, kind="stable")

        def run(s: int) -> None:
            rows = order[s:s + self.batch]
            width = max(int(counts[rows].max()), MIN_WIDTH)
            cols = np.argsort(~mask[rows], axis=1, kind="stable")[:, :width]  # real observations first
            pts = np.zeros((len(rows), width, 3), dtype=np.float32)
            msk = np.zeros((len(rows), width), dtype=bool)
            pts[:, :cols.shape[1]] = np.take_along_axis(points[rows], cols[..., None], axis=1)
            msk[:, :cols.shape[1]] = np.take_along_axis(mask[rows], cols, axis=1)
            feeds, context = prepare_inputs(self.card, pts, msk)
            feeds.update(self.extra_feeds)
            outputs = self.session.run(None, feeds)  # releases the GIL
            scores = scores_from_outputs(self.card, outputs, context, pts, msk)
            out[rows[:, None], cols] = scores[:, :cols.shape[1]]

        starts = range(0, frames, self.batch)
        if self.on_batch is not None:
            report, lock, finished = self.on_batch, threading.Lock(), [0]
            step = max(1, len(starts) // 100)  # about a hundred calls, whatever the take's length

            def run_and_report(s: int, inner=run) -> None:
                inner(s)
                with lock:
                    finished[0] += 1
                    if finished[0] % step == 0 or finished[0] == len(starts):
                        report(finished[0] / len(starts))

            run = run_and_report
        side_by_side(run, starts, self.workers)
        return out
