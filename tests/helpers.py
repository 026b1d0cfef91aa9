"""Small builders shared by the tests."""

from __future__ import annotations

import numpy as np
from mocap_autolabel.core.take import Take


def small_take(frames: int = 50, points: int = 4, seed: int = 0, gaps: bool = True) -> Take:
    """A take of points moving smoothly (metres), with a few gaps of each convention already as NaN."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames, dtype=np.float32)[:, None, None] / 100.0
    base = rng.uniform(-0.5, 0.5, (1, points, 3)).astype(np.float32)
    positions = (base + 0.1 * np.sin(2 * np.pi * t + np.arange(points)[None, :, None])).astype(np.float32)
    if gaps:
        positions[5:9, 0] = np.nan
        positions[20:21, 1] = np.nan
        positions[frames - 3:, points - 1] = np.nan
    return Take(positions=positions, names=[f"*{i}" for i in range(points)], rate=100.0, source="small.c3d")
