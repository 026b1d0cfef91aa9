"""Import speed: read a large C3D and build its Blender scene; seconds, samples/s, peak memory.

    python benchmarks/import_speed.py [--frames 100000] [--points 50] [--report benchmarks/reports/import_speed.md]

Each stage runs in a fresh process. Peak memory is the growth of the process's peak
resident size (VmHWM, reset through /proc/self/clear_refs just before the stage) over its
resident size before the stage: it counts numpy's and Blender's own allocations alike.
Goal on a 2-core machine: >= 2 million samples/s for each stage, and peak memory at most
3x the raw float32 size of the positions (frames x points x 3 x 4 bytes).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "addon"))


def _status_mb(field: str) -> float:
    """A memory figure of this process from /proc/self/status (Linux), in MB."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024
    raise RuntimeError(f"no {field} in /proc/self/status: this benchmark needs Linux")


def _reset_peak() -> None:
    # Writing 5 resets VmHWM to the current RSS (ru_maxrss cannot be reset, and is even
    # inherited across exec from the parent that generated the file).
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")


def _stage(stage: str, path: str) -> dict:
    """Run one stage in this process and return its figures."""
    import gc

    import numpy as np  # noqa: F401  (imported before measuring)
    from mocap_autolabel.core.take import read_take

    if stage == "build":
        import bpy
        from mocap_autolabel.blender.scene import build_take

        bpy.ops.wm.read_factory_settings(use_empty=True)
        take = read_take(path)
    gc.collect()
    _reset_peak()
    rss0 = _status_mb("VmRSS")
    t0 = time.perf_counter()
    if stage == "read":
        take = read_take(path)
    else:
        build_take(take, bpy.context.scene)
    seconds = time.perf_counter() - t0
    samples = take.n_frames * take.n_points
    return {"stage": stage, "seconds": seconds, "samples": samples, "samples_per_s": samples / seconds,
            "peak_growth_mb": _status_mb("VmHWM") - rss0, "raw_mb": samples * 12 / 2**20}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100_000)
    parser.add_argument("--points", type=int, default=50)
    parser.add_argument("--report", default=os.path.join(ROOT, "benchmarks", "reports", "import_speed.md"))
    parser.add_argument("--stage", choices=["read", "build"], help=argparse.SUPPRESS)
    parser.add_argument("--file", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.stage:
        print(json.dumps(_stage(args.stage, args.file)))
        return 0

    import numpy as np
    from mocap_autolabel.core.formats.c3d import write_c3d
    from mocap_autolabel.core.take import Take

    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "bench.c3d")
        t = np.arange(args.frames, dtype=np.float32)[:, None, None] / 120.0
        pos = (rng.uniform(-1, 1, (1, args.points, 3)) + 0.05 * np.sin(t * rng.uniform(1, 5, (1, args.points, 3))))
        pos = pos.astype(np.float32)
        gaps = rng.random((args.frames, args.points)) < 0.002  # gap starts
        for f, p in zip(*np.nonzero(gaps)):
            pos[f:f + 10, p] = np.nan
        write_c3d(Take(pos, [f"*{i}" for i in range(args.points)], 120.0), path)
        del pos
        rows = []
        for stage in ("read", "build"):
            out = subprocess.run([sys.executable, __file__, "--stage", stage, "--file", path],
                                 capture_output=True, text=True, check=True).stdout
            rows.append(json.loads(out.strip().splitlines()[-1]))
    lines = [
        f"# Import speed: {args.frames:,} frames x {args.points} markers",
        "",
        f"Machine: {os.cpu_count()} cores; Python {sys.version.split()[0]}. "
        f"Raw float32 positions: {rows[0]['raw_mb']:.1f} MB. Goal: >= 2 M samples/s, peak <= 3x raw.",
        "",
        "| stage | seconds | samples/s | peak memory growth (MB) | peak / raw |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['stage']} | {r['seconds']:.2f} | {r['samples_per_s'] / 1e6:.2f} M | "
                     f"{r['peak_growth_mb']:.0f} | {r['peak_growth_mb'] / r['raw_mb']:.2f}x |")
    report = "\n".join(lines) + "\n"
    print(report)
    os.makedirs(os.path.dirname(args.report), exist_ok=True)
    with open(args.report, "w") as fh:
        fh.write(report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
