"""The Take: one capture's marker positions, the unit everything else works on; reading a file into one.

The data class and the unit conversions live in :mod:`.take_data`, below the readers of
:mod:`.formats`; they are re-exported here.
"""

from __future__ import annotations

import os

import numpy as np

from .errors import MocapInputError
from .formats import reader_for
from .take_data import (
    DAMAGED_DISTANCE_M,
    MAX_RATE,
    MIN_RATE,
    UNIT_SCALE,
    UNLABELED_NAME,
    Take,
    mark_missing,
    to_metres,
    unit_scale,
)

__all__ = ["ABSURD_DISTANCE_M", "DAMAGED_DISTANCE_M", "MAX_RATE", "MIN_RATE", "UNIT_SCALE", "UNLABELED_NAME", "Take",
           "check_plausible", "mark_missing", "read_take", "to_metres", "unit_scale"]

#: A marker further than this from the origin (metres) means wrong units: no capture volume is that big.
ABSURD_DISTANCE_M = 100.0


def check_plausible(take: Take) -> None:
    """Add a warning to ``take`` when its positions are absurd for a capture volume."""
    if take.positions.size == 0:
        return
    if np.isnan(take.positions[..., 0]).all():
        take.warnings.append("every sample is missing")
        return
    # Reductions only: no copy of the positions (they can be hundreds of MB).
    extent = float(max(np.nanmax(take.positions), -np.nanmin(take.positions)))
    if extent > ABSURD_DISTANCE_M:
        take.warnings.append(
            f"markers reach {extent:.0f} m from the origin: the file's unit "
            f"({take.source_units!r}) is probably wrong"
        )


def read_take(path: str | os.PathLike) -> Take:
    """Read a C3D, TRC or Qualisys TSV file into a Take (positions in metres).

    Raises:
        MocapInputError: the file is missing, unreadable, of an unknown type or damaged.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise MocapInputError(path, "no such file")
    if os.path.isdir(path):
        raise MocapInputError(path, "is a folder, not a take file")
    take = reader_for(path)(path)
    check_plausible(take)
    return take
