"""How many threads one process's side-by-side work may use (ONNX batches, chunks of IK frames)."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

T = TypeVar("T")
R = TypeVar("R")

#: The most threads one process uses, however many cores it sees.
MOST_THREADS = 8


def worker_threads() -> int:
    """The cores, capped by ``MOCAP_AUTOLABEL_THREADS`` where several processes share them (``batch
    --jobs`` and a farm set it for their workers), at most :data:`MOST_THREADS`. Work is never cut
    by this number, only spread over it: results never depend on it."""
    return max(1, min(int(os.environ.get("MOCAP_AUTOLABEL_THREADS") or os.cpu_count() or 1), MOST_THREADS))


def side_by_side(work: Callable[[T], R], items: Sequence[T], threads: int | None = None) -> list[R]:
    """``[work(item) for item in items]``, the items spread over ``threads`` worker threads (default
    :func:`worker_threads`; one: in this thread). For work that releases the GIL (onnxruntime,
    numpy's loops) on pieces cut without regard to the thread count."""
    threads = min(worker_threads() if threads is None else threads, len(items))
    if threads <= 1:
        return [work(item) for item in items]
    with ThreadPoolExecutor(threads) as pool:
        return list(pool.map(work, items))
