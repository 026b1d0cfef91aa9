"""File formats: each module reads a file into a Take (and C3D also writes one)."""

from __future__ import annotations

import os
from collections.abc import Callable

from ..errors import MocapInputError
from ..take_data import Take

#: File extensions the readers accept, lower case.
EXTENSIONS = (".c3d", ".trc", ".tsv")


def reader_for(path: str | os.PathLike) -> Callable[[str], Take]:
    """The reader function for ``path``, chosen by its extension."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext == ".c3d":
        from .c3d import read_c3d

        return read_c3d
    if ext == ".trc":
        from .trc import read_trc

        return read_trc
    if ext == ".tsv":
        from .qtm_tsv import read_qtm_tsv

        return read_qtm_tsv
    raise MocapInputError(path, f"unknown file type {ext or '(none)'!r}; expected one of {', '.join(EXTENSIONS)}")
