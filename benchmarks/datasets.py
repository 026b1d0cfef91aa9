"""Evaluation data sets of the per-frame benchmark (real data stays in ../shared/data)."""

from __future__ import annotations

import glob
import os

import numpy as np
from mocap_autolabel.core.layout import Layout
from mocap_autolabel.core.take import read_take

DATA = os.environ.get("MOCAP_DATA", os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data"))
HAN2018 = os.path.join(DATA, "hands", "han2018_dense19")
GLOVE13 = os.path.join(DATA, "hands", "qualisys_glove13", "recording_part1.tsv")


def layout_columns(names: list[str], layout: Layout) -> np.ndarray:
    """Column of each layout label in a take's names (-1 if absent)."""
    where = {n: i for i, n in enumerate(names)}
    return np.array([where.get(n, -1) for n in layout.names])


def han2018_sequences(layout: Layout, every: int = 1, limit: int | None = None,
                      user: str = "User*") -> list[np.ndarray]:
    """Every han2018 TRC as ``(F, 19, 3)`` metres in layout order (sorted paths, frames subsampled by ``every``)."""
    paths = sorted(glob.glob(os.path.join(HAN2018, user, "capture*", "*.trc")))[:limit]
    out = []
    for p in paths:
        take = read_take(p)
        cols = layout_columns(take.names, layout)
        if (cols < 0).any():
            raise ValueError(f"{p}: missing labels {np.array(layout.names)[cols < 0]}")
        out.append(take.positions[::every, cols].astype(np.float64))
    return out


def glove13_take(layout: Layout):
    """The real Qualisys recording: the take and, per slot, its true label (-1 for distractors)."""
    take = read_take(GLOVE13)
    index = {n: i for i, n in enumerate(layout.names)}
    truth = np.array([index.get(n, -1) for n in take.names])
    return take, truth


def write_report(path: str, lines: list[str]) -> None:
    """Write a markdown report (one line per item) and say where."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w", encoding="utf-8") as f:
        f.write("\n".join(lines) + "\n")
    print(f"wrote {path}")
