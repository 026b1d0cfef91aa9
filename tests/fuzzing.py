"""A mutation fuzzer over the real corpus: C3D, TRC and Qualisys TSV files, damaged on purpose.

Used by ``tests/core/test_fuzz.py`` (a seeded sample), ``tests/blender/test_fuzz_blender.py`` (through
Blender's import operator) and ``benchmarks/fuzz.py`` (100,000+ cases); not part of the add-on. A
case is one seed file with one to three mutations, rebuilt from ``(master seed, case index)`` alone,
so any case can be reproduced from the report.

A case fails when reading it raises anything but :class:`MocapInputError`, when a warning
(numpy's included) escapes the reader, when the Take it returns holds an infinite coordinate
or a bad shape or rate, when it runs over ``TIME_LIMIT_S`` or when the process's peak resident
memory grows by more than ``MEMORY_BOUND_MB`` during it.
"""

from __future__ import annotations

import os
import signal
import struct
import time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("MOCAP_DATA", ROOT.parent / "shared" / "data"))

#: A case may take at most this long (seconds) ...
TIME_LIMIT_S = 5.0
#: ... and grow the process's peak resident memory by at most this much (MB).
MEMORY_BOUND_MB = 512.0
#: Rows of the Qualisys recording kept in its seed (the whole file takes a second to parse).
TSV_ROWS = 100
BLOCK = 512

FLOATS = [float("nan"), float("inf"), float("-inf"), 3.0e38, -3.0e38, 1e30, 2.0 ** 31, 60000.0, -1.0, 0.0,
          -0.0, 1e-40, -100.0]
WORDS = [0, 1, 2, 255, 256, 32767, 32768, 60000, 65535]
TOKENS = ["nan", "NaN", "inf", "-inf", "1e300", "-1e40", "3.5e38", "", "abc", "0", "1e-320", "-0", "0x10",
          "9" * 40, "1,5", " ", "\x00"]
COUNTS = ["60000", "2147483648", "-1", "0", "nan", "inf", "1e300", "", "abc", "9" * 40, "1.5", "-2147483649"]


@dataclass(frozen=True)
class Seed:
    """A real file to mutate: ``name`` (its path under the data folder), ``ext`` and its bytes."""

    name: str
    ext: str
    data: bytes


@dataclass(frozen=True)
class Case:
    index: int
    seed: Seed
    mutations: tuple[str, ...]
    data: bytes

    @property
    def label(self) -> str:
        return f"#{self.index} {self.seed.name}: {' + '.join(self.mutations)}"


@dataclass
class Outcome:
    status: str  # "read", "error" (the project's input error) or "failure"
    seconds: float
    peak_mb: float
    detail: str = ""


def load_seeds(data_dir: Path = DATA, max_bytes: int | None = None, trc_every: int = 16) -> list[Seed]:
    """The corpus's files: every non-empty C3D, every ``trc_every``-th Han TRC, the Qualisys TSV's
    header and first ``TSV_ROWS`` rows. ``max_bytes`` leaves out larger files. Empty if absent."""
    seeds: list[Seed] = []
    for path in sorted((data_dir / "c3d").rglob("*")):
        if path.suffix.lower() == ".c3d" and path.stat().st_size:
            seeds.append(Seed(str(path.relative_to(data_dir)), ".c3d", path.read_bytes()))
    for path in sorted((data_dir / "hands").rglob("*.trc"))[::trc_every]:
        seeds.append(Seed(str(path.relative_to(data_dir)), ".trc", path.read_bytes()))
    tsv = data_dir / "hands" / "qualisys_glove13" / "recording_part1.tsv"
    if tsv.exists():
        lines = tsv.read_bytes().split(b"\n")
        head = next(i for i, line in enumerate(lines) if line[:1].isdigit())
        seeds.append(Seed(str(tsv.relative_to(data_dir)), ".tsv", b"\n".join(lines[:head + TSV_ROWS]) + b"\n"))
    return [s for s in seeds if max_bytes is None or len(s.data) <= max_bytes]


# --- C3D mutations ---------------------------------------------------------------------------

def _param_start(data: bytes | bytearray) -> int:
    return max(data[0] - 1, 1) * BLOCK if data else BLOCK


def _param_records(data: bytes | bytearray) -> list[tuple[str, int, int, int]]:
    """Parameter records of an Intel/DEC/MIPS file: ``(name, type, dims offset, value offset)``."""
    start = _param_start(data)
    if start + 4 > len(data):
        return []
    endian = ">" if data[start + 3] == 86 else "<"
    end = min(start + max(data[start + 2], 1) * BLOCK, len(data))
    records, pos = [], start + 4
    while pos + 4 <= end and len(records) < 1000:
        n_chars, group = struct.unpack_from("bb", data, pos)
        if n_chars == 0:
            break
        name_end = pos + 2 + abs(n_chars)
        if name_end + 4 > end:
            break
        offset = struct.unpack_from(endian + "h", data, name_end)[0]
        if group > 0:
            kind, n_dims = struct.unpack_from("bB", data, name_end + 2)
            name = bytes(data[pos + 2:name_end]).decode("latin-1")
            records.append((name, kind, name_end + 4, name_end + 4 + n_dims))
        if offset <= 0:
            break
        pos = name_end + offset
    return records


def _pack_float(data: bytearray, at: int, value: float) -> None:
    """Write ``value`` as an Intel float32 at ``at`` (beyond float32's range: infinity)."""
    with np.errstate(over="ignore"):
        data[at:at + 4] = np.array([value], dtype="<f4").tobytes()


def _c3d_header(data: bytearray, rng: np.random.Generator) -> str:
    word = int(rng.integers(1, 12))  # 16-bit words 2..12 of the header (1-based)
    if word in (6, 10) and rng.random() < 0.7:  # the scale and rate floats
        value = FLOATS[rng.integers(len(FLOATS))] * (1 if rng.random() < 0.5 else float(rng.uniform(-5, 5)))
        _pack_float(data, 2 * word, value)
        return f"header float at byte {2 * word} = {value:g}"
    value = int(rng.choice(WORDS)) if rng.random() < 0.7 else int(rng.integers(0, 65536))
    struct.pack_into("<H", data, 2 * word, value)
    return f"header word {word + 1} = {value}"


def _c3d_absurd(data: bytearray, rng: np.random.Generator) -> str:
    """The issue's named absurdities: 60,000 points, 2^31 frames, negative scales."""
    what = rng.integers(5)
    records = {name: (kind, dims, value) for name, kind, dims, value in _param_records(data)}
    if what == 0:
        struct.pack_into("<H", data, 2, 60000)
        if "USED" in records and records["USED"][0] == 2:
            struct.pack_into("<H", data, records["USED"][2], 60000)
        return "60000 points"
    if what == 1 and "FRAMES" in records:
        kind, _, at = records["FRAMES"]
        if kind == 4:
            struct.pack_into("<f", data, at, 2.0 ** 31)
        else:
            struct.pack_into("<H", data, at, 65535)
        struct.pack_into("<HH", data, 6, 1, 65535)
        return "2^31 frames"
    if what == 2:
        scale = struct.unpack_from("<f", data, 12)[0]
        struct.pack_into("<f", data, 12, -scale)
        if "SCALE" in records and records["SCALE"][0] == 4:
            at = records["SCALE"][2]
            struct.pack_into("<f", data, at, -struct.unpack_from("<f", data, at)[0])
        return "scale negated"
    if what == 3:
        data[0] = int(rng.choice([0, 1, 2, 255, int(rng.integers(256))]))
        return f"parameter block {data[0]}"
    struct.pack_into("<H", data, 16, int(rng.choice([0, 1, 65535, int(rng.integers(65536))])))
    return "data start moved"


def _c3d_param_bytes(data: bytearray, rng: np.random.Generator) -> str:
    start = _param_start(data)
    end = min(start + max(data[start + 2] if start + 2 < len(data) else 1, 1) * BLOCK, len(data))
    if end <= start:
        return "no parameter section"
    n = int(rng.integers(1, 9))
    for at in rng.integers(start, end, n):
        data[at] = int(rng.integers(256))
    return f"{n} parameter bytes"


def _c3d_param_value(data: bytearray, rng: np.random.Generator) -> str:
    records = _param_records(data)
    if not records:
        return "no parameters"
    name, kind, dims, at = records[int(rng.integers(len(records)))]
    if rng.random() < 0.2 and at > dims:
        data[dims + int(rng.integers(at - dims))] = int(rng.choice([0, 255, int(rng.integers(256))]))
        return f"{name} dimension"
    if rng.random() < 0.1:
        data[dims - 1] = int(rng.choice([0, 7, 255]))
        return f"{name} number of dimensions"
    if at + 4 > len(data):
        return f"{name} (no room)"
    if kind == 4:
        value = FLOATS[rng.integers(len(FLOATS))]
        _pack_float(data, at, value)
        return f"{name} = {value:g}"
    if kind == 2:
        value = int(rng.choice(WORDS))
        struct.pack_into("<H", data, at, value)
        return f"{name} = {value}"
    for i in range(min(int(rng.integers(1, 5)), len(data) - at)):
        data[at + i] = int(rng.integers(256))
    return f"{name} bytes"


def _c3d_data_words(data: bytearray, rng: np.random.Generator) -> str:
    start = (struct.unpack_from("<H", data, 16)[0] - 1) * BLOCK
    if not 0 < start < len(data) - 4:
        start = len(data) // 2
    n = int(rng.integers(1, 33))
    floats = rng.random() < 0.7
    for at in rng.integers(start, len(data) - 4, n):
        at -= (at - start) % (4 if floats else 2)
        if floats:
            _pack_float(data, at, FLOATS[rng.integers(len(FLOATS))])
        else:
            struct.pack_into("<H", data, at, int(rng.choice(WORDS)))
    return f"{n} data {'floats' if floats else 'words'}"


def _c3d_truncate(data: bytearray, rng: np.random.Generator) -> str:
    cut = int(rng.integers(0, len(data) // BLOCK + 1)) * BLOCK + int(rng.choice([-1, 0, 0, 0, 1]))
    cut = min(max(cut, 0), len(data))
    del data[cut:]
    return f"cut at byte {cut}"


def _c3d_splice(data: bytearray, rng: np.random.Generator) -> str:
    blocks = len(data) // BLOCK
    if blocks < 2:
        return "no block to splice"
    at = int(rng.integers(1, blocks)) * BLOCK
    if rng.random() < 0.5:
        del data[at:at + BLOCK]
        return f"block at {at} removed"
    data[at:at] = data[at:at + BLOCK]
    return f"block at {at} doubled"


def _noise(data: bytearray, rng: np.random.Generator) -> str:
    if not data:
        return "noise on nothing"
    at = int(rng.integers(len(data)))
    n = int(rng.integers(1, 2049))
    data[at:at + n] = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
    return f"{n} random bytes at {at}"


def _append(data: bytearray, rng: np.random.Generator) -> str:
    n = int(rng.integers(1, 4)) * BLOCK + int(rng.integers(0, 3))
    data += rng.integers(0, 256, n, dtype=np.uint8).tobytes() if rng.random() < 0.5 else bytes(n)
    return f"{n} bytes appended"


C3D_MUTATIONS: dict[str, Callable[[bytearray, np.random.Generator], str]] = {
    "header": _c3d_header, "absurd": _c3d_absurd, "param_bytes": _c3d_param_bytes,
    "param_value": _c3d_param_value, "data_words": _c3d_data_words, "truncate": _c3d_truncate,
    "splice": _c3d_splice, "noise": _noise, "append": _append,
}


# --- text mutations (TRC, TSV) ---------------------------------------------------------------

def _lines(data: bytearray) -> list[bytes]:
    return bytes(data).split(b"\n")


def _set_lines(data: bytearray, lines: list[bytes]) -> None:
    data[:] = b"\n".join(lines)


def _header_count(data: bytearray) -> int:
    """How many lines the header takes: TRC 5, TSV up to the first data row."""
    lines = _lines(data)
    if data.startswith(b"PathFileType"):
        return 5
    return next((i for i, line in enumerate(lines) if line[:1].isdigit()), len(lines))


def _text_header_field(data: bytearray, rng: np.random.Generator) -> str:
    lines = _lines(data)
    row = 2 if data.startswith(b"PathFileType") else int(rng.integers(max(_header_count(data) - 1, 1)))
    fields = lines[row].split(b"\t")
    col = int(rng.integers(len(fields))) if row == 2 else min(1, len(fields) - 1)
    value = COUNTS[rng.integers(len(COUNTS))]
    fields[col] = value.encode()
    lines[row] = b"\t".join(fields)
    _set_lines(data, lines)
    return f"header line {row + 1} field {col + 1} = {value!r}"


def _text_tokens(data: bytearray, rng: np.random.Generator) -> str:
    lines = _lines(data)
    first = _header_count(data)
    if first >= len(lines) - 1:
        return "no data rows"
    n = int(rng.integers(1, 17))
    for _ in range(n):
        row = int(rng.integers(first, len(lines)))
        fields = lines[row].split(b"\t")
        fields[int(rng.integers(len(fields)))] = TOKENS[rng.integers(len(TOKENS))].encode()
        lines[row] = b"\t".join(fields)
    _set_lines(data, lines)
    return f"{n} data fields"


def _text_truncate(data: bytearray, rng: np.random.Generator) -> str:
    lines = _lines(data)
    row = int(rng.integers(len(lines)))
    cut = len(b"\n".join(lines[:row])) + (int(rng.integers(0, len(lines[row]) + 1)) if rng.random() < 0.5 else 0)
    del data[cut:]
    return f"cut at byte {cut} (line {row + 1})"


def _text_columns(data: bytearray, rng: np.random.Generator) -> str:
    lines = _lines(data)
    row = int(rng.integers(len(lines)))
    what = rng.integers(4)
    if what == 0:
        lines[row] = lines[row].replace(b"\t", b"", 1)
    elif what == 1:
        lines[row] = lines[row] + b"\t" * int(rng.integers(1, 10))
    elif what == 2:
        lines.insert(row, lines[row])
    else:
        del lines[row]
    _set_lines(data, lines)
    return ["tab removed", "tabs added", "line doubled", "line removed"][what] + f" at line {row + 1}"


def _text_bytes(data: bytearray, rng: np.random.Generator) -> str:
    at = int(rng.integers(len(data) + 1))
    junk = [b"\xff\xfe", b"\x00", b"\r", b"\xc3", b"\xef\xbb\xbf", "é".encode(), b"\t\t\t"][rng.integers(7)]
    data[at:at] = junk
    return f"{junk!r} inserted at {at}"


TEXT_MUTATIONS: dict[str, Callable[[bytearray, np.random.Generator], str]] = {
    "header_field": _text_header_field, "tokens": _text_tokens, "truncate": _text_truncate,
    "columns": _text_columns, "bytes": _text_bytes, "noise": _noise,
}


# --- cases -----------------------------------------------------------------------------------

def mutate(seed: Seed, rng: np.random.Generator) -> tuple[tuple[str, ...], bytes]:
    """One to three mutations of ``seed``; their descriptions and the mutated bytes."""
    table = C3D_MUTATIONS if seed.ext == ".c3d" else TEXT_MUTATIONS
    names = list(table)
    data = bytearray(seed.data)
    done = []
    for _ in range(int(rng.choice([1, 1, 1, 2, 3]))):
        kind = names[int(rng.integers(len(names)))]
        try:
            done.append(f"{kind}: {table[kind](data, rng)}")
        except (struct.error, IndexError, ValueError):  # an earlier mutation left too little to change
            done.append(f"{kind}: nothing to change")
    return tuple(done), bytes(data)


def truncations(seeds: list[Seed], data_blocks: int = 8) -> list[tuple[Seed, int]]:
    """Every block boundary of every C3D seed's header and parameter section and of the first
    ``data_blocks`` blocks of its data (and every boundary of a seed of up to 128 blocks); every
    line boundary of a text seed's header and first rows."""
    cuts = []
    for seed in seeds:
        if seed.ext == ".c3d":
            blocks = len(seed.data) // BLOCK
            head = _param_start(seed.data) // BLOCK + max(seed.data[_param_start(seed.data) + 2], 1) \
                if _param_start(seed.data) + 2 < len(seed.data) else blocks
            last = blocks if blocks <= 128 else min(blocks, head + data_blocks)
            cuts += [(seed, k * BLOCK) for k in range(last + 1)]
        else:
            ends = [i for i, byte in enumerate(seed.data) if byte == 10][:_header_count(bytearray(seed.data)) + 4]
            cuts += [(seed, 0)] + [(seed, end + 1) for end in ends]
    return cuts


def cases(seeds: list[Seed], n: int, master_seed: int = 0, start: int = 0, step: int = 1,
          systematic: bool = True) -> Iterator[Case]:
    """Cases ``start``, ``start + step``, ... below ``n``: first the truncations (when
    ``systematic``), then random mutations, a third of them on each format (C3D, TRC, TSV)
    where the seeds have it."""
    cuts = truncations(seeds) if systematic else []
    by_ext: dict[str, list[Seed]] = {}
    for seed in seeds:
        by_ext.setdefault(seed.ext, []).append(seed)
    formats = sorted(by_ext)
    for index in range(start, n, step):
        if index < len(cuts):
            seed, cut = cuts[index]
            yield Case(index, seed, (f"truncate: cut at byte {cut} (a block or line boundary)",), seed.data[:cut])
            continue
        rng = np.random.default_rng([master_seed, index])
        group = by_ext[formats[int(rng.integers(len(formats)))]]
        seed = group[int(rng.integers(len(group)))]
        mutations, data = mutate(seed, rng)
        yield Case(index, seed, mutations, data)


# --- running a case --------------------------------------------------------------------------

def _status_mb(field_name: str) -> float:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field_name + ":"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def _reset_peak() -> None:
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")  # VmHWM back to the current resident size
    except OSError:
        pass


class _Timeout(Exception):
    pass


def _alarm(_signum, _frame):
    raise _Timeout()


def check_take(take) -> str:
    """What is wrong with a Take that a reader returned; "" when nothing is."""
    p = take.positions
    if p.dtype != np.float32 or p.ndim != 3 or p.shape[2] != 3 or len(take.names) != p.shape[1]:
        return f"bad positions {p.dtype} {p.shape} for {len(take.names)} names"
    if np.isinf(p).any():
        return "infinite coordinates"
    from mocap_autolabel.core.take import MAX_RATE, MIN_RATE

    if not (np.isfinite(take.rate) and MIN_RATE <= take.rate < MAX_RATE):  # 1e-320 Hz: a C3D of rate 0
        return f"bad rate {take.rate}"
    if any("\n" in w for w in take.warnings):
        return "a warning of several lines"
    return ""


def run_case(case: Case, folder: Path, reader: Callable | None = None) -> Outcome:
    """Write ``case`` to ``folder`` and read it with ``reader`` (``read_take`` by default)."""
    from mocap_autolabel.core.errors import MocapInputError
    from mocap_autolabel.core.take import read_take

    reader = reader or read_take
    path = folder / f"case{case.seed.ext}"
    path.write_bytes(case.data)
    _reset_peak()
    before = _status_mb("VmRSS")
    status, detail = "failure", ""
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, 6 * TIME_LIMIT_S)
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            take = reader(path)
            detail = check_take(take)
            status = "failure" if detail else "read"
        except MocapInputError as exc:
            message = str(exc)
            status, detail = "error", message
            if str(path) not in message or "\n" in message:
                status, detail = "failure", f"input error not naming the file on one line: {message!r}"
        except _Timeout:
            detail = f"no result after {6 * TIME_LIMIT_S:g} s"
        except BaseException as exc:  # noqa: BLE001 - any other exception is what the fuzzer looks for
            detail = f"{type(exc).__name__}: {exc}"
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
    seconds = time.perf_counter() - t0
    peak = max(_status_mb("VmHWM") - before, 0.0)
    if caught and status != "failure":
        status, detail = "failure", f"warning escaped: {caught[0].category.__name__}: {caught[0].message}"
    if seconds > TIME_LIMIT_S and status != "failure":
        status, detail = "failure", f"took {seconds:.1f} s"
    if peak > MEMORY_BOUND_MB and status != "failure":
        status, detail = "failure", f"peak memory grew by {peak:.0f} MB"
    return Outcome(status, seconds, peak, detail)


@dataclass
class Tally:
    """Counts over many cases, mergeable across processes."""

    cases: int = 0
    by_status: dict[str, int] = field(default_factory=dict)
    by_kind: dict[str, dict[str, int]] = field(default_factory=dict)
    failures: list[tuple[str, str]] = field(default_factory=list)
    slowest: tuple[float, str] = (0.0, "")
    peak: tuple[float, str] = (0.0, "")
    errors: dict[str, int] = field(default_factory=dict)

    def add(self, case: Case, outcome: Outcome) -> None:
        self.cases += 1
        self.by_status[outcome.status] = self.by_status.get(outcome.status, 0) + 1
        kind = f"{case.seed.ext[1:]} {case.mutations[0].split(':')[0]}"
        counts = self.by_kind.setdefault(kind, {})
        counts[outcome.status] = counts.get(outcome.status, 0) + 1
        if outcome.status == "failure" and len(self.failures) < 200:
            self.failures.append((case.label, outcome.detail))
        if outcome.status == "error":
            problem = outcome.detail.split(": ", 1)[-1]
            key = " ".join(problem.split()[:4])
            self.errors[key] = self.errors.get(key, 0) + 1
        if outcome.seconds > self.slowest[0]:
            self.slowest = (outcome.seconds, case.label)
        if outcome.peak_mb > self.peak[0]:
            self.peak = (outcome.peak_mb, case.label)

    def merge(self, other: Tally) -> None:
        self.cases += other.cases
        for key, value in other.by_status.items():
            self.by_status[key] = self.by_status.get(key, 0) + value
        for kind, counts in other.by_kind.items():
            mine = self.by_kind.setdefault(kind, {})
            for key, value in counts.items():
                mine[key] = mine.get(key, 0) + value
        for key, value in other.errors.items():
            self.errors[key] = self.errors.get(key, 0) + value
        self.failures += other.failures
        self.slowest = max(self.slowest, other.slowest)
        self.peak = max(self.peak, other.peak)
