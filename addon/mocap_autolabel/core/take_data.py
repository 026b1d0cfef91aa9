"""The Take data class and the unit conversions the readers share.

It sits below the readers (:mod:`.formats`, which build Takes) and :mod:`.take`, which re-exports
everything here and dispatches reading a file by its extension.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field

import numpy as np

from .errors import MocapInputError

#: Metres per source unit; C3D's POINT:UNITS and TRC's Units use these spellings.
UNIT_SCALE = {"mm": 1e-3, "cm": 1e-2, "dm": 1e-1, "m": 1.0, "in": 0.0254, "ft": 0.3048}

#: Names the capture systems give to points they have not labeled: ``*12``, ``M012``, empty.
UNLABELED_NAME = re.compile(r"^(\*\d+|M\d{3,}|Unlabeled\s*\d*|)$", re.IGNORECASE)

#: Frame rates at or above this (frames per second) are damage, not a capture system's.
MAX_RATE = 1e6
#: Frame rates below this are damage too: no marker capture records less than a frame a second, and a
#: subnormal rate (1e-320 Hz) is 0 as a C3D's float32, a file that no reader (this one included) accepts.
MIN_RATE = 1.0

#: A coordinate further than this (metres) is damage, not a position: a unit mistake (metres read
#: as millimetres) stays under 1e4 m, and beyond 1e9 the squares of distances overflow float32.
DAMAGED_DISTANCE_M = 1e6


@dataclass
class Take:
    """Marker positions of one capture.

    Attributes:
        positions: float32 array ``(frames, points, 3)`` in metres; NaN where a sample is missing.
        names: one name per point slot (``len(names) == points``); unlabeled slots are ``*N``.
        rate: frames per second (may be non-integer, e.g. 69.993).
        first_frame: frame number of ``positions[0]`` as the file counts frames.
        source_units: the unit the file stored positions in (``"mm"``, ``"m"``...).
        residuals: float32 ``(frames, points)`` in metres, or None when the format has none;
            NaN where the sample is missing.
        source: path of the file the take came from ("" if built in memory).
        vendor: capture system or writer of the file, as far as the file says.
        warnings: things a user should know that did not stop the read.
        filled: bool ``(frames, points)`` or None: samples computed by a gap fill, not measured
            (:mod:`.fill`; a C3D marks them with residual 0 and no camera bits). None: not known.
    """

    positions: np.ndarray
    names: list[str]
    rate: float
    first_frame: int = 1
    source_units: str = "mm"
    residuals: np.ndarray | None = None
    source: str = ""
    vendor: str = "unknown"
    warnings: list[str] = field(default_factory=list)
    filled: np.ndarray | None = None

    def __post_init__(self) -> None:
        p = self.positions
        if p.ndim != 3 or p.shape[2] != 3:
            raise ValueError(f"positions must be (frames, points, 3), got {p.shape}")
        if len(self.names) != p.shape[1]:
            raise ValueError(f"{len(self.names)} names for {p.shape[1]} points")
        if self.residuals is not None and self.residuals.shape != p.shape[:2]:
            raise ValueError(f"residuals {self.residuals.shape} do not match positions {p.shape}")
        if self.filled is not None and self.filled.shape != p.shape[:2]:
            raise ValueError(f"filled {self.filled.shape} does not match positions {p.shape}")
        if not (self.rate > 0 and np.isfinite(self.rate)):
            raise ValueError(f"rate must be a positive number of frames per second, got {self.rate}")

    @property
    def n_frames(self) -> int:
        return int(self.positions.shape[0])

    @property
    def n_points(self) -> int:
        return int(self.positions.shape[1])

    @property
    def valid(self) -> np.ndarray:
        """bool ``(frames, points)``: True where a sample exists."""
        return ~np.isnan(self.positions[..., 0])

    @property
    def missing_fraction(self) -> float:
        """Share of (frame, point) samples that are missing, 0 for an empty take."""
        n = self.n_frames * self.n_points
        return float(1.0 - self.valid.sum() / n) if n else 0.0

    @property
    def unlabeled(self) -> np.ndarray:
        """bool ``(points,)``: True for slots whose name is a capture system's placeholder."""
        return np.array([bool(UNLABELED_NAME.match(n.strip())) for n in self.names], dtype=bool)

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame."""
        return max(self.n_frames - 1, 0) / self.rate

    def summary(self) -> dict:
        """A plain dict describing the take, used by ``info`` and reports."""
        n_unl = int(self.unlabeled.sum())
        return {
            "file": self.source,
            "vendor": self.vendor,
            "points": self.n_points,
            "frames": self.n_frames,
            "rate": self.rate,
            "first_frame": self.first_frame,
            "duration_s": round(self.duration, 3),
            "units": self.source_units,
            "missing_percent": round(100.0 * self.missing_fraction, 2),
            "labeled_points": self.n_points - n_unl,
            "unlabeled_points": n_unl,
            "has_residuals": self.residuals is not None,
            "filled_samples": 0 if self.filled is None else int(self.filled.sum()),
            "warnings": list(self.warnings),
        }


def unit_scale(units: str, path: str | os.PathLike | None = None) -> float:
    """Metres per ``units``; raises MocapInputError naming ``path`` for an unknown unit."""
    key = units.strip().lower()
    if key in ("millimeters", "millimetres", "millimeter"):
        key = "mm"
    elif key in ("meters", "metres", "meter"):
        key = "m"
    try:
        return UNIT_SCALE[key]
    except KeyError:
        raise MocapInputError(path, f"unknown position unit {units!r} (expected one of {sorted(UNIT_SCALE)})") from None


def mark_missing(positions: np.ndarray, residuals: np.ndarray | None = None) -> np.ndarray:
    """Set to NaN, in place, every sample that a file marks as missing.

    Real files use three conventions: a negative residual, NaN coordinates, and an exact
    (0, 0, 0) position. Returns the bool ``(frames, points)`` mask of missing samples.

    Args:
        positions: float ``(frames, points, 3)``, modified in place.
        residuals: float ``(frames, points)`` or None; negative means missing.
    """
    x, y, z = positions[..., 0], positions[..., 1], positions[..., 2]
    # Axis by axis: ``.any(axis=2)`` over a length-3 axis is several times slower (numpy reduces
    # such short rows one by one), a third of reading a 65,535 x 50 C3D.
    missing = np.isnan(x) | np.isnan(y) | np.isnan(z)
    missing |= (x == 0) & (y == 0) & (z == 0)  # exact (0, 0, 0)
    if residuals is not None:
        missing |= residuals < 0
    positions[missing] = np.nan
    if residuals is not None:
        residuals[missing] = np.nan
    return missing


def to_metres(positions: np.ndarray, scale: float, residuals: np.ndarray | None = None) -> str:
    """Convert, in place, source units to metres; samples that are damage become missing.

    A damaged file (a flipped exponent bit, a huge scale) holds infinite or absurdly large
    coordinates (beyond ``DAMAGED_DISTANCE_M``): they become gaps, not positions that overflow
    later arithmetic, and no numpy warning reaches the terminal.

    Args:
        positions: float ``(frames, points, 3)`` in source units, modified in place.
        scale: metres per source unit.
        residuals: float ``(frames, points)`` in source units or None; scaled too, NaN where a
            sample is dropped.

    Returns:
        One warning line naming how many samples were dropped, or "" when none was.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        positions *= scale
        if residuals is not None:
            residuals *= scale
        far = np.abs(positions) > DAMAGED_DISTANCE_M  # inf too; NaN compares False
        damaged = far[..., 0] | far[..., 1] | far[..., 2]
    count = int(damaged.sum())
    if not count:
        return ""
    positions[damaged] = np.nan
    if residuals is not None:
        residuals[damaged] = np.nan
    return (f"{count} damaged sample{'s' if count > 1 else ''} (infinite, or more than "
            f"{DAMAGED_DISTANCE_M:g} m from the origin) read as missing")
