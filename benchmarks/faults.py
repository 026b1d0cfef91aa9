"""Faults in batch: a worker process killed at 10 random points per mode; nothing lost, nothing half-written.

    python benchmarks/faults.py [--runs 10] [--takes 4] [--frames 1500]

Each run labels the same synthetic takes with ``--jobs 2`` (a pool of spawned processes) or on a local
Dask cluster of 2 workers, while one worker process is killed (SIGKILL) at a random moment. Checked per
run: every take ok (the killed take was run again), no temporary file left, a rerun skips everything,
and the outputs are byte for byte those of an undisturbed run. Writes benchmarks/reports/faults.md.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "addon"))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))

from datasets import write_report  # noqa: E402
from helpers import run_killing_a_worker, same_outputs  # noqa: E402
from mocap_autolabel.batch import BatchSettings, run_batch  # noqa: E402
from mocap_autolabel.core.formats.c3d import write_c3d  # noqa: E402
from mocap_autolabel.core.layout import load_layout  # noqa: E402
from mocap_autolabel.core.synth.generate import synthesize  # noqa: E402

REPORT = os.path.join(HERE, "reports", "faults.md")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--takes", type=int, default=4)
    parser.add_argument("--frames", type=int, default=1500)
    args = parser.parse_args()
    rng = np.random.default_rng(2024)
    lines = ["# Faults in batch", "", f"`python benchmarks/faults.py`: {args.takes} synthetic han19 takes of "
             f"{args.frames:,} frames; per mode {args.runs} runs, each with one worker process killed (SIGKILL) at a "
             "random moment of the run; on a shared, loaded 2-core machine.", "",
             "| mode | run | killed at (s) | killed | takes ok | run (s) | temporary files left | rerun skips all | "
             "bytes as undisturbed |", "|---|---|---|---|---|---|---|---|---|"]
    failures = 0
    with tempfile.TemporaryDirectory() as tmp:
        takes = os.path.join(tmp, "takes")
        os.makedirs(takes)
        for seed in range(args.takes):
            take = synthesize(load_layout("han19"), args.frames, seed=seed).take
            write_c3d(take, os.path.join(takes, f"t{seed}.c3d"))
        ref = os.path.join(tmp, "ref")
        base = run_batch([takes], ref, BatchSettings(), progress="none")
        modes = (("--jobs 2", BatchSettings(jobs=2)), ("Dask local:2", BatchSettings(scheduler="local:2")))
        for mode, settings in modes:
            for run in range(args.runs):
                out = os.path.join(tmp, f"{mode}-{run}".replace(" ", ""))
                delay = float(rng.uniform(0.2, 0.8 * base["seconds"] + 2))
                start = time.perf_counter()
                summary, killed = run_killing_a_worker(
                    lambda out=out, settings=settings: run_batch([takes], out, settings, progress="none"), delay, rng)
                took = time.perf_counter() - start
                left = [p for p in os.listdir(out) if ".partial" in p]
                rerun = run_batch([takes], out, settings, progress="none")
                try:
                    same_outputs(ref, out)
                    same = True
                except AssertionError:
                    same = False
                ok = summary["ok"] == args.takes and not left and rerun["skipped"] == args.takes and same
                failures += not ok
                lines.append(f"| {mode} | {run + 1} | {delay:.1f} | {'yes' if killed else 'no (run ended first)'} | "
                             f"{summary['ok']}/{args.takes} | {took:.1f} | {len(left)} | "
                             f"{'yes' if rerun['skipped'] == args.takes else 'no'} | {'yes' if same else 'NO'} |")
                print(lines[-1], flush=True)
    lines += ["", f"{failures} failed runs. A killed pool process breaks the whole pool: its unfinished takes run "
              "again in a new pool (each up to 3 times); Dask reschedules the dead worker's task on a worker "
              "(the nanny restarts the dead one). The killed take's temporary file is removed at the end of the run.",
              ""]
    write_report(REPORT, lines)


if __name__ == "__main__":
    main()
