"""Rotation helpers, vectorised over leading axes: axis rotations, rotation vectors, quaternions.

Quaternions are ``(w, x, y, z)`` as Blender stores them.
"""

from __future__ import annotations

import numpy as np


def rot_x(angle: np.ndarray) -> np.ndarray:
    """Rotations about x: ``(...,) -> (..., 3, 3)``."""
    c, s = np.cos(angle), np.sin(angle)
    o, z = np.ones_like(c), np.zeros_like(c)
    return np.stack([o, z, z, z, c, -s, z, s, c], axis=-1).reshape(*np.shape(angle), 3, 3)


def rot_y(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    o, z = np.ones_like(c), np.zeros_like(c)
    return np.stack([c, z, s, z, o, z, -s, z, c], axis=-1).reshape(*np.shape(angle), 3, 3)


def rot_z(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    o, z = np.ones_like(c), np.zeros_like(c)
    return np.stack([c, -s, z, s, c, z, z, z, o], axis=-1).reshape(*np.shape(angle), 3, 3)


def rotvec_to_matrix(rotvec: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation vectors ``(..., 3)`` (axis times angle, radians) to matrices ``(..., 3, 3)``."""
    rotvec = np.asarray(rotvec, dtype=float)
    theta = np.linalg.norm(rotvec, axis=-1)[..., None, None]
    k = np.zeros(rotvec.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -rotvec[..., 2], rotvec[..., 1], -rotvec[..., 0]
    k = k - np.swapaxes(k, -1, -2)
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0, np.sin(safe) / safe)
    b = np.where(small, 0.5, (1.0 - np.cos(safe)) / safe**2)
    return np.eye(3) + a * k + b * (k @ k)


def matrix_to_rotvec(matrix: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rotvec_to_matrix` for ``(..., 3, 3)``, via quaternions (stable near pi)."""
    m = np.asarray(matrix, dtype=float)
    w = np.sqrt(np.clip(1.0 + m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2], 0, None)) / 2
    x = np.copysign(np.sqrt(np.clip(1.0 + m[..., 0, 0] - m[..., 1, 1] - m[..., 2, 2], 0, None)) / 2,
                    m[..., 2, 1] - m[..., 1, 2])
    y = np.copysign(np.sqrt(np.clip(1.0 - m[..., 0, 0] + m[..., 1, 1] - m[..., 2, 2], 0, None)) / 2,
                    m[..., 0, 2] - m[..., 2, 0])
    z = np.copysign(np.sqrt(np.clip(1.0 - m[..., 0, 0] - m[..., 1, 1] + m[..., 2, 2], 0, None)) / 2,
                    m[..., 1, 0] - m[..., 0, 1])
    return quaternion_to_rotvec(np.stack([w, x, y, z], axis=-1))


def quaternion_to_rotvec(q: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` (w, x, y, z; either sign) to rotation vectors ``(..., 3)``."""
    q = q * np.where(q[..., :1] < 0, -1.0, 1.0)
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1)
    angle = 2 * np.arctan2(s, q[..., 0])
    return v * np.where(s > 1e-12, angle / np.where(s > 1e-12, s, 1.0), 2.0)[..., None]


def matrix_to_quaternion(matrix: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` to unit quaternions ``(..., 4)`` (w, x, y, z), w >= 0."""
    v = matrix_to_rotvec(matrix)
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    axis = v / np.where(angle > 1e-12, angle, 1.0)
    return np.concatenate([np.cos(angle / 2), axis * np.sin(angle / 2)], axis=-1)


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` (w, x, y, z) to rotation matrices ``(..., 3, 3)``."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)


def continuous_quaternions(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip signs along ``axis`` (time) so that consecutive quaternions lie in the same hemisphere,
    which keeps interpolated keyframes from spinning the long way round."""
    q = np.array(q, copy=True)
    qt = np.moveaxis(q, axis, 0)
    dots = np.sum(qt[1:] * qt[:-1], axis=-1)
    flips = np.cumprod(np.where(dots < 0, -1.0, 1.0), axis=0)
    qt[1:] *= flips[..., None]
    return q


def random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    """``(n, 3, 3)`` rotations drawn uniformly (normalised Gaussian quaternions)."""
    q = rng.standard_normal((n, 4))
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)



def kabsch(model: np.ndarray, observed: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted rigid fit of ``model (K, 3)`` onto each frame of ``observed (F, K, 3)`` (weights
    ``(F, K)``, 0 where a point is unseen, its value then ignored): rotation matrices ``(F, 3, 3)``
    and translations ``(F, 3)`` with ``observed ~ R model + t`` (Kabsch, numpy's batched SVD)."""
    w = weights / np.maximum(weights.sum(axis=1, keepdims=True), 1e-12)
    obs = np.where(weights[..., None] > 0, observed, 0.0)
    mc = w @ model  # (F, 3)
    oc = (w[:, None] @ obs)[:, 0]
    cov = ((obs - oc[:, None]) * w[..., None]).transpose(0, 2, 1) @ (model[None] - mc[:, None])
    u, _, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(u @ vt))
    u[:, :, 2] *= d[:, None]
    rot = u @ vt
    return rot, oc - (rot @ mc[..., None])[..., 0]
