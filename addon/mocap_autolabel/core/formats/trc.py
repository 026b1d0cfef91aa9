"""TRC files (Motion Analysis / OpenSim marker trajectories), as in the Han et al. data."""

from __future__ import annotations

import os

from ..errors import MocapInputError
from ..take import Take, mark_missing, unit_scale
from ._text import marker_table, read_lines


def read_trc(path: str | os.PathLike) -> Take:
    """Read a TRC file: a 5-line header (rate, units, marker names), then one row per frame.

    Positions are converted to metres from the header's Units; empty fields and exact
    (0, 0, 0) triplets are missing samples.
    """
    path = os.fspath(path)
    lines = read_lines(path)
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise MocapInputError(path, "not a TRC file (no PathFileType header line)")
    keys, values = lines[1].split("\t"), lines[2].split("\t")
    header = {k.strip(): v.strip() for k, v in zip(keys, values)}
    try:
        rate = float(header.get("DataRate") or header["CameraRate"])
        n_markers = int(header["NumMarkers"])
    except (KeyError, ValueError):
        raise MocapInputError(path, "TRC header lacks DataRate or NumMarkers") from None
    units = header.get("Units", "mm")
    names = [n.strip() for n in lines[3].split("\t")[2:] if n.strip()]
    if len(names) != n_markers:
        raise MocapInputError(path, f"header says {n_markers} markers but names {len(names)}")
    positions = marker_table(path, lines[5:], 2, n_markers)
    mark_missing(positions)
    positions *= unit_scale(units, path)
    first = lines[5].split("\t", 1)[0].strip() if len(lines) > 5 else "1"
    return Take(
        positions=positions,
        names=names,
        rate=rate,
        first_frame=int(float(first)) if first else 1,
        source_units=units,
        source=path,
        vendor="TRC",
    )

