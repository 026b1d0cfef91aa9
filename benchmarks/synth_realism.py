#!/usr/bin/env python3
"""How realistic are the synthetic takes? Real recordings beside the generator, same layouts.

1. Gaps (occlusion) on the real Qualisys glove recording (glove13, 100 Hz) against synthetic
   glove13 takes at 100 Hz: % missing per marker, gaps per marker per minute, gap lengths.
2. Inter-marker distances on the Han et al. dense-19 recordings against synthetic han19 takes:
   the median and spread of the distance of every marker pair.

Writes benchmarks/reports/synth_realism.md and synth_realism.png. Needs ../shared/data (or
MOCAP_DATA) and matplotlib (``pip install -e .[bench]``). Not a test: it measures.

    python benchmarks/synth_realism.py [--takes 12]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "addon"))

from mocap_autolabel.core.layout import load_layout  # noqa: E402
from mocap_autolabel.core.synth.generate import SynthConfig, synthesize  # noqa: E402
from mocap_autolabel.core.take import read_take  # noqa: E402
from mocap_autolabel.core.tracklets import mask_runs  # noqa: E402

DATA = Path(os.environ.get("MOCAP_DATA", ROOT.parent / "shared" / "data"))
REPORTS = ROOT / "benchmarks" / "reports"


def gap_stats(present: np.ndarray, rate: float) -> dict:
    """Occlusion statistics of a presence mask ``(frames, markers)``."""
    frames, markers = present.shape
    minutes = frames / rate / 60
    column, start, stop = mask_runs(~present)
    lengths = (stop - start) / rate
    per_marker = np.bincount(column, minlength=markers) / minutes
    missing = 100 * (1 - present.mean(axis=0))
    return {
        "missing_mean_pct": float(missing.mean()),
        "missing_max_pct": float(missing.max()),
        "markers_with_gaps_pct": float(100 * np.mean(missing > 0)),
        "gaps_per_marker_min": float(np.mean(per_marker)),
        "gap_mean_s": float(lengths.mean()) if lengths.size else 0.0,
        "gap_median_s": float(np.median(lengths)) if lengths.size else 0.0,
        "gap_p90_s": float(np.percentile(lengths, 90)) if lengths.size else 0.0,
        "lengths": lengths,
    }


def presence_from_truth(labels: np.ndarray, n_markers: int) -> np.ndarray:
    return np.stack([(labels == m).any(axis=1) for m in range(n_markers)], axis=1)


def pair_distances(points: np.ndarray) -> np.ndarray:
    """``(frames, M, 3)`` -> ``(frames, M*(M-1)/2)`` distances in mm (NaN where either is missing)."""
    iu = np.triu_indices(points.shape[1], 1)
    return np.linalg.norm(points[:, iu[0]] - points[:, iu[1]], axis=-1) * 1000


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--takes", type=int, default=12, help="synthetic takes per comparison")
    parser.add_argument("--han-files", type=int, default=48, help="real han2018 files to read")
    args = parser.parse_args()
    glove_path = DATA / "hands" / "qualisys_glove13" / "recording_part1.tsv"
    han_dir = DATA / "hands" / "han2018_dense19"
    if not glove_path.exists() or not han_dir.exists():
        print(f"real hand data not found under {DATA}; nothing to compare", file=sys.stderr)
        return 1

    # 1. Gaps
    glove = load_layout("glove13")
    real = read_take(glove_path)
    cols = [real.names.index(n) for n in glove.names]
    real_gaps = gap_stats(real.valid[:, cols], real.rate)
    config = dataclasses.replace(SynthConfig(), rate=real.rate)
    synth_present = []
    for seed in range(args.takes):
        s = synthesize(glove, real.n_frames, seed=1000 + seed, config=config)
        synth_present.append(presence_from_truth(s.labels, len(glove)))
    synth_gaps = gap_stats(np.concatenate(synth_present, axis=0), real.rate)

    # 2. Distances
    han = load_layout("han19")
    files = sorted(han_dir.rglob("*.trc"))
    pick = files[:: max(1, len(files) // args.han_files)][: args.han_files]
    real_d = np.concatenate([pair_distances(read_take(f).positions) for f in pick], axis=0)
    synth_d = np.concatenate([pair_distances(synthesize(han, 2000, seed=2000 + s).markers)
                              for s in range(args.takes)], axis=0)
    real_med, synth_med = np.nanmedian(real_d, axis=0), np.nanmedian(synth_d, axis=0)
    rel = synth_med / real_med - 1
    iu = np.triu_indices(len(han), 1)
    pair_names = [f"{han.names[a]}-{han.names[b]}" for a, b in zip(*iu)]
    real_iqr = np.nanpercentile(real_d, 75, axis=0) - np.nanpercentile(real_d, 25, axis=0)
    synth_iqr = np.nanpercentile(synth_d, 75, axis=0) - np.nanpercentile(synth_d, 25, axis=0)
    neighbours = ["BackHand1-BackHand2", "BackHand2-BackHand3", "BackHand1-MiddleMCP", "ThumbCMC-ThumbMCP",
                  "ThumbMCP-ThumbIP", "ThumbIP-ThumbTip", "IndexMCP-IndexPIP", "IndexPIP-IndexTip",
                  "MiddleMCP-MiddlePIP", "MiddlePIP-MiddleTip", "RingMCP-RingPIP", "RingPIP-RingTip",
                  "PinkyMCP-PinkyPIP", "PinkyPIP-PinkyTip", "IndexMCP-MiddleMCP", "MiddleMCP-RingMCP",
                  "RingMCP-PinkyMCP", "ThumbTip-IndexTip", "ThumbCMC-IndexMCP", "BackHand3-ThumbCMC"]

    lines = ["# Synthetic takes against real recordings", "",
             f"Generated by `python benchmarks/synth_realism.py` ({args.takes} synthetic takes per comparison, "
             "default `SynthConfig`).", "",
             "## Occlusion: real Qualisys glove13 recording vs synthetic glove13 takes (100 Hz)", "",
             f"Real: {real.n_frames} frames ({real.n_frames / real.rate:.0f} s), 13 hand markers. "
             f"Synthetic: {args.takes} x {real.n_frames} frames.", "",
             "| statistic | real | synthetic |", "|---|---|---|"]
    for key, label in [("missing_mean_pct", "% missing, mean over markers"),
                       ("missing_max_pct", "% missing, worst marker"),
                       ("markers_with_gaps_pct", "% of markers with any gap"),
                       ("gaps_per_marker_min", "gaps per marker per minute"),
                       ("gap_mean_s", "gap length, mean (s)"), ("gap_median_s", "gap length, median (s)"),
                       ("gap_p90_s", "gap length, 90th percentile (s)")]:
        lines.append(f"| {label} | {real_gaps[key]:.2f} | {synth_gaps[key]:.2f} |")
    lines += ["", "## Inter-marker distances: Han et al. dense-19 vs synthetic han19 (mm)", "",
              f"Real: {len(pick)} of {len(files)} TRC files ({real_d.shape[0]} frames). "
              f"Synthetic: {args.takes} x 2000 frames, true marker centres.", "",
              f"Over all {len(pair_names)} pairs: median |relative difference of the medians| "
              f"{100 * np.median(np.abs(rel)):.1f} %, 90th percentile {100 * np.percentile(np.abs(rel), 90):.1f} %, "
              f"pairs within 25 %: {100 * np.mean(np.abs(rel) <= 0.25):.0f} %.", "",
              "| pair | real median | synthetic median | difference | real IQR | synthetic IQR |",
              "|---|---|---|---|---|---|"]
    for name in neighbours:
        a, b = name.split("-")
        k = pair_names.index(name) if name in pair_names else pair_names.index(f"{b}-{a}")
        lines.append(f"| {name} | {real_med[k]:.1f} | {synth_med[k]:.1f} | {100 * rel[k]:+.0f} % | "
                     f"{real_iqr[k]:.1f} | {synth_iqr[k]:.1f} |")
    REPORTS.mkdir(parents=True, exist_ok=True)
    (REPORTS / "synth_realism.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    _plot(real_gaps, synth_gaps, real_med, synth_med, REPORTS / "synth_realism.png")
    return 0


def _plot(real_gaps: dict, synth_gaps: dict, real_med: np.ndarray, synth_med: np.ndarray, path: Path) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed: no plot (pip install -e .[bench])", file=sys.stderr)
        return
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.5))
    bins = np.linspace(0, 1.0, 26)
    a.hist(real_gaps["lengths"], bins=bins, density=True, alpha=0.6, label="real glove13")
    a.hist(synth_gaps["lengths"], bins=bins, density=True, alpha=0.6, label="synthetic glove13")
    a.set_xlabel("gap length (s)")
    a.set_ylabel("density")
    a.set_title("Occlusion gap lengths")
    a.legend()
    b.scatter(real_med, synth_med, s=10)
    lim = [0, max(real_med.max(), synth_med.max()) * 1.05]
    b.plot(lim, lim, "k--", lw=1)
    b.fill_between(lim, [v * 0.75 for v in lim], [v * 1.25 for v in lim], color="grey", alpha=0.15, label="+-25 %")
    b.set_xlabel("real median distance (mm), han2018")
    b.set_ylabel("synthetic median distance (mm), han19")
    b.set_title("All 171 marker pairs")
    b.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


if __name__ == "__main__":
    sys.exit(main())
