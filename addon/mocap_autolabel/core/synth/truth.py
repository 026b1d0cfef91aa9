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
