"""A small, deterministic raw take for the demo and the README: a waving hand-like marker set.

This is a stand-in until the procedural hand generator exists: 19 markers on five digits and
the back of a hand, fingers flexing in a wave, occlusions in runs, one persistent ghost, and
the capture system's habit of starting a new ``*N`` slot after every gap.
"""

from __future__ import annotations

import numpy as np

from ..take import Take

#: Marker positions on the flat hand (metres, hand frame: x to the thumb, y to the fingertips).
_DIGITS = {  # base (x, y) and the distances of its markers along the digit
    "Thumb": ((0.045, 0.02), (0.03, 0.06, 0.09, 0.115)),
    "Index": ((0.025, 0.09), (0.0, 0.045, 0.08)),
    "Middle": ((0.0, 0.095), (0.0, 0.05, 0.09)),
    "Ring": ((-0.022, 0.09), (0.0, 0.045, 0.08)),
    "Pinky": ((-0.042, 0.08), (0.0, 0.035, 0.063)),
}
_BACK = np.array([[0.0, 0.02, 0.012], [0.0, 0.05, 0.012], [-0.03, 0.035, 0.012]])


def sample_take(frames: int = 600, rate: float = 120.0, seed: int = 0) -> Take:
    """An unlabeled raw take: positions ``(frames, slots, 3)`` in metres, names ``*0 .. *N``."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / rate
    markers = []
    for d, ((bx, by), dist) in enumerate(_DIGITS.values()):
        flex = 0.6 * (1 + np.sin(2 * np.pi * 0.5 * t - 0.7 * d))  # radians, a wave across the digits
        for k, s in enumerate(dist):
            angle = flex * (k / max(len(dist) - 1, 1))
            y = by + s * np.cos(angle)
            z = 0.015 - s * np.sin(angle)
            markers.append(np.stack([np.full_like(t, bx), y, z], axis=1))
    markers += [np.repeat(p[None], frames, axis=0) for p in _BACK]
    local = np.stack(markers, axis=1)  # (frames, 19, 3)
    yaw = 0.4 * np.sin(2 * np.pi * 0.2 * t)
    rot = np.zeros((frames, 3, 3))
    rot[:, 0, 0] = rot[:, 1, 1] = np.cos(yaw)
    rot[:, 0, 1], rot[:, 1, 0] = -np.sin(yaw), np.sin(yaw)
    rot[:, 2, 2] = 1.0
    world = np.einsum("fij,fmj->fmi", rot, local) + np.array([0.2, 0.1, 1.0]) + 0.05 * np.sin(t)[:, None, None]
    world += rng.normal(0, 0.0008, world.shape)
    ghost = np.array([0.35, 0.1, 0.95]) + 0.01 * rng.normal(size=(frames, 3)).cumsum(0) / np.sqrt(frames)
    tracks = np.concatenate([world, ghost[:, None]], axis=1).astype(np.float32)
    for m in range(tracks.shape[1]):  # occlusions in runs of 3-15 frames
        for start in rng.choice(frames, size=rng.integers(0, 4), replace=False):
            tracks[start:start + rng.integers(3, 16), m] = np.nan
    positions = _fragment(tracks)
    return Take(positions=positions, names=[f"*{i}" for i in range(positions.shape[1])], rate=rate,
                vendor="mocap_autolabel sample")


def _fragment(tracks: np.ndarray) -> np.ndarray:
    """One slot per run of valid samples, as capture systems store unlabeled data."""
    columns = []
    for m in range(tracks.shape[1]):
        valid = ~np.isnan(tracks[:, m, 0])
        edges = np.diff(np.concatenate([[0], valid.astype(np.int8), [0]]))
        for start, stop in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
            column = np.full((tracks.shape[0], 3), np.nan, dtype=np.float32)
            column[start:stop] = tracks[start:stop, m]
            columns.append(column)
    return np.stack(columns, axis=1)

