"""TRC files (Motion Analysis / OpenSim marker trajectories), as in the Han et al. data."""

from __future__ import annotations

import os

from ..errors import MocapInputError
from ..take_data import Take, mark_missing, to_metres, unit_scale
from ._text import first_frame_number, frame_count_note, frame_rate, marker_count, marker_table, read_lines


def read_trc(path: str | os.PathLike) -> Take:
    """Read a TRC file: a 5-line header (rate, units, marker names), then one row per frame.

    Positions are converted to metres from the header's Units; empty fields and exact
    (0, 0, 0) triplets are missing samples. Where NumMarkers, the marker names and the data
    rows disagree, or NumFrames and the rows, the rows are read, with a warning.
    """
    path = os.fspath(path)
    lines = read_lines(path)
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise MocapInputError(path, "not a TRC file (no PathFileType header line)")
    keys, values = lines[1].split("\t"), lines[2].split("\t")
    header = {k.strip(): v.strip() for k, v in zip(keys, values)}
    if "NumMarkers" not in header or not ({"DataRate", "CameraRate"} & set(header)):
        raise MocapInputError(path, "TRC header lacks DataRate or NumMarkers")
    rate = frame_rate(path, ("DataRate", header.get("DataRate")), ("CameraRate", header.get("CameraRate")))
    units = header.get("Units", "mm")
    rows = lines[5:]
    named = _names(lines[3])
    n_markers, names, note = marker_count(path, [("NumMarkers", header["NumMarkers"])], named, rows, 2)
    positions = marker_table(path, rows, 2, n_markers)
    data = [r for r in rows if r.strip()]
    notes = [note, frame_count_note("NumFrames", header.get("NumFrames"), len(data),
                                    [r.split("\t", 1)[0] for r in data[:1] + data[-1:]])]
    mark_missing(positions)
    notes.append(to_metres(positions, unit_scale(units, path)))
    first_frame, note = first_frame_number(data)
    return Take(
        positions=positions,
        names=names,
        rate=rate,
        first_frame=first_frame,
        source_units=units,
        source=path,
        vendor="TRC",
        warnings=[n for n in [*notes, note] if n],
    )


def _names(line: str) -> list[str]:
    """The marker names of the header's names line; where each name heads its X/Y/Z columns (as
    TRC writers lay them out), an empty one is an unlabeled marker ``*N``."""
    fields = [f.strip() for f in line.split("\t")[2:]]
    while fields and not fields[-1]:
        fields.pop()
    if any(fields[i] for i in range(len(fields)) if i % 3):  # not laid out in triplets
        return [f for f in fields if f]
    return [f or f"*{i}" for i, f in enumerate(fields[::3])]
