"""Any marker set, no training: the shipped layout-conditioned ``set`` model on sparse finger sets.

(a) han2018_dense19 Users 1-2 sequences (after each user's first 10, which fit ``gmm``; with ``--limit``,
    that many spread evenly over each user's recording: its first takes alone are not typical of it) reduced to
    sparse sets of its own markers and corrupted exactly as the temporal benchmark corrupts its raw
    takes (``corrupt_take``, seed 1000 * user + index). Each set is a layout built from han19's own
    entries, as a user would write it. The ``*MCP`` markers sit in the band of the proximal phalanx
    that the training never samples (``core.synth.layouts.HELD_OUT``): the sets with them test
    positions the model never saw.
(b) The real qualisys_glove13 recording reduced to two subsets (labels stripped, every slot cut at
    its gaps, the body and pillow markers kept as distractors), as the temporal benchmark does.
(c) Two hands: both files of each han2018 sequence of at least 100 frames as one take, per set (spread
    over the recording as in (a)).
(d) Speed and start: a 10,000-frame synthetic take of a sparse layout written as a new TOML, through
    the ``label`` CLI, against a built-in layout.

Rows: ``set`` + vote (the default, through ``process_take`` with the no-hand rule: a refused take
counts as unlabeled), ``gmm`` fitted per subject (its hand frame needs three hand markers), ``gmm``
fitted on the layout's synthetic range of motion (no take of the performer), and ``nearest`` from
the true labels of the first frame. Writes ``benchmarks/reports/layouts.md``.

    python benchmarks/layouts.py [--limit N] [--sets NAME ...] [--no-two-hands] [--no-speed]
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import temporal  # noqa: E402
from datasets import HAN2018, glove13_take, write_report  # noqa: E402
from mocap_autolabel.core.cache import RunCache  # noqa: E402
from mocap_autolabel.core.errors import MocapInputError  # noqa: E402
from mocap_autolabel.core.labelers.gmm import GmmLabeler  # noqa: E402
from mocap_autolabel.core.layout import Layout, load_layout  # noqa: E402
from mocap_autolabel.core.metrics import clustered_se, score_labeling, segments_right  # noqa: E402
from mocap_autolabel.core.pipeline import label_take  # noqa: E402
from mocap_autolabel.core.process import Outputs, process_take  # noqa: E402
from mocap_autolabel.core.settings import LabelSettings  # noqa: E402
from mocap_autolabel.core.synth.generate import corrupt_take, save_synth, synthesize  # noqa: E402
from mocap_autolabel.core.take import Take  # noqa: E402
from temporal import Case, glove_case  # noqa: E402
from two_hands import han_pairs  # noqa: E402

REPORTS = Path(__file__).parent / "reports"
TIPS = ["ThumbTip", "IndexTip", "MiddleTip", "RingTip", "PinkyTip"]
BACK = ["BackHand1", "BackHand2", "BackHand3"]
MCP = ["ThumbMCP", "IndexMCP", "MiddleMCP", "RingMCP", "PinkyMCP"]
PIP = ["ThumbIP", "IndexPIP", "MiddlePIP", "RingPIP", "PinkyPIP"]
#: Sparse sets of han19's markers: name -> (markers, what it stands for). "held out": has markers
#: where the training never put one.
HAN_SETS = {
    "tips3": (["ThumbTip", "IndexTip", "PinkyTip"], "thumb, index and little tips"),
    "tips5": (TIPS, "fingertips only"),
    "tips3+back": (["ThumbTip", "IndexTip", "PinkyTip"] + BACK, "3 tips + a hand cluster"),
    "tips5+back": (TIPS + BACK, "fingertips + a hand cluster"),
    "tips+pip": (TIPS + PIP, "tips + middle phalanges (thumb: distal base)"),
    "tips+pip+back": (TIPS + PIP + BACK, "tips + middle phalanges + a hand cluster"),
    "tips+mcp (held out)": (TIPS + MCP, "tips + proximal phalanges, held-out positions"),
    "tips+mcp+back (held out)": (TIPS + MCP + BACK, "tips + proximal phalanges + hand cluster, held-out positions"),
    "index-thumb3+back": (["ThumbTip", "IndexTip", "MiddleTip"] + BACK, "thumb, index, middle tips + hand cluster"),
}
GLOVE_SETS = {
    "glove tips5+hand": (["thumb_tip", "index_tip", "middle_tip", "ring_tip", "little_tip", "hand_top", "hand_left",
                          "hand_right"], "fingertips + the three back-of-hand markers"),
    "glove tips+middles": (["thumb_tip", "index_tip", "middle_tip", "ring_tip", "little_tip", "thumb_middle",
                            "index_middle", "middle_middle", "ring_middle", "little_middle"],
                           "fingertips + proximal phalanges, no hand markers"),
}
COUNTS = ("instances", "correct", "frames", "frames_all_correct")
#: The row of set's labels without the no-hand rule: how much of a refusal is the rule's.
UNCHECKED = "set, no hand rule"
#: ``gmm`` without the performer's take: fitted on the layout's synthetic range of motion.
ROM = "gmm, synthetic ROM"
CONFIDENT = 0.95


def subset(layout: Layout, names: list[str], name: str) -> Layout:
    """``layout`` reduced to ``names`` (in that order): what a user writes from its entries."""
    by_name = {m.name: m for m in layout.markers}
    return Layout(name, tuple(by_name[n] for n in names), layout.glove, f"{layout.name} subset")


def has_hand_markers(layout: Layout) -> bool:
    return sum(m.bone == "palm" for m in layout.markers) >= 3


def spread(count: int, limit: int | None) -> np.ndarray:
    """Indices of ``limit`` of ``count`` items spread evenly over them (all where None or more)."""
    if limit is None or limit >= count:
        return np.arange(count)
    return np.unique(np.linspace(0, count - 1, limit).round().astype(int))


def han_cases(han19: Layout, names: list[str], limit: int | None) -> list[Case]:
    from datasets import han2018_sequences

    cols = [han19.names.index(n) for n in names]
    cases = []
    for u, user in enumerate(("User1", "User2")):
        seqs = [s[:, cols] for s in han2018_sequences(han19, user=user)]
        fit = np.concatenate(seqs[:10])
        for i in spread(len(seqs) - 10, limit):
            s = seqs[10 + i]
            take, truth, _ = corrupt_take(s, 120.0, seed=1000 * u + i)
            cases.append(Case(take, truth, fit, s[0]))
    return cases


def glove_subset_case(layout: Layout, fit_frames: int = 600) -> Case:
    """The real glove recording reduced to ``layout``'s markers (the glove's others removed, the body and
    pillow markers kept as distractors), cut and packed as the temporal benchmark does."""
    glove13 = load_layout("glove13")
    take, slot = glove13_take(glove13)
    keep = [i for i, s in enumerate(slot) if s < 0 or glove13.names[s] in layout.names]
    reduced = Take(positions=take.positions[:, keep], names=[take.names[i] for i in keep], rate=take.rate,
                   source=take.source)
    original = glove13_take
    try:  # glove_case reads the recording through datasets.glove13_take: hand it the reduced take
        temporal.glove13_take = lambda lay: (reduced, np.array([lay.names.index(n) if n in lay.names else -1
                                                                for n in reduced.names]))
        return glove_case(layout, fit_frames)
    finally:
        temporal.glove13_take = original


def run(cases: list[Case], layout: Layout, method: str) -> dict:
    """Totals of one method on the cases; a refused take (one line) counts as unlabeled."""
    per_take, segments, refused, seconds = [], [], [], 0.0
    fitted: dict[int, GmmLabeler] = {}
    rom_cache = RunCache()  # one range-of-motion fit per layout, as a batch run keeps it
    for c in cases:
        t = time.perf_counter()
        labeler = None
        try:
            if method == "gmm":
                labeler = fitted.get(id(c.fit)) or GmmLabeler(layout).fit(c.fit)
                fitted[id(c.fit)] = labeler
            if method == UNCHECKED:  # what set labels where the no-hand rule refuses the take
                labeling = label_take(c.take, layout, LabelSettings())
            elif method == ROM:
                labeling = process_take(c.take, layout, LabelSettings(method="gmm"), Outputs(check_layout=False),
                                        cache=rom_cache).labeling
            else:
                result = process_take(c.take, layout, LabelSettings(method=method), Outputs(check_layout=False),
                                      labeler=labeler, start=c.start if method == "nearest" else None)
                labeling = result.labeling
        except (MocapInputError, ValueError) as exc:
            refused.append(str(exc).splitlines()[0][:160])
            per_take.append([int(c.take.valid[c.truth >= 0].sum()), 0, c.take.n_frames, 0])
            continue
        finally:
            seconds += time.perf_counter() - t
        s = score_labeling(labeling.per_sample(), c.truth, c.take.valid, len(layout)).as_dict()
        per_take.append([s[k] for k in COUNTS])
        right = segments_right(labeling, c.truth, c.take.valid)
        segments.append(np.stack([labeling.confidence, right, labeling.length], axis=1))
    rows = np.array(per_take, dtype=np.int64).reshape(-1, len(COUNTS))
    seg = np.concatenate(segments) if segments else np.zeros((0, 3))
    sure = seg[:, 0] >= CONFIDENT
    labeled_sure = sure & (seg[:, 2] > 0)
    return {"rows": rows, "refused": refused, "seconds": seconds,
            "confident_right": float(seg[labeled_sure, 1].mean()) if labeled_sure.any() else float("nan"),
            "confident_segments": int(labeled_sure.sum())}


def run_two_hands(han19: Layout, names: list[str], name: str, limit: int | None) -> dict:
    layout = subset(han19, names, name)
    cols = [han19.names.index(n) for n in names]
    m = len(layout)
    rows, sides = [], []
    pairs = han_pairs(han19)
    for j in spread(len(pairs), limit):
        _, seed, a, b = pairs[j]
        take, truth, _ = corrupt_take(np.concatenate([a[:, cols], b[:, cols]], axis=1), 120.0, seed=seed)
        lab = label_take(take, layout)
        s = score_labeling(lab.per_sample(), truth, take.valid, 2 * m).as_dict()
        rows.append([s[k] for k in COUNTS])
        per = lab.per_sample()
        ok = take.valid & (truth >= 0) & (per >= 0)
        sides.append(bool(lab.info["hands"]["count"] == 2 and ((truth[ok] < m) == (per[ok] < m)).mean() > 0.5))
    return {"rows": np.array(rows, dtype=np.int64), "sides": sides}


def cli_speed(layout: Layout, frames: int = 10_000) -> dict:
    """``label`` on a 10,000-frame synthetic take: ``layout`` written as a new TOML against han19."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        toml = os.path.join(tmp, "studio.toml")
        with open(toml, "w") as f:
            f.write('name = "studio"\n')
            for mk in layout.markers:
                f.write(f'[[markers]]\nname = "{mk.name}"\nbone = "{mk.bone}"\nalong = {mk.along}\n'
                        f'across = {mk.across}\nangle_deg = {mk.angle_deg}\n')
        for key, layout_arg, lay in (("new TOML", toml, layout), ("han19 (built-in)", "han19", load_layout("han19"))):
            path = os.path.join(tmp, f"{key[:4]}.c3d")
            save_synth(synthesize(lay, frames, seed=77), path)
            cmd = [sys.executable, "-m", "mocap_autolabel", "label", path, "--layout", layout_arg,
                   "-o", os.path.join(tmp, "out.c3d")]
            t = time.perf_counter()
            res = subprocess.run(cmd, capture_output=True, text=True)
            wall = time.perf_counter() - t
            said = res.stdout.split(" frames in ")
            inside = float(said[1].split(" s")[0]) if len(said) > 1 else float("nan")
            out[key] = {"wall_s": wall, "pipeline_s": inside, "fps": frames / inside, "rc": res.returncode,
                        "error": res.stderr.strip().splitlines()[-1] if res.returncode else ""}
    return out


def pct(rows: np.ndarray, hit: int, count: int) -> str:
    if not len(rows) or rows[:, count].sum() == 0:
        return "-"
    share = rows[:, hit].sum() / rows[:, count].sum()
    se = clustered_se(rows[:, hit], rows[:, count])  # percentage points already; NaN for one take
    return f"{100 * share:.2f}" + ("" if np.isnan(se) else f" ± {se:.2f}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limit", type=int, help="sequences per han2018 user (default: all)")
    ap.add_argument("--sets", nargs="*", help="only these sets")
    ap.add_argument("--methods", nargs="*", default=["set", UNCHECKED, "gmm", ROM, "nearest"])
    ap.add_argument("--no-two-hands", action="store_true")
    ap.add_argument("--no-speed", action="store_true")
    args = ap.parse_args()
    if not Path(HAN2018).is_dir():
        print(f"no data at {HAN2018}; nothing to benchmark")
        return 0
    han19, glove13 = load_layout("han19"), load_layout("glove13")
    lines = ["# Any marker set, no training (benchmarks/layouts.py)", "",
             f"{platform.machine()}, {os.cpu_count()} cores; `python benchmarks/layouts.py"
             + (f" --limit {args.limit}" if args.limit else "") + "`.", "",
             "Instances and frames: % right ± standard error over takes. Confident: share of labeled segments "
             f"with confidence >= {CONFIDENT} that are entirely right. A refused take counts as unlabeled.", "",
             "| set | markers | hand markers | method | instances % | frames all right % | confident right % "
             "| refused | frames/s |", "|---|---|---|---|---|---|---|---|---|"]
    sets = [(name, names, desc, "han") for name, (names, desc) in HAN_SETS.items()]
    sets += [(name, names, desc, "glove") for name, (names, desc) in GLOVE_SETS.items()]
    for name, names, _desc, source in sets:
        if args.sets and name not in args.sets:
            continue
        base = han19 if source == "han" else glove13
        layout = subset(base, names, name.split(" ")[0])
        cases = han_cases(han19, names, args.limit) if source == "han" else [glove_subset_case(layout)]
        for method in args.methods:
            r = run(cases, layout, method)
            fps = sum(c.take.n_frames for c in cases) / max(r["seconds"], 1e-9)
            lines.append(f"| {name} | {len(layout)} | {'yes' if has_hand_markers(layout) else 'no'} | {method} | "
                         f"{pct(r['rows'], 1, 0)} | {pct(r['rows'], 3, 2)} | {100 * r['confident_right']:.2f} "
                         f"({r['confident_segments']}) | {len(r['refused'])}/{len(cases)} | {fps:,.0f} |")
            print(lines[-1], flush=True)
            for why in sorted(set(r["refused"]))[:2]:
                lines.append(f"|  | | | | refused: {why} | | | | |")
    if not args.no_two_hands:
        lines += ["", "## Two hands (both files of each sequence, >= 100 frames)", "",
                  "| set | instances % | frames all right % | sides right |", "|---|---|---|---|"]
        for name in ("tips5+back", "tips+pip", "tips5"):
            if args.sets and name not in args.sets:
                continue
            r = run_two_hands(han19, HAN_SETS[name][0], name.split(" ")[0], args.limit and 2 * args.limit)
            lines.append(f"| {name} | {pct(r['rows'], 1, 0)} | {pct(r['rows'], 3, 2)} | "
                         f"{sum(r['sides'])}/{len(r['sides'])} |")
            print(lines[-1], flush=True)
    if not args.no_speed:
        speed = cli_speed(subset(han19, HAN_SETS["tips5+back"][0], "studio"))
        lines += ["", "## `label` CLI, 10,000 synthetic frames", "", "| layout | pipeline s | frames/s | wall s |",
                  "|---|---|---|---|"]
        for key, s in speed.items():
            lines.append(f"| {key} | {s['pipeline_s']:.2f} | {s['fps']:,.0f} | {s['wall_s']:.2f} |"
                         + (f" error: {s['error']}" if s["rc"] else ""))
        print("\n".join(lines[-2:]))
    write_report(str(REPORTS / "layouts.md"), lines)
    return 0


if __name__ == "__main__":
    sys.exit(main())
