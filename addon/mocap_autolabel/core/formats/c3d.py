"""C3D files: read into a Take, write a Take.

Reading: the ``c3d`` package parses the header and parameter section (it is lazy and knows
Intel, DEC and MIPS files); the data block is read here with numpy, chunk by chunk, because
ezc3d holds every sample as a C++ object (about 11x the positions' size in memory) and
stops at 65,535 frames. A damaged parameter section (a last parameter that does not end
the section, dimensions that overflow their own record) is repaired in memory first.

Writing: ezc3d, the reference implementation; the output round-trips through ezc3d and
``c3d``.
"""

from __future__ import annotations

import collections
import errno
import io
import itertools
import os
import struct
import warnings
from dataclasses import dataclass

import numpy as np

from ..atomic import atomic_output
from ..errors import MocapInputError
from ..take_data import MAX_RATE, MIN_RATE, Take, mark_missing, to_metres, unit_scale
from ..version import __version__

BLOCK = 512
MAGIC = 0x50
#: The most frames the header's and POINT:FRAMES's 16-bit counts hold; a longer take states its
#: length in TRIAL:ACTUAL_START/END_FIELD (two words each) and POINT:LONG_FRAMES.
MAX_SHORT_FRAMES = 65535
#: Frames converted per chunk: bounds the temporary memory of a read.
CHUNK_FRAMES = 8192


@dataclass
class _Layout:
    """Where and how the samples are stored in the data block."""

    processor: str
    is_real: bool
    scale: float
    n_points: int
    analog_words: int
    data_offset: int
    n_frames: int

    @property
    def frame_words(self) -> int:
        return 4 * self.n_points + self.analog_words

    @property
    def word_bytes(self) -> int:
        return 4 if self.is_real else 2

    @property
    def frame_bytes(self) -> int:
        return self.frame_words * self.word_bytes


def read_c3d(path: str | os.PathLike) -> Take:
    """Read a C3D file into a Take; positions in metres, NaN where missing.

    Raises:
        MocapInputError: empty, truncated, not a C3D file, or a parameter section that
            cannot be repaired.
    """
    path = os.fspath(path)
    size = os.path.getsize(path)
    if size == 0:
        raise MocapInputError(path, "file is empty (0 bytes)")
    with open(path, "rb") as fh:
        head = fh.read(BLOCK)
        if 1 < len(head) < BLOCK and head[1] == MAGIC:
            raise MocapInputError(path, f"truncated C3D file: {len(head)} bytes, shorter than its 512-byte header")
        if len(head) < BLOCK or head[1] != MAGIC:
            raise MocapInputError(path, "not a C3D file (no C3D header signature in the first 512 bytes)")
        param_start = (head[0] - 1) * BLOCK
        if head[0] < 2 or param_start + 4 > size:
            raise MocapInputError(
                path, f"the header points to a parameter section at byte {param_start}, "
                f"outside the file ({size} bytes)")
        fh.seek(param_start)
        param_head = fh.read(4)
        n_param_blocks = param_head[2] or 1
        fh.seek(0)
        reader, fixes = _parse_metadata(path, fh.read(param_start + n_param_blocks * BLOCK))
        layout, disagreements = _layout(path, reader, size)
        positions, residuals, computed = _read_samples(fh, layout)

    units = _string_param(reader, "POINT:UNITS")
    take_warnings = [f"repaired parameter section: {fix}" for fix in fixes] + disagreements
    if not units:
        units = _guess_units(positions)
        take_warnings.append(f"no POINT:UNITS parameter; the values look like {units}")
    damaged = to_metres(positions, unit_scale(units, path), residuals)
    take_warnings += [damaged] if damaged else []

    names = _point_labels(reader, layout.n_points)
    if layout.n_points == 0:
        take_warnings.append("the file holds no 3D points (analog data only)")
    dupes = sorted(n for n, count in collections.Counter(names).items() if n and count > 1)
    if dupes:
        take_warnings.append(f"duplicate point names: {', '.join(dupes[:5])}" + (" ..." if len(dupes) > 5 else ""))

    # A zero 4th word (residual 0, no camera) marks a computed sample (a gap fill), but only in a
    # file that states residuals at all: one whose every word is 0 says nothing either way.
    valid = ~np.isnan(positions[..., 0])
    filled = computed & valid if (valid & ~computed).any() else None
    rate, note = _point_rate(path, reader)
    take_warnings += [note] if note else []
    return Take(
        positions=positions,
        names=names,
        rate=rate,
        first_frame=int(reader.header.first_frame),
        source_units=units,
        residuals=residuals,
        source=path,
        vendor=_vendor(reader, layout),
        warnings=take_warnings,
        filled=filled,
    )


def _guess_units(positions: np.ndarray) -> str:
    """'m' if every coordinate is within 20 units of the origin (no capture volume is 20 mm), else 'mm'."""
    finite = np.isfinite(positions)
    return "m" if finite.any() and np.abs(positions[finite]).max() < 20 else "mm"


def rebuild_parameter_section(meta: bytes) -> tuple[bytes, list[str]]:
    """Rebuild a damaged parameter section so that a standard parser reads it.

    ``meta`` holds the header and the whole parameter section. Records are walked by their
    "next" offsets (the part of a damaged file that is usually still right) and written
    back in standard form. Damage seen in real files and repaired here:
    - dimensions that describe more bytes than the record holds (a stray extra dimension);
    - a record that ends before its description-length byte;
    - a numeric parameter with no value at all (dropped: the header's value is used);
    - a last record that points to a zero-filled record instead of ending the section.

    Returns the rebuilt bytes and a list of what was repaired.
    """
    start = (meta[0] - 1) * BLOCK
    endian = ">" if meta[start + 3] == 86 else "<"
    end = min(start + meta[start + 2] * BLOCK, len(meta))
    records: list[bytes] = []
    fixes: list[str] = []
    pos = start + 4
    while pos + 4 <= end:
        n_chars, group_id = struct.unpack_from("bb", meta, pos)
        if n_chars == 0 or group_id == 0:
            break
        name_end = pos + 2 + abs(n_chars)
        name = _printable(meta[pos + 2:name_end].decode("latin-1").strip())
        offset = struct.unpack_from(endian + "h", meta, name_end)[0]
        body_end = name_end + offset if offset > 0 else end
        body = bytearray(meta[name_end + 2:min(body_end, end)])
        if group_id > 0:
            body, fix = _normalise_parameter(body)
            if fix:
                fixes.append(f"{name}: {fix}")
            if body is None:
                pos = body_end
                continue
        elif not body:
            body = bytearray(1)  # a group with no description-length byte
        records.append(struct.pack("bb", n_chars, group_id) + meta[pos + 2:name_end]
                       + struct.pack(endian + "h", len(body) + 2) + bytes(body))
        if offset <= 0:
            break
        pos = body_end
    section = bytearray(meta[start:start + 4]) + b"".join(records) + bytes(2)
    n_blocks = -(-len(section) // BLOCK)
    section[2] = n_blocks
    section += bytes(n_blocks * BLOCK - len(section))
    return bytes(meta[:start]) + bytes(section), fixes


def _normalise_parameter(body: bytearray) -> tuple[bytearray | None, str]:
    """One parameter record (after its offset field) in standard form, and what was wrong."""
    if len(body) < 2:
        return None, "record too short, dropped"
    type_size = abs(struct.unpack_from("b", body, 0)[0])

    def data_end(n_dims: int) -> int:
        dims = list(body[2:2 + n_dims])
        return 2 + n_dims + type_size * int(np.prod(dims, dtype=np.int64))

    fix = ""
    n_dims = body[1]
    if data_end(n_dims) > len(body):
        fitting = [n for n in range(n_dims - 1, 0, -1) if data_end(n) <= len(body)]
        if not fitting:
            return None, "dimensions larger than the record, dropped"
        n_dims, fix = fitting[0], "dimensions larger than the record"
        body[1] = n_dims
    stop = data_end(n_dims)
    if type_size != 1 and stop == 2 + n_dims:
        return None, "numeric parameter without a value, dropped"
    if stop >= len(body):
        return body[:stop] + bytes(1), fix or "no description-length byte"
    return body, fix


def _parse_metadata(path: str, meta: bytes):
    """The ``c3d`` package's Reader over header + parameters, rebuilding them if damaged."""
    import c3d as c3dpkg

    class LenientReader(c3dpkg.Reader):
        # Header and parameters often disagree in real files; _layout decides which to trust.
        def _check_metadata(self) -> None:
            pass

    def parse(data: bytes):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return LenientReader(io.BytesIO(data))

    try:
        return parse(meta), []
    except Exception:  # the c3d package raises bare struct/Value/Assertion errors
        pass
    try:
        rebuilt, fixes = rebuild_parameter_section(meta)
        return parse(rebuilt), fixes
    except Exception as exc:
        raise MocapInputError(path, "damaged parameter section that cannot be repaired: "
                              + _parse_failure(meta, exc)) from None


#: The parameter section's processor type byte: how its numbers are stored.
PROCESSORS = {84: "Intel", 85: "DEC", 86: "MIPS"}


def _parse_failure(meta: bytes, exc: Exception) -> str:
    """What a reader of the file can act on, instead of the parser's internal error: an unknown
    processor type, or where the parameters stop making sense."""
    start = (meta[0] - 1) * BLOCK if meta and meta[0] >= 1 else -1
    if 0 <= start and start + 3 < len(meta) and meta[start + 3] not in PROCESSORS:
        known = ", ".join(f"{code} ({name})" for code, name in PROCESSORS.items())
        return f"unknown processor type {meta[start + 3]} in its first block; {known} expected"
    if isinstance(exc, (ValueError, EOFError)) and str(exc):
        return str(exc)
    return "a parameter's name, type or size is out of range"


def _param(reader, key: str):
    try:
        return reader.get(key)
    except Exception:
        return None


def _string_param(reader, key: str) -> str:
    p = _param(reader, key)
    if p is None:
        return ""
    try:
        value = p.string_value if len(p.dimensions) <= 1 else " ".join(p.string_array.ravel())
    except Exception:
        return ""
    return _printable(str(value).strip().strip("\x00").strip())


def _printable(text: str) -> str:
    """``text`` with every control character (a newline in a damaged name) shown as "?": names
    and units go into one-line messages and Blender object names."""
    return text if text.isprintable() else "".join(c if c.isprintable() else "?" for c in text)


def _number_param(reader, key: str) -> float | None:
    """A numeric parameter's first value, whatever its stored type; None if absent."""
    p = _param(reader, key)
    if p is None or p.total_bytes == 0:
        return None
    try:
        if p.bytes_per_element == 4:
            return float(p.float_value)
        if p.bytes_per_element == 2:
            return float(p.uint16_value)
        if p.bytes_per_element == 1:
            return float(p.uint8_value)
    except Exception:
        return None
    return None


def _point_rate(path: str, reader) -> tuple[float, str]:
    """Frames per second: POINT:RATE, else the header's; and a warning when the two disagree."""
    header_rate = float(reader.header.frame_rate)
    param_rate = _number_param(reader, "POINT:RATE")
    usable = [r for r in (param_rate, header_rate) if r is not None and np.isfinite(r) and MIN_RATE <= r < MAX_RATE]
    if not usable:
        raise MocapInputError(path, f"no usable frame rate (POINT:RATE is {param_rate}, the header's rate "
                                    f"{header_rate:g}; expected {MIN_RATE:g} to {MAX_RATE:,.0f} frames per second)")
    if len(usable) == 2 and not np.isclose(usable[0], usable[1], rtol=1e-4):
        return usable[0], (f"frame rate disagrees: {usable[0]:g} Hz in POINT:RATE, {usable[1]:g} Hz in "
                           f"the header; read {usable[0]:g} Hz")
    return usable[0], ""


def _point_labels(reader, n_points: int) -> list[str]:
    names: list[str] = []
    for key in ["POINT:LABELS"] + [f"POINT:LABELS{i}" for i in range(2, 100)]:
        p = _param(reader, key)
        if p is None:
            if key != "POINT:LABELS":
                break
            continue
        try:
            names.extend(_printable(str(s).strip()) for s in np.atleast_1d(p.string_array))
        except Exception:
            break
    names = names[:n_points]
    names += [f"*{i}" for i in range(len(names), n_points)]
    return [n if n else f"*{i}" for i, n in enumerate(names)]


def _vendor(reader, layout: _Layout) -> str:
    company, software = _string_param(reader, "MANUFACTURER:COMPANY"), _string_param(reader, "MANUFACTURER:SOFTWARE")
    vendor = software if software.startswith(company) else " ".join(p for p in (company, software) if p)
    kind = f"{layout.processor} {'REAL' if layout.is_real else 'INT'}"
    return f"{vendor} ({kind})" if vendor else f"unknown ({kind})"


def _layout(path: str, reader, file_size: int) -> tuple[_Layout, list[str]]:
    """The data block's layout, and a warning for each header/parameter disagreement resolved.

    The header and the parameters can disagree on the point count (POINT:USED), the sample
    format (the sign of POINT:SCALE), the data start (POINT:DATA_START) and the frame count
    (POINT:FRAMES, TRIAL:ACTUAL_START/END_FIELD) and the analog words per frame (ANALOG:USED
    times ANALOG:RATE / POINT:RATE). Every combination of the stated values is checked against
    the size of the data section (see :func:`_fit`); among equals the header's values win, as
    they define the layout of a standard file. Only when no combination fits in the file is it
    refused (truncated).
    """
    header = reader.header
    processor = {"INTEL": "Intel", "DEC": "DEC", "MIPS": "MIPS"}.get(reader._dtypes.proc_type, "Intel")
    points = _stated(("the header", header.point_count), ("POINT:USED", _number_param(reader, "POINT:USED")))
    param_scale = _number_param(reader, "POINT:SCALE")
    header_scale = float(header.scale_factor)
    usable = [s for s in (param_scale, header_scale) if s is not None and s != 0 and np.isfinite(s)]
    formats = _stated(("the header's scale sign", header_scale < 0),
                      ("POINT:SCALE", None if param_scale is None or np.isnan(param_scale) else param_scale < 0))
    starts = _stated(("the header", header.data_block if header.data_block > 1 else None),
                     ("POINT:DATA_START", _number_param(reader, "POINT:DATA_START")), minimum=2)
    if not starts:
        starts = [(2, "the default")]
    # The header's frame fields are 16 bits: a range of 65535 frames or a wrapped one is no count.
    header_frames = int(header.last_frame) - int(header.first_frame) + 1
    trial_frames, long_frames = _trial_frames(reader), _number_param(reader, "POINT:LONG_FRAMES")
    frames = _stated(("the header's first/last frame",
                      header_frames if header_frames > 0 and header.last_frame != 65535 else None),
                     ("POINT:FRAMES", _number_param(reader, "POINT:FRAMES")),
                     ("TRIAL:ACTUAL_START/END_FIELD", trial_frames or None),
                     ("POINT:LONG_FRAMES", long_frames), minimum=0)
    if max(trial_frames, int(long_frames) if long_frames is not None and np.isfinite(long_frames) else 0) \
            > MAX_SHORT_FRAMES:  # a long take: the 16-bit counts are only capped, no disagreement
        frames = [(n, who) for n, who in frames if n > MAX_SHORT_FRAMES] or frames
    # An exporter (an Optotrak one) can state analog words in the header that its data section does not
    # hold (ANALOG:USED 0): ezc3d sizes a frame from the parameters; both are tried against the data.
    analogs = _stated(("the header", int(header.analog_count)), ("ANALOG:USED x ANALOG:RATE/POINT:RATE",
                                                                 _analog_words(reader)))

    best, first = None, None
    for (n_points, _), (is_real, _), (start, _), (analog_words, _) in itertools.product(
            points or [(0, "")], formats, starts, analogs):
        word = 4 if is_real else 2
        frame_bytes = (4 * n_points + analog_words) * word
        space = file_size - (start - 1) * BLOCK
        available = max(space, 0) // frame_bytes if frame_bytes else 0
        for n_frames, _ in frames or [(available, "")]:
            rank = _fit(space, n_frames, frame_bytes)
            # Among layouts that leave data unread, the one that reads the most.
            key = (rank, space - n_frames * frame_bytes if rank == 2 else 0)
            choice = (key, n_points, is_real, start, analog_words, n_frames, available)
            first = first or choice
            if best is None or key < best[0]:
                best = choice
    (rank, _), n_points, is_real, start, analog_words, n_frames, available = best
    capped = ""
    frame_bytes = (4 * n_points + analog_words) * (4 if is_real else 2)
    if rank == 2 and n_frames == MAX_SHORT_FRAMES and frame_bytes:
        # 65535 is all a 16-bit count holds: the data section holds the take's whole length (less
        # the zero bytes that pad its last block).
        available = _unpadded_frames(path, (start - 1) * BLOCK, file_size, frame_bytes)
        capped = (f"the file states {MAX_SHORT_FRAMES} frames, the most its 16-bit counts hold, and no longer "
                  f"count (TRIAL:ACTUAL_END_FIELD, POINT:LONG_FRAMES); read the {available} frames its data "
                  f"section holds")
        n_frames = available
    if rank == 3:
        _, n_points, is_real, start, analog_words, n_frames, available = first
        raise MocapInputError(
            path, f"file is truncated: the header declares {n_frames} frames but the data "
            f"section holds only {available}" + _disagreement_note(points, formats, starts, analogs, frames))
    scale = abs(usable[0]) if usable else 1.0
    notes = [_resolved("point count", points, n_points, f"{n_points} points"),
             _resolved("sample format", formats, is_real, "REAL (float)" if is_real else "INT (16-bit)"),
             _resolved("data start", starts, start, f"block {start}"),
             _resolved("analog words per frame", analogs, analog_words, f"{analog_words} analog words per frame"),
             _resolved("frame count", frames, n_frames, f"{n_frames} frames"), capped]
    if not is_real and len(usable) == 2 and not np.isclose(abs(usable[0]), abs(usable[1]), rtol=1e-4):
        notes.append(f"POINT:SCALE ({abs(usable[0]):g}) and the header's scale ({abs(usable[1]):g}) "
                     f"disagree; read with POINT:SCALE")
    if not is_real and not usable:
        raise MocapInputError(path, "no usable scale for its integer samples (POINT:SCALE and the header's are 0)")
    layout = _Layout(processor, is_real, scale, n_points, analog_words, (start - 1) * BLOCK, n_frames)
    return layout, [n for n in notes if n]


def _unpadded_frames(path: str, data_start: int, file_size: int, frame_bytes: int) -> int:
    """Whole frames from ``data_start`` to the end of the file, less the frames at its end that
    are all zero bytes within its last block (the padding of a data section that ends mid-block)."""
    n = (file_size - data_start) // frame_bytes
    with open(path, "rb") as f:
        while n > 0 and data_start + n * frame_bytes > file_size - BLOCK:
            f.seek(data_start + (n - 1) * frame_bytes)
            if any(f.read(frame_bytes)):
                break
            n -= 1
    return n


def _fit(space: int, n_frames: int, frame_bytes: int) -> int:
    """How well ``n_frames`` frames of ``frame_bytes`` fill ``space`` bytes: 0 the data holds
    exactly that many whole frames, 1 the rest is under a block (padding), 2 they fit with more
    after them, 3 they do not fit (or the data starts past the end of the file). Zero frames, or
    frames of no bytes, are never exact: they say nothing about the data."""
    if space < 0:
        return 3
    rest = space - n_frames * frame_bytes
    if rest < 0:
        return 3
    if not frame_bytes or not n_frames:
        return 1 if rest < BLOCK else 2  # nothing to check against, or no frame read from a data section
    return 0 if rest < frame_bytes else 1 if rest < BLOCK else 2


def _stated(*sources: tuple[str, float | bool | None], minimum: int = 0) -> list[tuple[int, str]]:
    """The distinct values that ``sources`` state, in order, each with who states it.

    ``None`` (absent) and values below ``minimum`` or not whole numbers are left out.
    """
    values: dict[int, list[str]] = {}
    for name, value in sources:
        if value is None or isinstance(value, float) and not (np.isfinite(value) and value == int(value)):
            continue
        if int(value) >= minimum:
            values.setdefault(int(value), []).append(name)
    return [(value, " and ".join(names)) for value, names in values.items()]


def _resolved(what: str, stated: list[tuple[int, str]], used: int, said: str) -> str:
    """A warning line when the sources in ``stated`` disagree on ``what``; "" when they agree."""
    if len(stated) < 2:
        return ""
    claims = ", ".join(f"{_claim(what, value)} in {who}" for value, who in stated)
    return f"{what} disagrees: {claims}; read {said}, which the data section's size supports"


def _claim(what: str, value: int) -> str:
    if what == "sample format":
        return "REAL" if value else "INT"
    return str(value)


def _disagreement_note(*stated: list[tuple[int, str]]) -> str:
    parts = [", ".join(f"{who} {value}" for value, who in s) for s in stated if len(s) > 1]
    return f" (and none of the stated layouts fits: {'; '.join(parts)})" if parts else ""


def _analog_words(reader) -> int | None:
    """Analog words per frame as the parameters state them (ANALOG:USED channels, each sampled
    ANALOG:RATE / POINT:RATE times a frame, as ezc3d reads them); None where they do not say."""
    used = _number_param(reader, "ANALOG:USED")
    if used is None or not np.isfinite(used) or used < 0:
        return None
    if used == 0:
        return 0  # no channel: no analog word, whatever the rates
    analog_rate = _number_param(reader, "ANALOG:RATE")
    point_rate = _number_param(reader, "POINT:RATE") or float(reader.header.frame_rate)
    if not analog_rate or not point_rate or not np.isfinite(analog_rate / point_rate):
        return None
    per_frame = analog_rate / point_rate
    # A count or rate ratio that is not whole (or not positive) states no layout; rates stored as rounded
    # floats are allowed 0.1 %.
    if used != int(used) or per_frame <= 0 or abs(per_frame - round(per_frame)) > 1e-3 * per_frame:
        return None
    return int(used) * int(round(per_frame))


def _trial_frames(reader) -> int:
    """Frame count from TRIAL:ACTUAL_START/END_FIELD (two 16-bit words each), 0 if absent."""
    ends = []
    for key in ("TRIAL:ACTUAL_START_FIELD", "TRIAL:ACTUAL_END_FIELD"):
        p = _param(reader, key)
        try:
            if p.bytes_per_element == 4:  # the words stored as floats (ezc3d writes integers so)
                lo, hi = (int(v) & 0xFFFF for v in p.float_array.ravel()[:2])
            else:
                lo, hi = p.uint16_array.ravel()[:2]
        except Exception:  # absent, or too short to hold two words
            return 0
        ends.append(int(lo) + 65536 * int(hi))
    return ends[1] - ends[0] + 1 if ends[1] >= ends[0] else 0


def _read_samples(fh, layout: _Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions ``(frames, points, 3)`` and residuals ``(frames, points)``, float32, source units, and
    bool ``(frames, points)``: samples whose 4th word is 0 (residual 0, no camera: computed)."""
    n_f, n_p = layout.n_frames, layout.n_points
    positions = np.empty((n_f, n_p, 3), dtype=np.float32)
    residuals = np.empty((n_f, n_p), dtype=np.float32)
    computed = np.zeros((n_f, n_p), dtype=bool)
    if n_f == 0 or n_p == 0:
        return positions, residuals, computed
    if layout.processor == "MIPS":
        dtype = np.dtype(">f4" if layout.is_real else ">i2")
    else:
        dtype = np.dtype("<f4" if layout.is_real else "<i2")
    fh.seek(layout.data_offset)
    with np.errstate(all="ignore"):  # damaged words (NaN, inf, overflow) become missing samples
        _convert_chunks(fh, layout, dtype, positions, residuals, computed)
    return positions, residuals, computed


def _convert_chunks(fh, layout: _Layout, dtype: np.dtype, positions: np.ndarray, residuals: np.ndarray,
                    computed: np.ndarray) -> None:
    """Fill ``positions`` and ``residuals`` (source units) and ``computed`` (a 4th word of 0) from the
    data block, chunk by chunk."""
    n_f, n_p = layout.n_frames, layout.n_points
    frame_bytes = layout.frame_bytes
    for f0 in range(0, n_f, CHUNK_FRAMES):
        nf = min(CHUNK_FRAMES, n_f - f0)
        raw = fh.read(nf * frame_bytes)
        if layout.processor == "DEC" and layout.is_real:
            from c3d.c3d import DEC_to_IEEE_BYTES

            words = DEC_to_IEEE_BYTES(raw).reshape(nf, layout.frame_words)
        else:
            words = np.frombuffer(raw, dtype=dtype).reshape(nf, layout.frame_words)
        pts = words[:, :4 * n_p].reshape(nf, n_p, 4)
        xyz = positions[f0:f0 + nf]
        xyz[...] = pts[..., :3]
        fourth = pts[..., 3]
        if not layout.is_real:
            xyz *= layout.scale
        res = residuals[f0:f0 + nf]
        # The 4th word: negative = invalid; else low byte = residual / |scale|.
        res[...] = np.where(fourth < 0, -1.0, (fourth.astype(np.int32) & 0xFF) * layout.scale)
        computed[f0:f0 + nf] = fourth == 0
        mark_missing(xyz, res)


def _file_values(positions: np.ndarray, scale_m: float) -> np.ndarray:
    """The float32 values in file units whose reading (:func:`read_c3d`: float32 times ``scale_m``)
    gives back ``positions`` (metres) exactly where one exists: a take read and written again keeps
    every sample bit for bit (of the nearest three float32 values one reads back exactly)."""
    p = np.asarray(positions, dtype=np.float32)
    s = np.float32(scale_m)
    best = (p / s).astype(np.float32)
    with np.errstate(invalid="ignore"):
        for step in (np.inf, -np.inf):
            other = np.nextafter(best, np.float32(step))
            best = np.where((best * s != p) & (other * s == p), other, best)
    return best


def write_c3d(take: Take, path: str | os.PathLike, units: str = "mm") -> None:
    """Write ``take`` as a C3D file (Intel, REAL), atomically.

    Missing samples are written as invalid (residual -1), so that every reader sees the gap.
    Names are written in order; unlabeled slots should be named ``*N``. Where ``take.filled`` is
    given, its samples are written as computed the way C3D marks them (residual 0, no camera
    bits: a 4th word of 0); measured ones carry the first camera bit and their residual (whole
    file units), so that no measured sample reads as computed (:func:`_fourth_words`).

    Args:
        take: positions in metres.
        path: output file; it appears complete or not at all.
        units: POINT:UNITS of the file ("mm" by default, as capture systems write).

    Raises:
        MocapInputError: a take of no frames, or of a rate :func:`read_c3d` refuses (nothing is written).
        OSError: naming ``path`` (a folder, a folder that cannot be written, a full disk).
    """
    import ezc3d

    path = os.fspath(path)
    # Written files must read back: ezc3d cannot write a take of 0 frames (it divides by the frame count), and
    # a rate the reader refuses (a subnormal one is 0 as the file's float32) would make a file no one reads.
    if take.n_frames == 0:
        raise MocapInputError(path, "cannot write a C3D of a take with no frames (0 frames)")
    if not MIN_RATE <= np.float32(take.rate) < MAX_RATE:
        raise MocapInputError(path, f"cannot write a C3D at {take.rate:g} frames per second (expected "
                                    f"{MIN_RATE:g} to {MAX_RATE:,.0f})")
    scale = 1.0 / unit_scale(units, path)
    n_f, n_p = take.n_frames, take.n_points
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [float(take.rate)]
    c["parameters"]["POINT"]["UNITS"]["value"] = [units]
    c["parameters"]["POINT"]["LABELS"]["value"] = [n[:32] for n in take.names]
    c["parameters"]["POINT"]["DESCRIPTIONS"]["value"] = [""] * n_p
    if n_f > MAX_SHORT_FRAMES:  # beyond the 16-bit counts: the long count as capture systems write it
        end = int(take.first_frame) + n_f - 1
        c.add_parameter("POINT", "LONG_FRAMES", [float(n_f)])
        c.add_parameter("TRIAL", "ACTUAL_START_FIELD", list(_words(int(take.first_frame))))
        c.add_parameter("TRIAL", "ACTUAL_END_FIELD", list(_words(end)))
    c.add_parameter("MANUFACTURER", "COMPANY", ["mocap_autolabel"])
    c.add_parameter("MANUFACTURER", "SOFTWARE", [f"mocap_autolabel {__version__}"])
    pts = np.zeros((4, n_p, n_f), dtype=np.float64)
    pts[:3] = np.transpose(_file_values(take.positions, unit_scale(units, path)), (2, 1, 0))
    pts[3] = 1.0
    c["data"]["points"] = pts
    valid = take.valid.T
    c["data"]["meta_points"]["residuals"] = np.where(valid, 0.0, -1.0)[np.newaxis]
    c["header"]["points"]["first_frame"] = max(int(take.first_frame) - 1, 0)
    with atomic_output(path, suffix=".c3d") as tmp:  # ezc3d appends ".c3d" to any other name (x.C3D)
        c.write(tmp)
        _check_written(tmp, path, n_f, n_p)
        _write_fourth_words(tmp, _fourth_words(take, scale))


def _words(value: int) -> tuple[int, int]:
    """A 32-bit count as the two signed 16-bit words of a TRIAL field (low, high)."""
    lo, hi = value & 0xFFFF, (value >> 16) & 0xFFFF
    return (lo - 65536 if lo > 32767 else lo), (hi - 65536 if hi > 32767 else hi)


def _fourth_words(take: Take, scale: float) -> np.ndarray:
    """float32 ``(F, P)``: the 4th word of each sample as the C3D format states it for REAL data: -1
    where missing; 0 where computed (``take.filled``: residual 0, no camera); else the first camera
    bit (256; which cameras saw it is not kept) plus the residual in file units (POINT:SCALE -1: whole
    units, at most 255)."""
    res = np.zeros(take.valid.shape) if take.residuals is None else np.nan_to_num(take.residuals) * scale
    words = 256.0 + np.clip(np.round(res), 0, 255)
    if take.filled is not None:
        words[take.filled] = 0.0
    return np.where(take.valid, words, -1.0).astype(np.float32)


def _write_fourth_words(path: str, words: np.ndarray) -> None:
    """Write ``words (F, P)`` as the 4th word of every point sample of the C3D file ``path``.

    ezc3d writes a REAL file's 4th word as two 16-bit integers (camera bits, then residual) in the
    float's place, which a reader that follows the format (the ``c3d`` package, ours) reads as a
    1-unit residual with no camera; here it is the float the format defines instead.
    """
    with open(path, "r+b") as f:
        header = np.frombuffer(f.read(20), dtype="<u2")
        n_p, analog, start = int(header[1]), int(header[2]), int(header[8])
        frame = 4 * n_p + analog  # 4-byte words per frame
        data = np.memmap(f, dtype="<f4", mode="r+", offset=(start - 1) * BLOCK, shape=(len(words), frame))
        data[:, 3:4 * n_p:4] = words
        data.flush()
        del data


def _check_written(tmp: str, path: str, n_frames: int, n_points: int) -> None:
    """Raise OSError if ezc3d's write (which never reports a failed write) left ``tmp`` shorter than its data.

    The header's DATA_START block (word 9) plus ``n_frames x n_points`` REAL samples of 16 bytes is the
    least a whole file holds; a full disk or a file size limit leaves less.
    """
    if not os.path.isfile(tmp):  # the writer could not create it
        raise OSError(errno.EIO, "the C3D writer could not create the file", path)
    size = os.path.getsize(tmp)
    with open(tmp, "rb") as f:
        header = f.read(18)
    data_start = int.from_bytes(header[16:18], "little") if len(header) == 18 else 0
    if data_start < 2 or size < (data_start - 1) * 512 + 16 * n_frames * n_points:
        raise OSError(errno.EFBIG if size else errno.ENOSPC, "the file was cut short while writing (is the disk full?)",
                      path)
