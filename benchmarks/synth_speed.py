#!/usr/bin/env python3
"""Generation speed of synthetic takes (frames per second), all corruptions on and off.

    python benchmarks/synth_speed.py [--frames 20000] [--seeds 5]

Writes benchmarks/reports/synth_speed.md. The goal: at least 20,000 frames/s for han19 with
every corruption on, so that training sets of millions of frames are cheap.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "addon"))

from mocap_autolabel.core.layout import load_layout  # noqa: E402
from mocap_autolabel.core.synth.generate import SynthConfig, clean_config, synthesize  # noqa: E402


def measure(layout_name: str, config: SynthConfig, frames: int, seeds: int) -> list[float]:
    layout = load_layout(layout_name)
    synthesize(layout, 500, seed=0, config=config)  # warm caches and imports
    rates = []
    for seed in range(seeds):
        start = time.perf_counter()
        synthesize(layout, frames, seed=seed, config=config)
        rates.append(frames / (time.perf_counter() - start))
    return rates


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=20000)
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args()
    rows = []
    for layout in ("han19", "glove13", "tips5"):
        for label, config in (("all corruptions", SynthConfig()), ("clean", clean_config())):
            r = np.array(measure(layout, config, args.frames, args.seeds))
            rows.append((layout, label, np.median(r), r.min(), r.max()))
            print(f"{layout:8s} {label:16s} median {np.median(r):8.0f} frames/s (min {r.min():.0f}, max {r.max():.0f})")
    lines = ["# Synthetic take generation speed", "",
             f"`python benchmarks/synth_speed.py --frames {args.frames} --seeds {args.seeds}` on "
             f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, "
             f"numpy {np.__version__}. "
             "One process, one core busy. Each row: one take per seed (the seed changes the camera count, "
             "ghost rates, hand size...), frames per second of `synthesize` (motion, skinning, camera "
             "visibility, gaps, merges, ghosts, slot packing; C3D writing not included).", "",
             "| layout | corruption | median frames/s | min | max |", "|---|---|---|---|---|"]
    lines += [f"| {a} | {b} | {c:,.0f} | {d:,.0f} | {e:,.0f} |" for a, b, c, d, e in rows]
    out = ROOT / "benchmarks" / "reports" / "synth_speed.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
