"""Hand poses: the canonical poses of HAND.md and random poses within the joint limits.

Poses here are the 20 joint angles of a pose vector (``pose[6:]``), radians; the global part is
the motion's business.
"""

from __future__ import annotations

import numpy as np

from ..hand.skeleton import FINGERS, JOINT_LIMITS_DEG, JOINT_NAMES

_FIST = {"index": (85, 100, 65), "middle": (88, 100, 65), "ring": (90, 100, 65), "little": (90, 100, 65)}
_RELAXED = {"index": (20, 30, 15), "middle": (25, 35, 20), "ring": (30, 40, 25), "little": (35, 45, 30)}
_STRAIGHT = {f: (0, 0, 0) for f in FINGERS}
_THUMB_ACROSS = (35, 30, 40, 30)


def _pose(thumb: tuple, fingers: dict, abduction: dict | None = None) -> np.ndarray:
    """Joint angles (20,) in radians from degrees: thumb (CMC flex, CMC abd, MCP, IP),
    fingers ``{finger: (MCP, PIP, DIP)}`` and abduction ``{finger: deg}``."""
    abduction = abduction or {}
    out = list(thumb)
    for f in FINGERS:
        mcp, pip, dip = fingers[f]
        out += [mcp, abduction.get(f, 0.0), pip, dip]
    return np.radians(np.array(out, dtype=float))


def _with(base: dict, **fingers: tuple) -> dict:
    return {**base, **fingers}


#: Named poses (HAND.md), joint angles (20,) in radians. The crossed fingers (letter R) and the
#: isolated hooked index (letter X) are the poses that broke published methods.
CANONICAL_POSES: dict[str, np.ndarray] = {
    "flat": _pose((0, 20, 0, 0), _STRAIGHT),
    "spread": _pose((-20, 40, 0, 0), _STRAIGHT, {"index": 15, "middle": 5, "ring": 12, "little": 25}),
    "relaxed": _pose((10, 30, 10, 10), _RELAXED),
    "fist": _pose((30, 20, 50, 40), _FIST),
    "point": _pose((30, 20, 50, 40), _with(_FIST, index=(0, 0, 0))),
    "tip_pinch": _pose((25, 45, 20, 20), _with(_RELAXED, index=(40, 60, 40))),
    "thumbs_up": _pose((-10, 20, 0, 0), _FIST),
    "power_grip": _pose((30, 45, 30, 20), {"index": (45, 65, 40), "middle": (50, 65, 42), "ring": (55, 65, 44),
                                           "little": (60, 65, 45)}),
    "tripod": _pose((25, 45, 20, 20), {"index": (40, 50, 30), "middle": (40, 50, 30), "ring": (50, 60, 40),
                                       "little": (55, 60, 40)}),
    "ok": _pose((25, 45, 20, 20), {"index": (50, 60, 40), "middle": (10, 10, 5), "ring": (10, 10, 5),
                                   "little": (10, 10, 5)}, {"index": 0, "middle": 0, "ring": 8, "little": 18}),
    "letter_a": _pose((0, 15, 10, 0), _FIST),
    "letter_b": _pose((40, 30, 40, 30), _STRAIGHT),
    "letter_l": _pose((-20, 10, 0, 0), _with(_FIST, index=(0, 0, 0))),
    "letter_y": _pose((-20, 30, 0, 0), _with(_FIST, little=(0, 0, 0)), {"little": 25}),
    "letter_v": _pose(_THUMB_ACROSS, _with(_FIST, index=(0, 0, 0), middle=(0, 0, 0)), {"index": 15, "middle": -10}),
    "letter_r": _pose(_THUMB_ACROSS, _with(_FIST, index=(12, 5, 0), middle=(0, 0, 0)), {"index": -15, "middle": 15}),
    "letter_x": _pose(_THUMB_ACROSS, _with(_FIST, index=(10, 90, 60))),
    "three": _pose((-20, 20, 0, 0), _with(_FIST, index=(0, 0, 0), middle=(0, 0, 0)), {"index": 10}),
    "four": _pose(_THUMB_ACROSS, _STRAIGHT, {"index": 8, "ring": 5, "little": 12}),
}

_LO, _HI = np.radians(JOINT_LIMITS_DEG[:, 0]), np.radians(JOINT_LIMITS_DEG[:, 1])
_PIP = np.array([JOINT_NAMES.index(f"{f}_pip") for f in FINGERS])
_DIP = np.array([JOINT_NAMES.index(f"{f}_dip") for f in FINGERS])


def couple_dip(angles: np.ndarray, rng: np.random.Generator | None = None, noise_deg: float = 8.0,
               limits: tuple[np.ndarray, np.ndarray] = (_LO, _HI)) -> np.ndarray:
    """Set every DIP to 2/3 of its PIP (plus Gaussian noise if ``rng``), as tendons do. ``(..., 20)``."""
    out = np.array(angles, dtype=float, copy=True)
    dip = out[..., _PIP] * 2.0 / 3.0
    if rng is not None:
        dip = dip + np.radians(noise_deg) * rng.standard_normal(dip.shape)
    out[..., _DIP] = dip
    return np.clip(out, *limits)


def widened_limits(margin_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Joint limits ``(20,)`` low and high (radians), each range widened by ``margin_deg`` on both sides."""
    m = np.radians(margin_deg)
    return _LO - m, _HI + m


def sample_joint_angles(rng: np.random.Generator, n: int, canonical: float = 0.4, synergy: float = 0.3,
                        jitter_deg: float = 8.0, margin_deg: float = 0.0) -> np.ndarray:
    """``n`` joint-angle vectors ``(n, 20)`` (radians) within the limits.

    A mix of: a canonical pose plus Gaussian jitter (share ``canonical``); a "synergy" pose in
    which all fingers share one flexion level, as real hands mostly move (share ``synergy``);
    and uniform samples over the limits with DIP coupled to PIP (the rest). ``margin_deg`` widens
    every range (training data for hands and gloves that go past the textbook limits).
    """
    lo, hi = widened_limits(margin_deg)
    names = list(CANONICAL_POSES)
    kind = rng.random(n)
    out = np.empty((n, len(JOINT_NAMES)))
    uniform = rng.uniform(lo, hi, size=(n, len(JOINT_NAMES)))
    uniform = couple_dip(uniform, rng, limits=(lo, hi))
    picks = np.array([CANONICAL_POSES[names[i]] for i in rng.integers(len(names), size=n)])
    jitter = np.radians(jitter_deg) * rng.standard_normal((n, len(JOINT_NAMES)))
    level = rng.uniform(0, 1, size=(n, 1))
    syn = lo + (hi - lo) * np.clip(level + 0.12 * rng.standard_normal((n, len(JOINT_NAMES))), 0, 1)
    syn = couple_dip(syn, rng, limits=(lo, hi))
    abd = [JOINT_NAMES.index(f"{f}_mcp_abd") for f in FINGERS]
    syn[:, abd] = rng.uniform(lo[abd], hi[abd], size=(n, len(abd))) * (1 - level)  # a fist is not spread
    out[:] = uniform
    out[kind < canonical + synergy] = syn[kind < canonical + synergy]
    out[kind < canonical] = picks[kind < canonical] + jitter[kind < canonical]
    return np.clip(out, lo, hi)
