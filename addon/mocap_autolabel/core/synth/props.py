"""A rigid prop held in a synthetic hand: 3-6 markers whose distances never change, near the
fingers, turning in the hand as it is handled.

The prop rides on the hand's overall motion (the rotation that best carries the hand's markers
from the first frame to each frame, Kabsch) at 5-8 cm from the hand's centre on the palm side,
and turns against the hand by up to ``wobble`` radians with a period of a few seconds, so that it
is rigid in itself but not with the hand. Its markers get the noise of the take and gaps of their own.
"""

from __future__ import annotations

import numpy as np


def _rotation(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(F, 3, 3)`` about the unit ``axis`` by ``angle`` ``(F,)`` radians (Rodrigues)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3)[None] + s * k[None] + (1 - c) * (k @ k)[None]


def hand_rotations(markers: np.ndarray) -> np.ndarray:
    """``(F, 3, 3)``: per frame, the rotation that best carries the hand's markers ``(F, M, 3)`` of
    the first frame (about their centre) onto that frame's (Kabsch)."""
    ref = markers[0] - markers[0].mean(axis=0)
    x = markers - markers.mean(axis=1, keepdims=True)
    u, _, vt = np.linalg.svd(np.einsum("mi,fmj->fij", ref, x))
    d = np.sign(np.linalg.det(np.einsum("fij,fjk->fik", u, vt)))
    fix = np.ones((len(markers), 3))
    fix[:, 2] = d
    return np.einsum("fji,fj,fkj->fik", vt, fix, u)  # R = V diag(1, 1, d) U^T


def hold_prop(markers: np.ndarray, rate: float, rng: np.random.Generator, n: int = 4,
              noise_sd: float = 0.001, wobble: float = 0.35, gap_share: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """A prop of ``n`` markers held by the hand whose true markers are ``markers`` ``(F, M, 3)`` metres.

    Returns:
        ``(observed, true)``: ``(F, n, 3)`` metres; observed has noise (SD ``noise_sd`` per axis)
        and NaN gaps (about ``gap_share`` of the samples, in runs of 5-40 frames).
    """
    frames = len(markers)
    if not 3 <= n <= 6:
        raise ValueError(f"a prop has 3 to 6 markers, not {n}")
    # The shape: markers spread over a small object, at least 15 mm apart.
    while True:
        shape = rng.uniform(-1, 1, (n, 3)) * np.array([0.035, 0.025, 0.015])
        d = np.linalg.norm(shape[:, None] - shape[None], axis=2)
        if d[np.triu_indices(n, 1)].min() > 0.015:
            break
    ref = markers[0] - markers[0].mean(axis=0)
    normal = np.linalg.svd(ref, full_matrices=False)[2][2]  # the hand's thinnest axis: across the palm
    offset = normal * rng.choice([-1.0, 1.0]) * rng.uniform(0.05, 0.08)
    t = np.arange(frames) / rate
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    turn = _rotation(axis, wobble * np.sin(2 * np.pi * t / rng.uniform(2.0, 4.0) + rng.uniform(0, 2 * np.pi)))
    local = offset[None, None] + np.einsum("fij,nj->fni", turn, shape)  # (F, n, 3) in the first frame's axes
    true = markers.mean(axis=1)[:, None] + np.einsum("fij,fnj->fni", hand_rotations(markers), local)
    observed = true + rng.normal(0.0, noise_sd, true.shape)
    for k in range(n):
        hidden = 0
        while hidden < gap_share * frames:
            length = int(rng.integers(5, 41))
            start = int(rng.integers(0, max(1, frames - length)))
            observed[start:start + length, k] = np.nan
            hidden += length
    return observed, true


__all__ = ["hand_rotations", "hold_prop"]
