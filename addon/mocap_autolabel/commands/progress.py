"""The progress bar of the long commands (``label``, ``solve``, ``fill``) on stderr."""

from __future__ import annotations

import sys


class _ProgressBar:
    """Progress of one long command (``label``, ``solve``) on stderr: stage, share done, seconds.

    Drawn on a terminal, or anywhere when asked (``--progress``), never with ``--quiet``; it
    appears only once the work has run for :attr:`DELAY` seconds, so short takes print nothing
    extra. On a terminal one line is redrawn in place and wiped at the end (stdout keeps only the
    results); elsewhere (a log) a line is written per stage and per tenth of the work.

    It is a progress callback of the core (``bar(message, share)``: the stage and the share done,
    0 to 1); ``bar(message)`` and ``bar.stage(message)`` start a stage of the command itself.
    """

    DELAY = 1.0  # seconds before anything is drawn
    WIDTH = 24

    def __init__(self, shown: bool, stream=None) -> None:
        import time

        self.stream = stream or sys.stderr
        self.shown = shown
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.clock = time.perf_counter
        self.start = self.clock()
        self.message, self.done = "", None
        self.drawn_at = -1.0
        self.logged: tuple[str, int] | None = None
        self.visible = False

    @classmethod
    def for_args(cls, args) -> _ProgressBar:
        return cls(not args.quiet and (args.progress or sys.stderr.isatty()))

    def __call__(self, message: str, share: float | None = None) -> None:
        self.message = message
        if share is not None:
            self.done = share
        self._draw(force=True)

    def stage(self, message: str, share: float | None = None) -> None:
        """A new stage whose share done is ``share`` (None: not known, only the seconds show)."""
        self.done = None
        self(message, share)

    def share(self, share: float) -> None:
        self.done = share
        self._draw()

    def _draw(self, force: bool = False) -> None:
        now = self.clock()
        elapsed = now - self.start
        if not self.shown or elapsed < self.DELAY or (not force and now - self.drawn_at < 0.1):
            return
        self.drawn_at = now
        part = min(max(self.done or 0.0, 0.0), 1.0)
        filled = int(self.WIDTH * part)
        bar = f"[{'#' * filled}{'.' * (self.WIDTH - filled)}] {100 * part:3.0f} %" if self.done is not None else ""
        line = f"{bar}  {self.message}  {elapsed:.1f} s".strip()
        if self.tty:
            self.stream.write("\r" + line[:119].ljust(119))
            self.visible = True
        else:
            key = (self.message, int(10 * part))
            if key == self.logged:
                return
            self.logged = key
            self.stream.write(line + "\n")
        self.stream.flush()

    def close(self) -> None:
        """Wipe the bar's line (a terminal) so that the results start on a clean line."""
        if self.visible:
            self.stream.write("\r" + " " * 119 + "\r")
            self.stream.flush()
            self.visible = False
