"""Qualisys Track Manager TSV exports (3D data)."""

from __future__ import annotations

import os

from ..errors import MocapInputError
from ..take import Take, mark_missing, unit_scale
from ._text import marker_table, read_lines

#: QTM writes its TSV exports in millimetres.
QTM_UNITS = "mm"


def read_qtm_tsv(path: str | os.PathLike) -> Take:
    """Read a QTM 3D TSV export: ``KEY<TAB>value`` header lines, then one row per frame.

    Newer exports have a ``Frame  Time  name X ...`` column line before the data; older ones
    start the data right after the header. Empty fields and (0, 0, 0) are missing samples.
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
    names = [n.strip() for n in header["MARKER_NAMES"] if n.strip()]
    try:
        rate = float(header["FREQUENCY"][0])
    except ValueError:
        raise MocapInputError(path, f"FREQUENCY is not a number: {header['FREQUENCY'][0]!r}") from None
    first_col = 0
    if row < len(lines) and lines[row].startswith("Frame"):
        columns = lines[row].split("\t")
        first_col = 2 if len(columns) > 1 and columns[1].strip() == "Time" else 1
        row += 1
    data = lines[row:]
    positions = marker_table(path, data, first_col, len(names))
    mark_missing(positions)
    positions *= unit_scale(QTM_UNITS, path)
    first_frame = int(data[0].split("\t", 1)[0]) if first_col and data else 1
    return Take(
        positions=positions,
        names=names,
        rate=rate,
        first_frame=first_frame,
        source_units=QTM_UNITS,
        source=path,
        vendor="Qualisys (TSV)",
    )
