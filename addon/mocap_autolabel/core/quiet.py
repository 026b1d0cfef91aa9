"""Keep a library's own console chatter out of the command line's output.

Blender writes ``Info: Saved copy as ".take.1a2b.partial.blend"`` and its exporters print
``FBX export starting...`` straight to the process's standard output (C ``printf`` and Python
``print``), naming the temporary files our atomic writes rename away. The command line prints
what it wrote itself, so those lines are only noise, and wrong noise: the names do not exist.
Standard library only: the command line imports this before numpy or bpy.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator


def _flush_c_stdio() -> None:
    """Flush C's stdout buffer: with output to a pipe or file it is block-buffered, and what is
    still in it would otherwise come out after the file descriptor is restored."""
    try:
        import ctypes

        libc = ctypes.CDLL(None) if os.name == "posix" else ctypes.cdll.msvcrt
        libc.fflush(None)
    except (OSError, AttributeError):  # no C library to reach: nothing buffered we can flush
        pass


@contextlib.contextmanager
def silenced_stdout() -> Iterator[None]:
    """Send everything written to file descriptor 1 (Python and C alike) to the null device.

    Standard error is left alone, so real errors and warnings still show. Where stdout has no
    file descriptor (an embedding that replaced ``sys.stdout``), only ``sys.stdout`` is redirected.
    """
    sys.stdout.flush()
    try:
        fd = sys.__stdout__.fileno() if sys.__stdout__ is not None else -1
        saved = os.dup(fd) if fd >= 0 else -1
    except (OSError, ValueError, AttributeError):
        fd = saved = -1
    with open(os.devnull, "w") as null:
        if saved < 0:
            with contextlib.redirect_stdout(null):
                yield
            return
        _flush_c_stdio()  # what C printed before belongs on the real output
        os.dup2(null.fileno(), fd)
        try:
            with contextlib.redirect_stdout(null):
                yield
        finally:
            sys.stdout.flush()
            _flush_c_stdio()
            os.dup2(saved, fd)
            os.close(saved)
