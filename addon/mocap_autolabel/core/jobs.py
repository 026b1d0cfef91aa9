"""A job on a worker thread that a UI polls: progress messages in, a result or an error out.

Blender-free so it is tested without Blender. The work must not touch Blender data; it may
call ``say(message)`` as often as it likes, and that call raises :class:`Cancelled` once
:meth:`Job.cancel` was asked for, which is how a long job stops between stages.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any


class Cancelled(Exception):
    """The user asked the job to stop."""


class Job:
    """Run ``work(say)`` on a daemon thread.

    Attributes:
        message: the last progress message.
        result: what ``work`` returned, once :attr:`done`.
        error: the exception it raised (a :class:`Cancelled` after a cancel), once :attr:`done`.
    """

    def __init__(self, work: Callable[[Callable[[str], None]], Any]) -> None:
        self._work = work
        self._cancel = threading.Event()
        self._done = threading.Event()
        self._thread: threading.Thread | None = None
        self.message = "starting"
        self.result: Any = None
        self.error: BaseException | None = None
        self.started = 0.0

    def _say(self, message: str) -> None:
        if self._cancel.is_set():
            raise Cancelled(message)
        self.message = message

    def _run(self) -> None:
        try:
            self.result = self._work(self._say)
            if self._cancel.is_set():
                raise Cancelled("after the last stage")
        except BaseException as exc:  # handed to the main thread, which reports it
            self.error = exc
        finally:
            self._done.set()

    def start(self) -> Job:
        self.started = time.perf_counter()
        self._thread = threading.Thread(target=self._run, name="mocap_autolabel job", daemon=True)
        self._thread.start()
        return self

    def cancel(self) -> None:
        self._cancel.set()

    @property
    def cancelled(self) -> bool:
        return isinstance(self.error, Cancelled)

    @property
    def done(self) -> bool:
        return self._done.is_set()

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.started if self.started else 0.0

    def wait(self, timeout: float | None = None) -> bool:
        return self._done.wait(timeout)
