"""``python -m training.confidence``: calibrate segment confidences on synthetic validation takes.

For each shipped layout and temporal mode of the ``set`` method, label synthetic takes (the
generator's realistic takes, and clean tracks broken up by ``corrupt_take``), record each
segment's raw confidence and whether it was entirely right, and fit the monotone, conservative
map of ``core/temporal/confidence.py``. Writes ``addon/mocap_autolabel/models/confidence.json``.
Needs no PyTorch; rerun after retraining a model.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np
from mocap_autolabel.core.atomic import atomic_output
from mocap_autolabel.core.labeling import NULL
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.pipeline import label_take
from mocap_autolabel.core.synth.generate import GHOST, corrupt_take, synthesize
from mocap_autolabel.core.temporal.confidence import CALIBRATIONS, calibration_key, fit_calibration

from .recipes import SHIPPED_LAYOUTS

#: Seeds of the calibration takes: apart from the benchmarks' and the tests' seeds.
SEED0 = 50_000


def validation_takes(layout, takes: int, frames: int) -> list:
    """Synthetic (take, truth) pairs: half as the generator makes them, half broken up harder."""
    out = []
    for i in range(takes):
        synth = synthesize(layout, frames, seed=SEED0 + i)
        if i % 2 == 0:
            out.append((synth.take, synth.labels))
        else:
            take, truth, _ = corrupt_take(synth.markers, synth.take.rate, seed=SEED0 + i)
            out.append((take, truth))
    return out


def segment_outcomes(labeling, take, truth) -> np.ndarray:
    """``(S, 3)``: raw confidence, entirely right (0/1) and length of every segment."""
    t = np.where(truth == GHOST, NULL, truth)
    ids = labeling.segment_ids()
    ok = take.valid
    wrong = np.bincount(ids[ok], weights=(labeling.per_sample()[ok] != t[ok]), minlength=len(labeling))
    return np.stack([labeling.confidence, wrong == 0, labeling.length], axis=1)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m training.confidence", description=__doc__.splitlines()[0])
    ap.add_argument("--takes", type=int, default=24, help="synthetic takes per layout (default 24)")
    ap.add_argument("--frames", type=int, default=3000, help="frames per take (default 3000)")
    ap.add_argument("--temporal", nargs="*", default=["vote", "none", "viterbi"])
    ap.add_argument("--out", default=CALIBRATIONS)
    args = ap.parse_args(argv)
    table = {}
    for name in SHIPPED_LAYOUTS:
        layout = load_layout(name)
        data = validation_takes(layout, args.takes, args.frames)
        for temporal in args.temporal:
            seg = np.concatenate([segment_outcomes(label_take(take, layout, temporal=temporal, calibrate=False),
                                                   take, truth) for take, truth in data])
            source = f"{len(data)} synthetic takes x {args.frames} frames, seeds {SEED0}+"
            cal = fit_calibration(seg[:, 0], seg[:, 2], seg[:, 1].astype(bool), source)
            table[calibration_key("set", temporal, name)] = cal.as_dict()
            conf = cal(seg[:, 0], seg[:, 2])
            hi = conf >= 0.95
            print(f"{name} set+{temporal}: {len(seg)} segments, {100 * seg[:, 1].mean():.2f} % right; "
                  f"{100 * hi.mean():.1f} % at >= 0.95, of which {100 * seg[hi, 1].mean():.3f} % right",
                  file=sys.stderr)
    with atomic_output(args.out) as tmp, open(tmp, "w", encoding="utf-8") as fh:
        json.dump(table, fh, indent=1, sort_keys=True)
    print(f"wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
