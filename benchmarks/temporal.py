"""Temporal labeling: every method x temporal mode on raw takes, plus the pipeline's speed and the
reliability of its confidence.

(a) han2018_dense19 sequences turned into raw takes by ``corrupt_take`` (run-length gaps,
    trajectories broken without gaps, a swap in some takes, flicker and persistent ghosts);
(b) the real qualisys_glove13 recording, labels stripped, every slot cut at its gaps, the
    elbow, shoulder, back and pillow markers kept as distractors.

``gmm`` is fitted per subject on labeled data, as in the paper: (a) the first 10 sequences of
each user (not scored), (b) the first 600 frames (not scored). ``nearest`` starts from the true
labels of the first frame. Writes ``benchmarks/reports/temporal.md`` and ``temporal_reliability.png``.

    python benchmarks/temporal.py [--limit N] [--rows set/vote gmm/viterbi ...]
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
from datasets import HAN2018, glove13_take, han2018_sequences  # noqa: E402
from mocap_autolabel.core.cache import RunCache  # noqa: E402
from mocap_autolabel.core.labelers.gmm import GmmLabeler  # noqa: E402
from mocap_autolabel.core.layout import load_layout  # noqa: E402
from mocap_autolabel.core.metrics import clustered_se, score_labeling, segments_right  # noqa: E402
from mocap_autolabel.core.pipeline import label_take  # noqa: E402
from mocap_autolabel.core.settings import LabelSettings  # noqa: E402
from mocap_autolabel.core.synth.generate import GHOST, _pack, corrupt_take, save_synth, synthesize  # noqa: E402
from mocap_autolabel.core.take import Take  # noqa: E402
from mocap_autolabel.core.tracklets import find_tracklets  # noqa: E402

REPORTS = Path(__file__).parent / "reports"
#: (method, temporal, voting score): the default first; "power" is Ghorbani's vote.
ROWS = [("set", "vote", "likelihood"), ("set", "vote", "power"), ("set", "viterbi", ""), ("set", "none", ""),
        ("perm", "vote", "power"), ("cnn", "vote", "power"), ("gmm", "viterbi", ""), ("gmm", "vote", "likelihood"),
        ("nearest", "none", "")]
COUNTS = ("instances", "correct", "erroneous", "false_marker", "false_occlusion", "frames", "frames_all_correct")


class Case:
    """One raw take with its truth, and what gmm / nearest need."""

    def __init__(self, take: Take, truth: np.ndarray, fit: np.ndarray | None, start: np.ndarray):
        self.take, self.truth, self.fit, self.start = take, truth, fit, start


def han_cases(layout, limit: int | None) -> list[Case]:
    cases = []
    for u, user in enumerate(("User1", "User2")):
        seqs = han2018_sequences(layout, user=user)
        fit = np.concatenate(seqs[:10])
        for i, s in enumerate(seqs[10:][:limit]):
            take, truth, _ = corrupt_take(s, 120.0, seed=1000 * u + i)
            cases.append(Case(take, truth, fit, s[0]))
    return cases


def glove_case(layout, fit_frames: int = 600) -> Case:
    take, slot_label = glove13_take(layout)
    pos = take.positions[fit_frames:].astype(np.float64)
    labels = np.where(slot_label >= 0, slot_label, GHOST)
    positions, truth = _pack(np.random.default_rng(0), pos, labels, [])
    raw = Take(positions=positions, names=[f"*{i}" for i in range(positions.shape[1])], rate=take.rate,
               source=take.source)
    cols = [list(slot_label).index(j) for j in range(len(layout))]
    labeled = take.positions[:, cols].astype(np.float64)
    return Case(raw, truth, labeled[:fit_frames], labeled[fit_frames])


def stats(cases: list[Case], m: int) -> dict:
    present = [np.stack([(c.truth == j).any(axis=1) for j in range(m)], axis=1) for c in cases]
    gaps, gap_len, instances = 0, [], 0
    for p in present:
        instances += p.size
        for j in range(m):
            edges = np.diff(np.concatenate([[1], p[:, j].astype(int), [1]]))
            a, b = np.flatnonzero(edges == -1), np.flatnonzero(edges == 1)
            inner = (a > 0) & (b < len(p))
            gaps += int(inner.sum())
            gap_len += list((b - a)[inner])
    lengths = np.concatenate([find_tracklets(c.take).length for c in cases])
    return {"takes": len(cases), "frames": sum(c.take.n_frames for c in cases), "instances": instances,
            "gaps": gaps, "mean_gap": float(np.mean(gap_len)) if gap_len else 0.0,
            "tracklets": len(lengths), "mean_tracklet": float(lengths.mean())}


def run(cases: list[Case], layout, method: str, temporal: str, score: str) -> tuple[dict, float, list]:
    per_take, seconds, segments = [], 0.0, []
    fitted: dict[int, GmmLabeler] = {}  # one fit per subject, as in the paper
    cache = RunCache()  # one model load for all the takes, as a batch run's worker keeps it
    for c in cases:
        t = time.perf_counter()
        gmm = None
        if method == "gmm":
            gmm = fitted.get(id(c.fit)) or GmmLabeler(layout).fit(c.fit)
            fitted[id(c.fit)] = gmm
        settings = LabelSettings(method=method, temporal=temporal, vote_score=score or "likelihood")
        labeling = label_take(c.take, layout, settings, labeler=gmm, start=c.start if method == "nearest" else None,
                              cache=cache)
        seconds += time.perf_counter() - t
        s = score_labeling(labeling.per_sample(), c.truth, c.take.valid, len(layout)).as_dict()
        per_take.append([s[key] for key in COUNTS])
        # Per segment: its confidence and whether every sample of it is right.
        right = segments_right(labeling, c.truth, c.take.valid)
        segments.append(np.stack([labeling.confidence, right, labeling.length], axis=1))
    per_take = np.array(per_take, dtype=np.int64).reshape(-1, len(COUNTS))
    total = {key: int(n) for key, n in zip(COUNTS, per_take.sum(axis=0))}
    total["per_take"] = per_take  # (takes, COUNTS): for the standard errors over takes
    return total, sum(c.take.n_frames for c in cases) / max(seconds, 1e-9), segments


def cli_speed(layout_name: str = "han19", frames: int = 10_000) -> dict:
    """End-to-end ``label`` CLI on a 10,000-frame synthetic take: read, score, vote, write."""
    layout = load_layout(layout_name)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "take.c3d")
        save_synth(synthesize(layout, frames, seed=77), path)
        cmd = [sys.executable, "-m", "mocap_autolabel", "label", path, "--layout", layout_name,
               "-o", os.path.join(tmp, "out.c3d")]
        subprocess.run(cmd[:3] + ["info", path], check=True, capture_output=True)  # warm the file cache
        t = time.perf_counter()
        out = subprocess.run(cmd, check=True, capture_output=True, text=True)
        wall = time.perf_counter() - t
        t = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import mocap_autolabel.core.pipeline, onnxruntime, scipy.optimize"],
                       check=True)
        startup = time.perf_counter() - t
    inside = float(out.stdout.split(" frames in ")[1].split(" s")[0])
    return {"frames": frames, "wall_s": wall, "startup_s": startup, "pipeline_s": inside,
            "fps_wall": frames / wall, "fps_without_startup": frames / max(wall - startup, 1e-9)}


def reliability_plot(segments: dict[str, np.ndarray], path: Path) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed: no PNG (pip install -e .[bench])")
        return
    fig, ax = plt.subplots(figsize=(5, 5))
    bins = np.linspace(0, 1, 11)
    for name, seg in segments.items():
        conf, ok = seg[:, 0], seg[:, 1]
        which = np.clip(np.digitize(conf, bins) - 1, 0, 9)
        xs, ys = [], []
        for b in range(10):
            sel = which == b
            if sel.sum() >= 5:
                xs.append(conf[sel].mean())
                ys.append(ok[sel].mean())
        ax.plot(xs, ys, "o-", label=name)
    ax.plot([0, 1], [0, 1], "k:", lw=1)
    ax.set_xlabel("confidence of the segment")
    ax.set_ylabel("share of segments entirely right")
    ax.set_title("Reliability of set + vote (segments)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limit", type=int, help="sequences per han2018 user (default: all)")
    ap.add_argument("--rows", nargs="*", help="method/temporal[/score] rows (default: all)")
    args = ap.parse_args()
    if not Path(HAN2018).is_dir():
        print(f"no data at {HAN2018}; nothing to benchmark")
        return 0
    rows = ROWS if not args.rows else [tuple((r.split("/") + [""])[:3]) for r in args.rows]
    han19, glove13 = load_layout("han19"), load_layout("glove13")
    sets = {"(a) han2018, raw takes": (han19, han_cases(han19, args.limit)),
            "(b) glove13 real recording": (glove13, [glove_case(glove13)])}
    results, reliability = {}, {}
    for name, (layout, cases) in sets.items():
        results[name] = {"stats": stats(cases, len(layout)), "rows": {}}
        for method, temporal, score in rows:
            key = f"{method} + {temporal}" + (f" ({score})" if score else "")
            total, fps, segs = run(cases, layout, method, temporal, score)
            results[name]["rows"][key] = (total, fps)
            print(f"{name} {key}: {100 * total['correct'] / total['instances']:.2f} % "
                  f"({100 * total['frames_all_correct'] / total['frames']:.2f} % frames), {fps:,.0f} frames/s",
                  flush=True)
            if (method, temporal, score) == ROWS[0]:
                reliability[name] = np.concatenate(segs)
    speed = cli_speed()
    write_report(results, reliability, speed)
    return 0


def _se(hits: np.ndarray, counts: np.ndarray, digits: int) -> str:
    """' ± SE' of a share over takes, or nothing for a single take."""
    se = clustered_se(hits, counts)
    return "" if np.isnan(se) else f" ± {se:.{digits}f}"


def write_report(results: dict, reliability: dict, speed: dict) -> None:
    REPORTS.mkdir(exist_ok=True)
    lines = ["# Temporal labeling", "",
             f"`python benchmarks/temporal.py` on {platform.machine()}, {platform.python_version()}. Instance metrics "
             "as in METHODS.md; frames = share of frames with every label right. Default pipeline: set + vote "
             "(likelihood). 'power' is Ghorbani's trajectory vote (p = 2, q = -1/2); both votes are exclusive in time. "
             "± is one standard error with the takes as the units (`core.metrics.clustered_se`): errors cluster "
             "within a take, so a bar closer to a figure than that is not settled by this data.",
             ""]
    for name, res in results.items():
        s = res["stats"]
        lines += [f"## {name}", "",
                  f"{s['takes']} takes, {s['frames']:,} frames, {s['instances']:,} instances, {s['gaps']:,} gaps "
                  f"(mean {s['mean_gap']:.1f} frames), {s['tracklets']:,} tracklets (mean {s['mean_tracklet']:.1f} "
                  "frames).", "",
                  "| method + temporal | correct % | frames % | erroneous | false marker | false occlusion "
                  "| frames/s |",
                  "|---|---|---|---|---|---|---|"]
        for key, (t, fps) in res["rows"].items():
            correct, instances, frames_right, frames = (t["per_take"][:, COUNTS.index(count)] for count in (
                "correct", "instances", "frames_all_correct", "frames"))
            lines.append(f"| {key} | {100 * t['correct'] / t['instances']:.3f}{_se(correct, instances, 3)} | "
                         f"{100 * t['frames_all_correct'] / t['frames']:.2f}{_se(frames_right, frames, 2)} | "
                         f"{t['erroneous']:,} | {t['false_marker']:,} | {t['false_occlusion']:,} | {fps:,.0f} |")
        lines.append("")
    lines += ["## Confidence (set + vote), per segment", "",
              "| data | segments | share at >= 0.95 | right at >= 0.95 % | right below 0.95 % |",
              "|---|---|---|---|---|"]
    for name, seg in reliability.items():
        hi = seg[:, 0] >= 0.95
        lines.append(f"| {name} | {len(seg):,} | {100 * hi.mean():.1f} % | "
                     f"{f'{100 * seg[hi, 1].mean():.3f}' if hi.any() else 'none there'} | "
                     f"{f'{100 * seg[~hi, 1].mean():.2f}' if (~hi).any() else 'none there'} |")
    lines += ["", "![reliability](temporal_reliability.png)", "",
              "## Speed of the `label` CLI (han19, 10,000 frames, Blender not involved)", "",
              f"- end to end (process start, read C3D, score, vote, write C3D): {speed['wall_s']:.2f} s, "
              f"{speed['fps_wall']:,.0f} frames/s",
              f"- of which interpreter and imports: {speed['startup_s']:.2f} s; without them "
              f"{speed['fps_without_startup']:,.0f} frames/s; `label_take` alone {speed['pipeline_s']:.2f} s", "",
              "IK validation (`label_take(validate=True)`) on the same data: `benchmarks/validation.py`, "
              "report in validation.md (it calibrates a hand per take, so it runs on every 4th han2018 take).", ""]
    (REPORTS / "temporal.md").write_text("\n".join(lines))
    reliability_plot(reliability, REPORTS / "temporal_reliability.png")
    print(f"wrote {REPORTS / 'temporal.md'}")


if __name__ == "__main__":
    sys.exit(main())
