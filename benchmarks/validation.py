"""IK validation's effect on labeling: the default pipeline with and without ``validate=True``.

    python benchmarks/validation.py [--every N]

Same data as benchmarks/temporal.py: (a) han2018 sequences made raw by ``corrupt_take`` (every
N-th take, default 4, since validation calibrates a hand per take), (b) the real glove13 recording.
Writes benchmarks/reports/validation.md.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "addon"))
sys.path.insert(0, os.path.dirname(__file__))

from datasets import write_report  # noqa: E402
from mocap_autolabel.core.layout import load_layout  # noqa: E402
from mocap_autolabel.core.metrics import score_labeling, segments_right  # noqa: E402
from mocap_autolabel.core.pipeline import label_take  # noqa: E402
from mocap_autolabel.core.settings import LabelSettings  # noqa: E402
from temporal import glove_case, han_cases  # noqa: E402

REPORT = os.path.join(os.path.dirname(__file__), "reports", "validation.md")


def measure(cases, layout, validate: bool) -> dict:
    out = dict.fromkeys(("correct", "instances", "frames_all_correct", "frames", "sure", "sure_right"), 0)
    out["seconds"] = 0.0
    for c in cases:
        t = time.perf_counter()
        labeling = label_take(c.take, layout, LabelSettings(validate=validate))
        out["seconds"] += time.perf_counter() - t
        s = score_labeling(labeling.per_sample(), c.truth, c.take.valid, len(layout)).as_dict()
        for key in ("correct", "instances", "frames_all_correct", "frames"):
            out[key] += s[key]
        sure = labeling.confidence >= 0.95
        out["sure"] += int(sure.sum())
        out["sure_right"] += int((sure & (segments_right(labeling, c.truth, c.take.valid) > 0)).sum())
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--every", type=int, default=4, help="use every N-th han2018 take (default 4)")
    args = parser.parse_args()
    lines = ["# IK validation benchmark", "", "`python benchmarks/validation.py`: `set` + `vote`, without and with "
             "IK validation (`label_take(validate=True)`, CLI `label --validate`).", "",
             "| data | takes | validation | correct | frames all correct | segments >= 0.95 | of those right | "
             "frames/s |", "|---|---|---|---|---|---|---|---|"]
    han = load_layout("han19")
    sets = [("(a) han2018 raw", han, han_cases(han, None)[::args.every])]
    glove = load_layout("glove13")
    sets.append(("(b) glove13 real", glove, [glove_case(glove)]))
    for name, layout, cases in sets:
        for validate in (False, True):
            r = measure(cases, layout, validate)
            frames = sum(c.take.n_frames for c in cases)
            lines.append(f"| {name} | {len(cases)} | {'on' if validate else 'off'} | "
                         f"{100 * r['correct'] / r['instances']:.2f} % | "
                         f"{100 * r['frames_all_correct'] / r['frames']:.2f} % | {r['sure']} | "
                         f"{100 * r['sure_right'] / max(r['sure'], 1):.2f} % | {frames / r['seconds']:,.0f} |")
            print(lines[-1], flush=True)
    lines += ["", "Validation calibrates a hand on the take's confident labels, solves it on all labels "
              "(a sample more than 16 mm off the first fit is left out of the second), adds every point's "
              "distance to the fitted markers to the labeler's scores (sigma = max(4 mm, 2 x fit RMS)), votes "
              "again, and caps at 0.5 the confidence of segments whose median residual exceeds the 8 mm gate.", ""]
    write_report(REPORT, lines)


if __name__ == "__main__":
    main()
