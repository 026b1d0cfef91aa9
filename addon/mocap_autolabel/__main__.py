"""``python -m mocap_autolabel ...``: the command line."""

import os
import sys


def _reuse_freed_memory() -> None:
    """Ask glibc to keep freed memory for the process's next arrays instead of handing it back.

    Labeling allocates and frees arrays of tens of megabytes stage after stage; by default glibc
    maps each anew and unmaps it when freed, and the kernel zeroes every page again: a fifth of a
    two-hand take's time went to the system (10,000 frames: 1.7 s of 7.1 s wall; 1.0 s and 6.6 s
    with this). A process setting, so only for the command line's own process; Linux with glibc only.
    """
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        m_trim_threshold, m_top_pad, m_mmap_threshold = -1, -2, -3
        libc.mallopt(m_mmap_threshold, 32 * 2 ** 20)  # glibc's most: larger arrays are mapped anyway
        libc.mallopt(m_trim_threshold, 2 ** 31 - 1)
        libc.mallopt(m_top_pad, 64 * 2 ** 20)
    except (OSError, AttributeError):  # another C library (musl): its defaults
        pass


_reuse_freed_memory()

from .cli import main  # noqa: E402 (after the allocator's settings, before any array)

try:
    code = main()
    sys.stdout.flush()
except BrokenPipeError:  # output piped into head/less that closed early: not an error
    os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    code = 0
sys.exit(code)
