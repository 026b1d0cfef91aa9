"""Batch throughput: takes per minute and frames per second with 1 and 2 jobs.

    python benchmarks/batch.py [--takes 8] [--frames 6000]

Synthetic raw han19 takes (realistic corruption), labeled with the defaults (set + vote), and once
more with the hand solved. Writes benchmarks/reports/batch.md.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "addon"))

from datasets import write_report  # noqa: E402
from mocap_autolabel.batch import BatchSettings, run_batch  # noqa: E402
from mocap_autolabel.core.formats.c3d import write_c3d  # noqa: E402
from mocap_autolabel.core.layout import load_layout  # noqa: E402
from mocap_autolabel.core.synth.generate import synthesize  # noqa: E402

REPORT = os.path.join(os.path.dirname(__file__), "reports", "batch.md")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--takes", type=int, default=8)
    parser.add_argument("--frames", type=int, default=6000)
    args = parser.parse_args()
    layout = load_layout("han19")
    lines = ["# Batch benchmark", "", f"`python benchmarks/batch.py`: {args.takes} synthetic raw han19 takes of "
             f"{args.frames:,} frames (120 Hz), on this 2-core machine.", "",
             "| work | jobs | seconds | takes/min | frames/s | speed-up |", "|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        takes = os.path.join(tmp, "takes")
        os.makedirs(takes)
        for seed in range(args.takes):
            write_c3d(synthesize(layout, args.frames, seed=seed).take, os.path.join(takes, f"take{seed}.c3d"))
        for work, settings in (("label", {}), ("label + solve hand", {"solve_hand": True})):
            base = None
            for jobs in (1, 2):
                out = os.path.join(tmp, f"out-{work}-{jobs}".replace(" ", ""))
                s = run_batch([takes], out, BatchSettings(jobs=jobs, **settings), progress="none")
                assert s["failed"] == 0, s
                base = base or s["seconds"]
                lines.append(f"| {work} | {jobs} | {s['seconds']:.1f} | {60 * s['takes'] / s['seconds']:.1f} | "
                             f"{s['frames_processed'] / s['seconds']:,.0f} | {base / s['seconds']:.2f}x |")
                print(lines[-1], flush=True)
    lines += ["", "Each job is a spawned process; with 2 jobs each labeler runs one ONNX thread (they run two "
              "otherwise), so the speed-up shows what process parallelism adds on top of the threads.", ""]
    write_report(REPORT, lines)


if __name__ == "__main__":
    main()
