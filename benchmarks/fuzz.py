"""Fuzz the readers: mutated real C3D, TRC and TSV files; every case reads or is refused cleanly.

    python benchmarks/fuzz.py [--cases 100000] [--seed 0] [--report benchmarks/reports/fuzz.md]

The cases come from tests/fuzzing.py (the mutations, the seeds, what counts as a failure): first
every block boundary truncation of the corpus's headers and parameter sections, then random
mutations. Half the cases run in this process, half in one worker process (the machine has two
cores). Each process's address space is capped (RLIMIT_AS) so that an absurd allocation fails
as a MemoryError case instead of swapping the machine. Needs ../shared/data; exits 1 on any
failure.
"""

from __future__ import annotations

import argparse
import multiprocessing
import platform
import resource
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "addon"))
sys.path.insert(0, str(ROOT / "tests"))

import fuzzing  # noqa: E402

#: Virtual address space each process may use beyond what it holds at the start (GB).
ADDRESS_SPACE_GB = 4


def _run(part: int, parts: int, n: int, seed: int, queue) -> None:
    """Run cases ``part``, ``part + parts``, ... and put the Tally on ``queue``."""
    seeds = fuzzing.load_seeds()
    vm = fuzzing._status_mb("VmSize") * 2 ** 20
    limit = int(vm + ADDRESS_SPACE_GB * 2 ** 30)
    resource.setrlimit(resource.RLIMIT_AS, (limit, resource.getrlimit(resource.RLIMIT_AS)[1]))
    tally = fuzzing.Tally()
    t0 = time.time()
    with tempfile.TemporaryDirectory(prefix="fuzz") as folder:
        for case in fuzzing.cases(seeds, n, seed, start=part, step=parts):
            tally.add(case, fuzzing.run_case(case, Path(folder)))
            if part == 0 and tally.cases % 5000 == 0:
                print(f"{tally.cases * parts} cases, {time.time() - t0:.0f} s, {tally.by_status}", file=sys.stderr)
    queue.put(tally)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=100_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--report", default=str(ROOT / "benchmarks" / "reports" / "fuzz.md"))
    args = parser.parse_args()
    seeds = fuzzing.load_seeds()
    if not seeds:
        print(f"no corpus under {fuzzing.DATA}: nothing to fuzz", file=sys.stderr)
        return 1
    n_cuts = len(fuzzing.truncations(seeds))
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    worker = context.Process(target=_run, args=(1, 2, args.cases, args.seed, queue))
    t0 = time.time()
    worker.start()
    _run(0, 2, args.cases, args.seed, queue)
    tallies = [queue.get(), queue.get()]
    worker.join()
    wall = time.time() - t0
    tally = tallies[0]
    tally.merge(tallies[1])
    report = _report(tally, seeds, n_cuts, args, wall)
    Path(args.report).write_text(report)
    print(report)
    return 1 if tally.by_status.get("failure") else 0


def _report(tally: fuzzing.Tally, seeds, n_cuts: int, args, wall: float) -> str:
    by_ext: dict[str, int] = {}
    for s in seeds:
        by_ext[s.ext] = by_ext.get(s.ext, 0) + 1
    status = tally.by_status
    lines = [
        "# Fuzzing the readers",
        "",
        f"`python benchmarks/fuzz.py --cases {args.cases} --seed {args.seed}`: {tally.cases:,} cases in "
        f"{wall / 60:.1f} min, two processes on a shared, loaded 2-core machine ({platform.machine()}, "
        f"Python {platform.python_version()}).",
        "",
        f"Seeds: {by_ext.get('.c3d', 0)} real C3D files (every non-empty one in the corpus), "
        f"{by_ext.get('.trc', 0)} Han et al. TRC files (every 16th), and the Qualisys glove recording's "
        f"header with its first {fuzzing.TSV_ROWS} rows. Mutations are in `tests/fuzzing.py`: the first "
        f"{n_cuts:,} cases cut every C3D seed at each block boundary of its header and parameter section "
        "and its first 8 data blocks (every block of a file of up to 128 blocks), and every text seed at "
        "each line of its header and first rows; then one to three random mutations per case: header "
        "words and floats (NaN, inf, 3e38, negative), 60,000 points, 2^31 frames, negated scales, moved "
        "parameter and data starts, parameter bytes, values and dimensions, data words (NaN, inf, huge "
        "floats), blocks removed or doubled, random bytes, appended bytes; in text files header counts "
        "and rates (60000, 2^31, nan, inf, 40 digits), data fields (nan, inf, 1e300, text), cut lines, "
        "tabs, doubled or removed lines, bytes that are not UTF-8.",
        "",
        "A case fails on any exception other than `MocapInputError` (or one that does not name the file "
        "on one line), a warning that escapes the reader (numpy's included), a Take with an infinite "
        f"coordinate, a bad shape or rate, more than {fuzzing.TIME_LIMIT_S:g} s, or a growth of the "
        f"process's peak resident memory (VmHWM, reset before each case) over {fuzzing.MEMORY_BOUND_MB:g} "
        f"MB, the bound stated here. Each process's address space is capped at its size at the start plus "
        f"{ADDRESS_SPACE_GB} GB (RLIMIT_AS), so that an allocation sized by an absurd count fails as a case "
        "(MemoryError) instead of swapping the machine.",
        "",
        "| cases | read | clean errors | failures |",
        "|---:|---:|---:|---:|",
        f"| {tally.cases:,} | {status.get('read', 0):,} | {status.get('error', 0):,} | {status.get('failure', 0):,} |",
        "",
        f"- Slowest case: {tally.slowest[0]:.2f} s, {tally.slowest[1]}",
        f"- Largest peak memory growth: {tally.peak[0]:.1f} MB (bound {fuzzing.MEMORY_BOUND_MB:g} MB), "
        f"{tally.peak[1]}",
        "",
        "## By format and first mutation",
        "",
        "| format, mutation | read | clean errors | failures |",
        "|---|---:|---:|---:|",
    ]
    for kind, counts in sorted(tally.by_kind.items()):
        lines.append(f"| {kind} | {counts.get('read', 0):,} | {counts.get('error', 0):,} | "
                     f"{counts.get('failure', 0):,} |")
    lines += ["", "## Most frequent clean errors (first words of the message)", "",
              "| count | message |", "|---:|---|"]
    for key, count in sorted(tally.errors.items(), key=lambda kv: -kv[1])[:12]:
        lines.append(f"| {count:,} | {key.replace('|', '/')} |")
    if tally.failures:
        lines += ["", "## Failures (first 50)", ""]
        lines += [f"- {label}: {detail}" for label, detail in tally.failures[:50]]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
