#!/usr/bin/env python3
"""Per-frame labeling accuracy of every method (set, perm, cnn, gmm, nearest) on four data sets.

    python benchmarks/per_frame.py [--every 2] [--quick] [--set-model cand.onnx --report /tmp/cand]

(a) han2018_dense19 with Han's protocol (drop 0-5 markers, add 0-2 ghosts per frame, seeded);
(b) han2018 by number of occluded markers, no ghosts (Ghorbani's Table 1);
(c) held-out synthetic takes (camera occlusion, ghosts, merges: the full generator);
(d) the real Qualisys glove13 recording, labels stripped, real gaps and distractors.
Writes benchmarks/reports/per_frame.md and per_frame.png. Not a test: figures, not pass/fail.

``gmm`` is fitted per subject on a labeled take, as in the paper: for (a)/(b) on the first 10
sequences of each han2018 user (left out of its own figures), for (c) on the first 600 frames of
each take, for (d) on the first 600 frames of the recording; the other methods are scored on the
same frames. ``nearest`` starts from the true labels of the first scored frame of each sequence.
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
sys.path.insert(0, str(ROOT / "benchmarks"))

from datasets import HAN2018, glove13_take, han2018_sequences  # noqa: E402
from mocap_autolabel.core.labelers import assign, make_labeler, pack_frames  # noqa: E402
from mocap_autolabel.core.labelers.gmm import GmmLabeler  # noqa: E402
from mocap_autolabel.core.labelers.nearest import NearestLabeler  # noqa: E402
from mocap_autolabel.core.layout import load_layout  # noqa: E402
from mocap_autolabel.core.metrics import data_set_stats, per_label, score_labeling  # noqa: E402
from mocap_autolabel.core.synth.frames import FrameConfig, LabeledFrames, corrupt_markers  # noqa: E402
from mocap_autolabel.core.synth.generate import synthesize  # noqa: E402
from mocap_autolabel.core.temporal.murty import nbest_labelings  # noqa: E402

METHODS = ("set", "perm", "cnn", "gmm", "nearest")
HAN = FrameConfig(drop=(0, 5), ghosts=(0, 2), distractor_share=0.0)
#: Candidate ONNX models by (method, layout name), from ``--set-model``: scored instead of the shipped ones.
CANDIDATES: dict[tuple[str, str], str] = {}


class Case:
    """One evaluation unit: sequences of labeled frames, plus what gmm and nearest need."""

    def __init__(self, frames: list[LabeledFrames], fit: list[np.ndarray] | None):
        self.frames = frames  # per sequence, in time order
        self.fit = fit  # labeled positions (F, M, 3) for gmm, per group


def run_method(method: str, layout, seqs: list[LabeledFrames], fit: np.ndarray | None) -> tuple[np.ndarray, float]:
    """Labels (concatenated over sequences) and frames per second."""
    labels, seconds, frames = [], 0.0, 0
    if method in ("set", "perm", "cnn"):
        labeler = make_labeler(method, layout, model=CANDIDATES.get((method, layout.name)))
    elif method == "gmm":
        labeler = GmmLabeler(layout).fit(fit)
    for fr in seqs:
        start = time.perf_counter()
        if method == "nearest":
            first = np.full((len(layout), 3), np.nan)
            ok = fr.mask[0] & (fr.labels[0] >= 0)
            first[fr.labels[0][ok]] = fr.points[0][ok]
            labeler = NearestLabeler(layout, start=first)
        scores = labeler.scores(fr.points, fr.mask)
        lab, _ = assign(scores, fr.mask)
        seconds += time.perf_counter() - start
        frames += len(fr.points)
        labels.append(lab)
    return labels, frames / max(seconds, 1e-9)


def evaluate(layout, groups: list[Case], methods) -> dict:
    """Score every method over all groups (a group = sequences sharing one gmm fit)."""
    out = {}
    all_frames = [fr for g in groups for fr in g.frames]
    k = max(fr.points.shape[1] for fr in all_frames)
    for method in methods:
        preds, rates = [], []
        for g in groups:
            fit = None if g.fit is None else np.concatenate(g.fit)
            lab, rate = run_method(method, layout, g.frames, fit)
            preds += lab
            rates.append(rate)
        pred = np.concatenate([_pad(p, k, -1) for p in preds])
        truth = np.concatenate([_pad(fr.labels, k, -2) for fr in all_frames])
        mask = np.concatenate([_pad(fr.mask, k, False) for fr in all_frames])
        out[method] = (score_labeling(pred, truth, mask, len(layout)), float(np.median(rates)))
    present = np.concatenate([per_label(fr.labels, fr.mask, len(layout)) >= 0 for fr in all_frames])
    return {"scores": out, "stats": data_set_stats(present)}


def _pad(a: np.ndarray, k: int, value) -> np.ndarray:
    if a.shape[1] == k:
        return a
    pad = np.full((a.shape[0], k - a.shape[1]) + a.shape[2:], value, dtype=a.dtype)
    return np.concatenate([a, pad], axis=1)


def han_groups(layout, every: int, cfg: FrameConfig, seed: int, fit_sequences: int = 10) -> list[Case]:
    groups = []
    for user in ("User1", "User2"):
        seqs = han2018_sequences(layout, every=every, user=user)
        rng = np.random.default_rng(seed)
        frames = [corrupt_markers(s, rng, cfg) for s in seqs[fit_sequences:]]
        groups.append(Case(frames, seqs[:fit_sequences]))
    return groups


def synth_groups(layout, takes: int, frames: int, fit_frames: int = 600) -> list[Case]:
    groups = []
    for seed in range(takes):
        s = synthesize(layout, frames, seed=90_000 + seed)
        batch = pack_frames(s.take.positions)
        truth = np.where(batch.slots >= 0, s.labels[np.arange(frames)[:, None], np.maximum(batch.slots, 0)], -2)
        truth = np.where(truth == -2, -1, truth).astype(np.int16)  # a sample of no marker is a ghost
        truth[~batch.mask] = -2
        sl = slice(fit_frames, None)
        fr = LabeledFrames(batch.points[sl], truth[sl], batch.mask[sl], s.markers[sl].astype(np.float32))
        groups.append(Case([fr], [s.markers[:fit_frames]]))
    return groups


def glove_groups(layout, fit_frames: int = 600) -> list[Case]:
    take, slot_label = glove13_take(layout)
    batch = pack_frames(take.positions)
    truth = np.where(batch.slots >= 0, slot_label[np.maximum(batch.slots, 0)], -2).astype(np.int16)
    cols = [list(slot_label).index(j) for j in range(len(layout))]
    labeled = take.positions[:, cols].astype(np.float64)
    sl = slice(fit_frames, None)
    fr = LabeledFrames(batch.points[sl], truth[sl], batch.mask[sl], labeled[sl].astype(np.float32))
    return [Case([fr], [labeled[:fit_frames]])]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--every", type=int, default=8, help="use every n-th han2018 frame")
    ap.add_argument("--quick", action="store_true", help="fewer frames, for a smoke run")
    ap.add_argument("--methods", nargs="*", default=list(METHODS))
    ap.add_argument("--set-model", help="a candidate han19 'set' model (.onnx with its card) to score "
                                        "instead of the shipped one")
    ap.add_argument("--report", type=Path, default=ROOT / "benchmarks" / "reports",
                    help="folder for per_frame.md and .png (give another with --set-model)")
    args = ap.parse_args()
    if args.set_model:
        CANDIDATES[("set", "han19")] = args.set_model
    if not Path(HAN2018).is_dir():
        print(f"no data at {HAN2018}; nothing to benchmark")
        return 0
    every = args.every = 32 if args.quick else args.every
    han19, glove13 = load_layout("han19"), load_layout("glove13")
    results = {}
    han = han_groups(han19, every, HAN, 1)
    results["(a) han2018, Han protocol"] = evaluate(han19, han, args.methods)
    anatomy = error_anatomy(han19, han) if "set" in args.methods else None
    results["(a) han2018, clean"] = evaluate(
        han19, han_groups(han19, every, FrameConfig(drop=(0, 0), ghosts=(0, 0), distractor_share=0.0), 1), args.methods)
    by_occ = {}
    for c in range(6):
        cfg = FrameConfig(drop=(c, c), ghosts=(0, 0), distractor_share=0.0)
        by_occ[c] = evaluate(han19, han_groups(han19, every * 2, cfg, 2 + c), args.methods)
    takes, frames = (1, 1500) if args.quick else (2, 2500)
    results["(c) synthetic han19, held out"] = evaluate(han19, synth_groups(han19, takes, frames), args.methods)
    results["(c) synthetic glove13, held out"] = evaluate(glove13, synth_groups(glove13, takes, frames), args.methods)
    results["(d) glove13 real recording"] = evaluate(glove13, glove_groups(glove13), args.methods)
    speed = set_speed(han19)
    write_report(results, by_occ, speed, anatomy, args)
    return 0


def set_speed(layout, frames: int = 20000) -> dict:
    """Frames per second of batched ONNX inference of ``set`` (scores only, and with assignment);
    batches run on one thread each, as many side by side as there are cores."""
    seqs = han2018_sequences(layout, every=1, user="User1")
    markers = np.concatenate(seqs)[:frames]
    fr = corrupt_markers(markers, np.random.default_rng(0), HAN)
    labeler = make_labeler("set", layout, model=CANDIDATES.get(("set", layout.name)))
    labeler.scores(fr.points[:512], fr.mask[:512])
    out = {}
    for batch in (128, 1024):
        labeler.batch = batch
        best = 0.0
        for _ in range(3):
            t = time.perf_counter()
            s = labeler.scores(fr.points, fr.mask)
            best = max(best, len(markers) / (time.perf_counter() - t))
        out[f"scores, batch {batch}"] = best
    t = time.perf_counter()
    assign(s, fr.mask)
    out["assignment only"] = len(markers) / (time.perf_counter() - t)
    out["frames"] = len(markers)
    out["K"] = fr.points.shape[1]
    return out


#: A ghost within this distance of a marker's true position counts as that marker's reflection
#: (Han's protocol puts half of its ghosts 5-25 mm from a marker, the rest anywhere in the hand's box).
NEAR_GHOST = 0.025
#: How many of set's best labelings per frame the reranking ceiling looks at.
NBEST = (1, 3, 10)


def error_anatomy(layout, groups: list[Case]) -> dict:
    """Where ``set`` goes wrong on Han-protocol frames: accuracy by ghosts x occluded markers, what
    becomes of each kind of ghost, the commonest confusions (true label -> given label), and the
    best of its N best labelings per frame (the ceiling of any reranker of them)."""
    m = len(layout)
    names = layout.names + ["empty"]
    labeler = make_labeler("set", layout, model=CANDIDATES.get(("set", layout.name)))
    right, ghosts, drops, fates, confusions = [], [], [], {}, {}
    best_of = dict.fromkeys(NBEST, 0)
    for fr in (fr for g in groups for fr in g.frames):
        scores = labeler.scores(fr.points, fr.mask)
        pred = np.where(fr.mask, assign(scores, fr.mask)[0], -1)
        given, true = per_label(pred, fr.mask, m), per_label(fr.labels, fr.mask, m)
        ok = given == true
        right.append(ok)
        ghosts.append((fr.labels == -1).sum(axis=1))
        drops.append((true < 0).sum(axis=1))
        # Each ghost: its nearest marker (true position, dropped or not), and whether it got a label.
        f, k = np.nonzero(fr.labels == -1)
        d = np.linalg.norm(fr.markers[f] - fr.points[f, k][:, None], axis=2)
        near = d.argmin(axis=1)
        within = f"within {NEAR_GHOST * 1000:.0f} mm of an"
        kind = np.where(d.min(axis=1) > NEAR_GHOST, "farther from every marker",
                        np.where(true[f, near] >= 0, f"{within} observed marker", f"{within} occluded marker"))
        for name in np.unique(kind):
            sel = kind == name
            n, labeled, own = fates.get(name, (0, 0, 0))
            fates[name] = (n + int(sel.sum()), labeled + int((pred[f, k][sel] >= 0).sum()),
                           own + int((pred[f, k][sel] == near[sel]).sum()))
        for r, j in zip(*np.nonzero(~ok & (true >= 0))):
            got = pred[r, true[r, j]]
            key = (names[j], names[got])  # names[-1]: left empty
            confusions[key] = confusions.get(key, 0) + 1
        for i in range(len(fr.points)):
            hypothesis, hits = np.full(fr.mask.shape[1], -1), []
            for _, h in nbest_labelings(scores[i][fr.mask[i]], max(NBEST)):
                hypothesis[fr.mask[i]] = h
                hits.append(int((per_label(hypothesis[None], fr.mask[i:i + 1], m)[0] == true[i]).sum()))
            for n in NBEST:
                best_of[n] += max(hits[:n])
    right, ghosts, drops = np.concatenate(right), np.concatenate(ghosts), np.concatenate(drops)
    grid = {(g, c): 100 * right[(ghosts == g) & (drops == c)].mean() for g in range(3) for c in range(6)
            if ((ghosts == g) & (drops == c)).any()}
    rows = {g: 100 * right[ghosts == g].mean() for g in range(3) if (ghosts == g).any()}
    top = sorted(confusions.items(), key=lambda kv: -kv[1])[:10]
    return {"grid": grid, "rows": rows, "fates": fates, "confusions": top,
            "best_of": {n: 100 * hit / right.size for n, hit in best_of.items()},
            "errors": int((~right).sum()), "instances": int(right.size)}


def _anatomy_lines(a: dict) -> list[str]:
    lines = ["## Where `set` goes wrong under Han's protocol", "",
             "The frames of (a), accuracy % by ghosts and occluded markers per frame:", "",
             "| ghosts | all | " + " | ".join(f"{c} occluded" for c in range(6)) + " |", "|---" * 8 + "|"]
    for g, acc in a["rows"].items():
        lines.append(f"| {g} | {acc:.2f} | " + " | ".join(
            f"{a['grid'][(g, c)]:.2f}" if (g, c) in a["grid"] else "" for c in range(6)) + " |")
    lines += ["", "What becomes of the ghosts (own label: the ghost took the label of the marker nearest to it):",
              "", "| ghost | ghosts | given a label % | given the nearest marker's own label % |", "|---|---|---|---|"]
    for name, (n, labeled, own) in sorted(a["fates"].items()):
        lines.append(f"| {name} | {n:,} | {100 * labeled / n:.1f} | {100 * own / n:.1f} |")
    lines += ["", f"Commonest confusions of an observed marker ({a['errors']:,} wrong instances of "
              f"{a['instances']:,}; 'empty': left unlabeled):", "", "| marker | given | instances |", "|---|---|---|"]
    lines += [f"| {t} | {g} | {n:,} |" for (t, g), n in a["confusions"]]
    lines += ["", "Best of `set`'s N best labelings per frame (Murty on its scores), picked with the truth: the "
              "most a reranker of them (an IK check, a second network) could reach, accuracy %:", "",
              "| N | " + " | ".join(str(n) for n in a["best_of"]) + " |", "|---" * (len(a["best_of"]) + 1) + "|",
              "| accuracy | " + " | ".join(f"{v:.2f}" for v in a["best_of"].values()) + " |"]
    return lines + [""]


def _pct(x: float) -> str:
    return "n/a" if x != x else f"{100 * x:.2f}"


def write_report(results: dict, by_occ: dict, speed: dict, anatomy: dict | None, args) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    model = f" --set-model {args.set_model}" if args.set_model else ""
    lines = ["# Per-frame labeling accuracy", "",
             f"`python benchmarks/per_frame.py --every {args.every}{' --quick' if args.quick else ''}{model}` on "
             f"{platform.machine()}, {platform.python_version()}. Metrics as defined in METHODS.md: accuracy = "
             "correct instances (frame x label) / instances; frames = share of frames with every label correct; "
             "ghost P/R = precision/recall of the null decision per observation; occl. P/R = precision/recall "
             "of 'label left empty'.", ""]
    for name, res in results.items():
        st = res["stats"]
        lines += [f"## {name}", "",
                  f"{st['frames']:,} frames, {st['instances']:,} instances, {st['gaps']:,} gaps "
                  f"(mean {st['mean_gap_frames']:.1f} frames), {st['tracklets']:,} tracklets "
                  f"(mean {st['mean_tracklet_frames']:.1f} frames).", "",
                  "| method | accuracy % | frames % | erroneous | false marker | false occlusion | ghost P | ghost R "
                  "| occl. P | occl. R | frames/s |", "|---|---|---|---|---|---|---|---|---|---|---|"]
        for method, (s, rate) in res["scores"].items():
            lines.append(f"| {method} | {_pct(s.accuracy)} | {_pct(s.frame_accuracy)} | {s.erroneous:,} | "
                         f"{s.false_marker:,} | {s.false_occlusion:,} | {_pct(s.ghost_precision)} | "
                         f"{_pct(s.ghost_recall)} | {_pct(s.occlusion_precision)} | {_pct(s.occlusion_recall)} | "
                         f"{rate:,.0f} |")
        lines.append("")
    methods = list(next(iter(by_occ.values()))["scores"])
    lines += ["## (b) han2018 by number of occluded markers (no ghosts), accuracy %", "",
              "| occluded | " + " | ".join(methods) + " |", "|---" * (len(methods) + 1) + "|"]
    for c, res in by_occ.items():
        lines.append(f"| {c} | " + " | ".join(_pct(res["scores"][m][0].accuracy) for m in methods) + " |")
    lines += [""] + (_anatomy_lines(anatomy) if anatomy else [])
    lines += ["## Speed of `set` (han19, batched ONNX inference, 2 cores)", "",
              f"{speed['frames']:,} han2018 frames with Han's corruption, K = {speed['K']}.", "",
              "| stage | frames/s |", "|---|---|"]
    lines += [f"| {k} | {v:,.0f} |" for k, v in speed.items() if k not in ("frames", "K")]
    args.report.mkdir(parents=True, exist_ok=True)
    out = args.report / "per_frame.md"
    out.write_text("\n".join(lines) + "\n")

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(13, 4.5))
    names = list(results)
    width = 0.8 / len(methods)
    for i, m in enumerate(methods):
        ax1.bar(np.arange(len(names)) + i * width, [100 * results[n]["scores"][m][0].accuracy for n in names],
                width, label=m)
    ax1.set_xticks(np.arange(len(names)) + 0.4 - width / 2)
    ax1.set_xticklabels([n.split(",")[0] + "\n" + ",".join(n.split(",")[1:]) for n in names], fontsize=7)
    ax1.set_ylabel("accuracy %")
    ax1.set_ylim(0, 100)
    ax1.legend(fontsize=8)
    for m in methods:
        ax2.plot(list(by_occ), [100 * by_occ[c]["scores"][m][0].accuracy for c in by_occ], marker="o", label=m)
    ax2.set_xlabel("occluded markers per frame")
    ax2.set_ylabel("accuracy %")
    ax2.set_title("(b) han2018 by occlusions")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.report / "per_frame.png", dpi=110)
    print(out.read_text())


if __name__ == "__main__":
    sys.exit(main())
