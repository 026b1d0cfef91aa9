"""Where a synthetic take's ground truth lies beside it, and reading it back (light: the ``label``
command checks every take for a sidecar without importing the generator)."""

from __future__ import annotations

import json
import os

import numpy as np


def truth_path(take_path: str | os.PathLike) -> str:
    """Where the ground truth of a synthetic take is written: ``take.c3d`` -> ``take.truth.npz``."""
    stem, _ = os.path.splitext(os.fspath(take_path))
    return stem + ".truth.npz"


def load_truth(path: str | os.PathLike) -> dict:
    """Read a truth sidecar: ``labels``, ``markers``, ``poses`` arrays and the ``info`` dict."""
    with np.load(os.fspath(path), allow_pickle=False) as z:
        out = {k: z[k] for k in ("labels", "markers", "poses")}
        out["info"] = json.loads(z["info"].item())
    return out


def truth_labels(labeling, names: list[str]) -> np.ndarray | None:
    """int ``(F, P)``: ``labeling``'s per-sample labels as indices into the truth's label ``names``
    (NULL/EMPTY kept); None where the two name different labels (a two-hand truth and a labeling of
    one hand): then there is nothing to score the labeling by."""
    where = {n: i for i, n in enumerate(names)}
    if len(names) != len(labeling.names) or any(n not in where for n in labeling.names):
        return None
    per = labeling.per_sample()
    index = np.array([where[n] for n in labeling.names], dtype=per.dtype)
    return np.where(per >= 0, index[np.maximum(per, 0)], per)
