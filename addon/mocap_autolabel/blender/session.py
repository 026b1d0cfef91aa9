"""What a Blender session keeps between review operations, and nothing that must be saved.

The per-frame scores of a take (a few seconds of network time for 10,000 frames) and the take
read back from the scene are kept here, so that a re-solve after a correction costs only the
temporal decision. Everything else lives in the .blend (see ``review.py``). Entries are keyed
by the take collection's session id, checked against what they were made from, and dropped
when a file is loaded and when the add-on is disabled.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.cache import RunCache
from ..core.labelers.base import RememberingLabeler
from ..core.take import Take


@dataclass
class TakeSession:
    take: Take | None = None
    take_key: tuple = ()
    labelers: dict = field(default_factory=dict)
    classes: tuple[str, np.ndarray] | None = None  # (state token, marker classes)
    cache: RunCache = field(default_factory=RunCache)  # the labeling's results kept between re-solves


_SESSIONS: dict[int, TakeSession] = {}


def session(take_coll) -> TakeSession:
    """The cache of one take collection."""
    return _SESSIONS.setdefault(int(take_coll.session_uid), TakeSession())


def labeler(take_coll, method: str, layout, make) -> RememberingLabeler:
    """The take's remembering labeler for (method, layout), made with ``make()`` the first time."""
    cache = session(take_coll).labelers
    key = (method, layout.name, tuple(layout.names))
    if key not in cache:
        cache[key] = RememberingLabeler(make())
    return cache[key]


def forget_all(*_args) -> None:
    """Drop every cache (a file was loaded, or the add-on is going away)."""
    _SESSIONS.clear()
