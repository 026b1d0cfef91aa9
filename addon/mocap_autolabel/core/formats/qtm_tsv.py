"""Qualisys Track Manager TSV exports (3D data)."""

from __future__ import annotations

import os

from ..errors import MocapInputError
from ..take_data import Take, mark_missing, to_metres, unit_scale
from ._text import first_frame_number, frame_count_note, frame_rate, marker_count, marker_table, read_lines

#: QTM writes its TSV exports in millimetres.
QTM_UNITS = "mm"


def read_qtm_tsv(path: str | os.PathLike) -> Take:
    """Read a QTM 3D TSV export: ``KEY<TAB>value`` header lines, then one row per frame.

    Newer exports have a ``Frame  Time  name X ...`` column line before the data; older ones
    start the data right after the header. Empty fields and (0, 0, 0) are missing samples.
    Where NO_OF_MARKERS, MARKER_NAMES and the data rows disagree, or NO_OF_FRAMES and the
    rows, the rows are read, with a warning.
    """
    path = os.fspath(path)
    lines = read_lines(path)
    header: dict[str, list[str]] = {}
    row = 0
    while row < len(lines):  # header lines: an upper-case key, a tab, values
        key, _, rest = lines[row].partition("\t")
        if not key or key[0].isdigit() or key[0] in "-." or key == "Frame":
            break
        header[key.strip()] = rest.split("\t")
        row += 1
    if "MARKER_NAMES" not in header or "FREQUENCY" not in header:
        raise MocapInputError(path, "not a Qualisys TSV export (no MARKER_NAMES / FREQUENCY header)")
    named = [n.strip() for n in header["MARKER_NAMES"] if n.strip()]
    rate = frame_rate(path, ("FREQUENCY", header["FREQUENCY"][0]))
    first_col = 0
    if row < len(lines) and lines[row].startswith("Frame"):
        columns = lines[row].split("\t")
        first_col = 2 if len(columns) > 1 and columns[1].strip() == "Time" else 1
        row += 1
    rows = lines[row:]
    n_markers, names, note = marker_count(path, [("NO_OF_MARKERS", _first(header, "NO_OF_MARKERS"))], named, rows,
                                          first_col)
    positions = marker_table(path, rows, first_col, n_markers)
    data = [r for r in rows if r.strip()]
    numbers = [r.split("\t", 1)[0] for r in data[:1] + data[-1:]] if first_col else []
    notes = [note, frame_count_note("NO_OF_FRAMES", _first(header, "NO_OF_FRAMES"), len(data), numbers)]
    mark_missing(positions)
    notes.append(to_metres(positions, unit_scale(QTM_UNITS, path)))
    first_frame, note = first_frame_number(data) if first_col else (1, "")
    return Take(
        positions=positions,
        names=names,
        rate=rate,
        first_frame=first_frame,
        source_units=QTM_UNITS,
        source=path,
        vendor="Qualisys (TSV)",
        warnings=[n for n in [*notes, note] if n],
    )


def _first(header: dict[str, list[str]], key: str) -> str | None:
    """The first value of a header line, None if the line is absent."""
    values = header.get(key)
    return values[0] if values else None
