"""How many threads one process's side-by-side work may use (ONNX batches, chunks of IK frames)."""

from __future__ import annotations

import os

#: The most threads one process uses, however many cores it sees.
MOST_THREADS = 8


def worker_threads() -> int:
    """The cores, capped by ``MOCAP_AUTOLABEL_THREADS`` where several processes share them (``batch
    --jobs`` and a farm set it for their workers), at most :data:`MOST_THREADS`. Work is never cut
    by this number, only spread over it: results never depend on it."""
    return max(1, min(int(os.environ.get("MOCAP_AUTOLABEL_THREADS") or os.cpu_count() or 1), MOST_THREADS))
