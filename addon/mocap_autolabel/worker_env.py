"""Environment that worker processes start with: their share of this machine's cores.

Used by both ways of running takes in other processes, ``batch --jobs`` (:mod:`.batch`'s process
pool) and a local Dask cluster (:mod:`.farm`). Only the standard library.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator


def thread_caps(workers: int, threads: int | None = None) -> dict[str, str]:
    """Environment variables that give each of ``workers`` processes sharing this machine's cores
    ``threads`` threads (default: its share) for onnxruntime, OpenMP and OpenBLAS; read as those
    start, so set before a worker process starts."""
    n = str(threads or max(1, (os.cpu_count() or 1) // workers))
    return dict.fromkeys(("MOCAP_AUTOLABEL_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS"), n)


@contextlib.contextmanager
def environ(env: dict[str, str]) -> Iterator[None]:
    """``env`` in ``os.environ`` for a while (a process started meanwhile inherits it)."""
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
