"""Smooth hand motion: key poses joined by minimum-jerk transitions at human speeds.

Reaching and grasping movements follow the minimum-jerk profile (Flash & Hogan 1985); finger
joints move at roughly 60-300 deg/s in everyday tasks, the wrist at up to about 1 m/s. The hand
wanders inside a capture volume and turns freely, so that a labeler trained on these takes sees
every orientation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..hand.skeleton import N_DOF
from ..rotations import matrix_to_rotvec, random_rotations, rotvec_to_matrix
from .poses import sample_joint_angles


@dataclass(frozen=True)
class MotionConfig:
    """Speeds and ranges of the synthetic motion (SI units: m, s, degrees where named)."""

    volume_min: tuple[float, float, float] = (-0.5, -0.5, 0.8)  # m, the capture volume the wrist stays in
    volume_max: tuple[float, float, float] = (0.5, 0.5, 1.4)
    max_tilt_deg: float = 180.0  # how far the back of the hand may turn from facing up (180: any way)
    joint_speed_deg: tuple[float, float] = (60.0, 300.0)  # peak-ish speed of the fastest joint
    turn_deg: float = 60.0  # largest orientation change between key poses
    turn_speed_deg: tuple[float, float] = (45.0, 180.0)
    step_m: float = 0.12  # SD of the wrist's move between key poses
    move_speed: tuple[float, float] = (0.1, 0.8)  # m/s
    hold_probability: float = 0.3
    hold_s: tuple[float, float] = (0.1, 0.6)
    min_transition_s: float = 0.2


def min_jerk(tau: np.ndarray) -> np.ndarray:
    """The minimum-jerk profile ``10t^3 - 15t^4 + 6t^5`` on ``[0, 1]``."""
    return tau**3 * (10 - 15 * tau + 6 * tau**2)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A rotation matrix drawn uniformly (a normalised Gaussian quaternion)."""
    return random_rotations(rng, 1)[0]


def _turn(rng: np.random.Generator, rot: np.ndarray, cfg: MotionConfig, tries: int = 20) -> np.ndarray:
    """A random turn (rotation vector, world frame, applied on the right) of at most ``turn_deg``
    that keeps the back of the hand within ``max_tilt_deg`` of facing up."""
    cos_max = np.cos(np.radians(cfg.max_tilt_deg))
    for _ in range(tries):
        axis = rng.standard_normal(3)
        turn = np.radians(rng.uniform(0, cfg.turn_deg)) * axis / np.linalg.norm(axis)
        if (rot @ rotvec_to_matrix(turn))[2, 2] >= cos_max - 1e-9:
            return turn
    # Nothing drawn fits: turn the back of the hand straight towards up instead.
    dorsal = rot[:, 2]
    axis_world = np.cross(dorsal, [0.0, 0.0, 1.0])
    norm = np.linalg.norm(axis_world)
    if norm < 1e-9:
        return np.zeros(3)
    angle = min(np.radians(cfg.turn_deg), np.arccos(np.clip(dorsal[2], -1, 1)))
    return rot.T @ (axis_world / norm * angle)


def _upright(rng: np.random.Generator, cfg: MotionConfig) -> np.ndarray:
    """A random orientation with the back of the hand within ``max_tilt_deg`` of up, any heading."""
    cos_tilt = rng.uniform(np.cos(np.radians(cfg.max_tilt_deg)), 1.0)
    az = rng.uniform(0, 2 * np.pi)
    tilt = np.arccos(cos_tilt) * np.array([np.cos(az), np.sin(az), 0.0])
    return rotvec_to_matrix(tilt) @ rotvec_to_matrix(np.array([0.0, 0.0, rng.uniform(0, 2 * np.pi)]))


def generate_motion(rng: np.random.Generator, frames: int, rate: float = 120.0,
                    config: MotionConfig | None = None) -> np.ndarray:
    """A smooth random hand motion.

    Args:
        rng: the random source (the only one used).
        frames: number of frames.
        rate: frames per second.
        config: speeds and ranges.

    Returns:
        ``(frames, 26)`` pose vectors (global rotation vector, wrist position in metres, joint
        angles in radians), every joint within its limits.
    """
    cfg = config or MotionConfig()
    lo, hi = np.array(cfg.volume_min), np.array(cfg.volume_max)
    out = np.empty((frames, N_DOF))
    n_keys = max(4, int(frames / rate * 3) + 4)  # more than enough: transitions last >= 0.2 s
    angles = sample_joint_angles(rng, n_keys)
    rot = random_rotation(rng) if cfg.max_tilt_deg >= 180 else _upright(rng, cfg)
    pos = rng.uniform(lo, hi)
    f, k = 0, 0
    while f < frames:
        k = min(k + 1, n_keys - 1)
        a0, a1 = angles[k - 1], angles[k]
        turn = _turn(rng, rot, cfg)
        pos1 = np.clip(pos + cfg.step_m * rng.standard_normal(3), lo, hi)
        duration = max(
            cfg.min_transition_s,
            np.degrees(np.abs(a1 - a0).max()) / rng.uniform(*cfg.joint_speed_deg),
            np.degrees(np.linalg.norm(turn)) / rng.uniform(*cfg.turn_speed_deg),
            np.linalg.norm(pos1 - pos) / rng.uniform(*cfg.move_speed),
        )
        hold = rng.uniform(*cfg.hold_s) if rng.random() < cfg.hold_probability else 0.0
        n = max(1, int(round(duration * rate)))
        n_hold = int(round(hold * rate))
        s = min_jerk(np.arange(1, n + 1) / n)[:, None]
        seg = np.empty((n + n_hold, N_DOF))
        seg[:n, 6:] = a0 + (a1 - a0) * s
        seg[:n, 3:6] = pos + (pos1 - pos) * s
        seg[:n, 0:3] = matrix_to_rotvec(rot @ rotvec_to_matrix(turn * s))
        seg[n:] = seg[n - 1]
        take = min(len(seg), frames - f)
        out[f:f + take] = seg[:take]
        f += take
        rot, pos = rot @ rotvec_to_matrix(turn), pos1
        if k == n_keys - 1:  # ran out of keys (only with absurdly slow settings): draw more
            angles = np.concatenate([angles[-1:], sample_joint_angles(rng, n_keys)])
            k = 0
    return out
