"""Shared parsing of the tab-separated marker tables of TRC and Qualisys TSV files."""

from __future__ import annotations

import io
import re

import numpy as np

from ..errors import MocapInputError


def read_lines(path: str) -> list[str]:
    """The file's lines without line endings; a clear error for binary or unreadable files."""
    try:
        with open(path, encoding="utf-8-sig", errors="strict") as fh:
            return fh.read().splitlines()
    except UnicodeDecodeError:
        raise MocapInputError(path, "not a text file (cannot be decoded as UTF-8)") from None


def marker_table(path: str, rows: list[str], first_col: int, n_markers: int) -> np.ndarray:
    """Parse tab-separated rows into float32 ``(frames, n_markers, 3)``; empty fields -> NaN.

    Args:
        rows: the data lines only.
        first_col: index of the first X column (after frame/time columns).
        n_markers: number of X/Y/Z triplets to read from each row.
    """
    rows = [r for r in rows if r.strip()]
    n_cols = first_col + 3 * n_markers
    if not rows:
        return np.empty((0, n_markers, 3), dtype=np.float32)
    try:
        table = np.genfromtxt(io.StringIO("\n".join(rows)), delimiter="\t", usecols=range(n_cols),
                              dtype=np.float32, filling_values=np.nan, invalid_raise=True, ndmin=2)
    except (ValueError, IndexError) as exc:
        # numpy says "Some errors were detected !" and then which line: say that line (a cut-off file).
        lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
        bad = re.match(r"Line #(\d+) \(got (\d+) columns instead of (\d+)\)", lines[-1]) if lines else None
        if bad:
            row, got, want = bad.groups()
            raise MocapInputError(path, f"malformed marker table: data row {row} has {got} columns instead of "
                                        f"{want} (is the file cut off or damaged?)") from None
        raise MocapInputError(path, f"malformed marker table ({lines[0] if lines else exc})") from None
    return table[:, first_col:].reshape(len(table), n_markers, 3)
