"""One exception type for bad input, so every front end can print one clear line."""

from __future__ import annotations

import os


class MocapInputError(Exception):
    """A file (or other input) cannot be used; the message names the file and the problem.

    Front ends (CLI, Blender operators) catch this and show ``str(error)`` as one line,
    never a traceback.
    """

    def __init__(self, path: str | os.PathLike | None, problem: str):
        self.path = None if path is None else os.fspath(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}" if self.path else problem)
