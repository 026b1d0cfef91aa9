"""A cache scoped to its owner: a Blender session's re-solves, one batch run, one CLI command.

The pipeline's per-take results (the crossings of trajectories, the hands found, rigid groups, a
take's per-hand scores, fitted range-of-motion labelers, loaded ONNX models) cost seconds and are
asked for again when a reviewer re-solves or a batch labels many takes with one layout. They are
kept here, on an object the caller holds and drops, never in a module. Keys compare for equality:
a take is known by its positions' values (:class:`TakeKey`), not by a hash alone.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Any

import numpy as np

#: Entries kept per kind at most (a re-solve labels the same take again; batch takes rarely repeat).
REMEMBERED = 4


class TakeKey:
    """A take's positions and rate as a dictionary key: equal when the values are (NaN equal to NaN).
    It holds a reference to the positions, which the pipeline never changes in place."""

    __slots__ = ("positions", "rate", "_hash")

    def __init__(self, positions: np.ndarray, rate: float) -> None:
        self.positions, self.rate = positions, float(rate)
        self._hash = hash((positions.shape, self.rate, positions.tobytes()))

    def __hash__(self) -> int:
        return self._hash

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, TakeKey):
            return NotImplemented
        if other is self or other.positions is self.positions and other.rate == self.rate:
            return True
        return (self._hash == other._hash and self.rate == other.rate
                and self.positions.shape == other.positions.shape
                and np.array_equal(self.positions, other.positions, equal_nan=True))


class RunCache:
    """Results remembered for one owner, by kind, each kind keeping its last :data:`REMEMBERED` keys."""

    def __init__(self, remembered: int = REMEMBERED) -> None:
        self.remembered = remembered
        self._kinds: dict[str, dict[Hashable, Any]] = {}
        self._keys: dict[int, TakeKey] = {}

    def take_key(self, take) -> TakeKey:
        """The key of ``take``'s positions (made once per positions array while it is alive)."""
        key = self._keys.get(id(take.positions))
        if key is None or key.positions is not take.positions:
            key = TakeKey(take.positions, take.rate)
            if len(self._keys) >= 4 * self.remembered:
                self._keys.clear()
            self._keys[id(take.positions)] = key
        return key

    def remember(self, kind: str, key: Hashable, make: Callable[[], Any]) -> Any:
        """``make()`` for ``key``, kept among the last few of ``kind``."""
        entries = self._kinds.setdefault(kind, {})
        if key not in entries:
            while len(entries) >= self.remembered:
                entries.pop(next(iter(entries)))
            entries[key] = make()
        return entries[key]

    def entries(self, kind: str) -> dict[Hashable, Any]:
        """The live dictionary of ``kind`` (for callers that keep lists under one key)."""
        return self._kinds.setdefault(kind, {})
