"""Shared parsing of the tab-separated marker tables of TRC and Qualisys TSV files."""

from __future__ import annotations

import io
import re
import warnings

import numpy as np

from ..errors import MocapInputError
from ..take_data import MAX_RATE, MIN_RATE


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
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # numbers beyond float32 become inf: see take.to_metres
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


#: The largest first frame number read from a file (Blender's last frame is 1,048,574).
MAX_FIRST_FRAME = 1_000_000


def marker_count(path: str, stated: list[tuple[str, str | None]], names: list[str], rows: list[str],
                 first_col: int) -> tuple[int, list[str], str]:
    """Resolve how many markers a table holds when its header, its names and its rows disagree.

    Args:
        stated: header fields that state the count, ``(field name, raw text or None)``.
        names: the marker names the header gives.
        rows: the data lines; the first non-empty one tells how many X/Y/Z triplets a row holds.
        first_col: index of the first X column.

    Returns:
        The count to read, the names padded with ``*N`` or cut to it, and a warning line ("" when
        everything agrees). A count that the rows hold exactly wins, then one they have room for,
        the header's first. Without data rows, the names' count is read.

    Raises:
        MocapInputError: the first data row holds fewer markers than every stated count.
    """
    counts: dict[int, list[str]] = {}
    for who, text in [*stated, ("the marker names", str(len(names)))]:
        try:
            value = int(str(text).strip())
        except ValueError:
            continue
        if value >= 0:
            counts.setdefault(value, []).append(who)
    if not counts:
        counts[len(names)] = ["the marker names"]
    first_row = next((r for r in rows if r.strip()), None)
    # No data row: nothing to check a count against, and no marker beyond the names to make up.
    held = len(names) if first_row is None else max(len(first_row.split("\t")) - first_col, 0) // 3
    fitting = [n for n in counts if n <= held]
    exact = [n for n in fitting if n == held]
    claims = ", ".join(f"{value} in {' and '.join(who)}" for value, who in counts.items())
    if not fitting:
        raise MocapInputError(path, f"malformed marker table: the first data row holds {held} markers "
                                    f"but the header states more ({claims})")
    n = (exact or fitting)[0]
    names = names[:n] + [f"*{i}" for i in range(len(names), n)]
    if len(counts) < 2:
        return n, names, ""
    rest = f"; the data rows hold {held}" if first_row is not None else ""
    return n, names, f"marker count disagrees: {claims}{rest}; read {n} (unnamed markers as *N)"


def frame_count_note(field: str, text: str | None, rows: int, numbers: list[str]) -> str:
    """A warning line when the header's frame count ``text`` is neither the number of data
    ``rows`` nor explained by their frame numbers (rows left out, numbering from 0 or 1); else "".

    Args:
        field: the header field's name, for the message.
        numbers: the first and last data rows' frame numbers as text (empty if there are none).
    """
    try:
        stated = int(str(text).strip())
    except ValueError:
        return ""
    explained = {rows}
    try:
        first, last = (int(float(n)) for n in numbers)
        explained |= {last - first + 1, last + 1, last}
    except (ValueError, OverflowError):
        pass
    if stated in explained:
        return ""
    return f"frame count disagrees: {field} says {stated}, the file holds {rows} data rows; read {rows}"


def frame_rate(path: str, *stated: tuple[str, str | None]) -> float:
    """The first of ``stated`` header fields ``(name, text)`` that is a plausible rate in Hz: finite, from
    ``MIN_RATE`` to below ``MAX_RATE`` (any other is damage: see there)."""
    for _, text in stated:
        try:
            rate = float(str(text).strip())
        except ValueError:
            continue
        if np.isfinite(rate) and MIN_RATE <= rate < MAX_RATE:
            return rate
    said = ", ".join(f"{name} {text!r}" for name, text in stated)
    raise MocapInputError(path, f"no usable frame rate ({said}; expected {MIN_RATE:g} to {MAX_RATE:,.0f} frames per "
                                f"second)")


def first_frame_number(rows: list[str]) -> tuple[int, str]:
    """The frame number in the first data row's first column, and a warning line ("" if none).

    A number that is not a whole number from 0 to ``MAX_FIRST_FRAME`` is damage (no capture
    numbers its frames so, and Blender's timeline ends near there): frames are numbered from 1.
    """
    if not rows:
        return 1, ""
    text = rows[0].split("\t", 1)[0].strip()
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if 0 <= value <= MAX_FIRST_FRAME and value == int(value):
        return int(value), ""
    return 1, f"first frame number {text[:20]!r} is not a frame number; frames numbered from 1"
