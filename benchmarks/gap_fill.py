"""Gap filling: hide real samples of labeled markers and compare each method's fill with them.

(a) The real Qualisys glove recording (glove13, 100 Hz, 3,000 frames, real occlusions besides).
(b) han2018_dense19 sequences (han19, 120 Hz) of at least 480 frames (4 s; Users 1-2, both hands).

Per take the hand is calibrated once on the take's own labels (:func:`core.hand.calibrate`, the
whole take as labeled); then in each round one gap per marker is hidden, of a length drawn
log-uniformly from 0.05 to 2 s at a random place where the marker is seen for the gap and
:data:`MARGIN` frames each side, and the take with those gaps is solved again with that
calibration (so the solve never sees a hidden sample) and filled by every method (``max_gap``
2 s). Errors are the distances from the fill to the hidden samples, pooled per gap-length band;
the jump at a gap's end is how much the step from the last sample before it to the fill (and from
the fill to the first sample after it) exceeds the marker's own frame-to-frame motion there: the
largest of its true steps over the three frame pairs centred on that step (a real marker that stops
or starts within a frame of the gap's end moves by that much itself; the excess over the one true
step of that frame pair alone is reported beside it).

(c) Speed: ``fill_gaps`` with ``auto`` on two 10,000-frame labeled han19 takes, given their hand
solve: a synthetic raw take labeled by its truth (its own occlusions), and a stress take (the
average hand's motion, 0.5 mm noise, one 0.05-2 s gap per marker every 500 frames).

Writes ``benchmarks/reports/gap_fill.md`` and ``gap_fill.png``.

    python benchmarks/gap_fill.py [--rounds N] [--han-rounds N] [--han-limit N]
"""

from __future__ import annotations

import argparse
import glob
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from datasets import GLOVE13, HAN2018, layout_columns, write_report  # noqa: E402
from mocap_autolabel.core.fill import METHODS, fill_gaps, fill_markers, find_gaps, layout_partners  # noqa: E402
from mocap_autolabel.core.hand import HandModel  # noqa: E402
from mocap_autolabel.core.hand.calibrate import calibrate  # noqa: E402
from mocap_autolabel.core.hand.ik import HandSolver  # noqa: E402
from mocap_autolabel.core.labeling import layout_markers  # noqa: E402
from mocap_autolabel.core.layout import load_layout  # noqa: E402
from mocap_autolabel.core.solve import HandSolve  # noqa: E402
from mocap_autolabel.core.synth.generate import marker_motion, synthesize  # noqa: E402
from mocap_autolabel.core.take import Take, read_take  # noqa: E402

REPORTS = Path(__file__).parent / "reports"
#: Gap-length bands, seconds.
BANDS = ((0.05, 0.1), (0.1, 0.25), (0.25, 0.5), (0.5, 1.0), (1.0, 2.0))
SHORTEST, LONGEST = 0.05, 2.0
#: Frames seen each side of a hidden gap (the spline's support and one more).
MARGIN = 5
ORDER = ("spline", "rigid", "pca", "pose", "hand", "auto")


def hide_gaps(valid: np.ndarray, rate: float, rng: np.random.Generator) -> list[tuple[int, int, int]]:
    """One gap ``(marker, start, stop)`` per marker where it is seen for the gap and MARGIN frames each side."""
    n_f, n_m = valid.shape
    cs = np.concatenate([np.zeros((1, n_m), dtype=np.int64), np.cumsum(valid, axis=0)])
    out = []
    for m in range(n_m):
        for _ in range(100):
            n = max(1, int(round(np.exp(rng.uniform(np.log(SHORTEST), np.log(LONGEST))) * rate)))
            if n + 2 * MARGIN >= n_f:
                continue
            start = int(rng.integers(MARGIN, n_f - n - MARGIN))
            if cs[start + n + MARGIN, m] - cs[start - MARGIN, m] == n + 2 * MARGIN:
                out.append((m, start, start + n))
                break
    return out


def evaluate(name: str, observed: np.ndarray, rate: float, layout, rounds: int, seed: int, rows: list) -> None:
    """Calibrate on ``observed (F, M, 3)``, then ``rounds`` rounds of hidden gaps, every method."""
    t = time.perf_counter()
    cal = calibrate(observed, layout)
    print(f"{name}: calibrated in {time.perf_counter() - t:.1f} s", flush=True)
    solver = cal.solver(layout)
    partners = layout_partners(layout)
    rng = np.random.default_rng(seed)
    valid = np.isfinite(observed[..., 0])
    for r in range(rounds):
        gaps = hide_gaps(valid, rate, rng)
        hidden = observed.copy()
        for m, a, b in gaps:
            hidden[a:b, m] = np.nan
        poses = solver.solve(hidden, rate=rate).poses
        for method in ORDER:
            t = time.perf_counter()
            out = fill_markers(hidden, rate, method, LONGEST, solver=solver, poses=poses, partners=partners)
            seconds = time.perf_counter() - t
            used = {(g.marker, g.start): g.method for g in out.gaps}
            for m, a, b in gaps:
                x, truth = out.positions[:, m], observed[:, m]
                if not np.isfinite(x[a:b, 0]).all():
                    rows.append(dict(take=name, method=method, seconds=(b - a) / rate, used=None, err=None,
                                     jump=None, est=None))
                    continue
                err = np.linalg.norm(x[a:b] - truth[a:b], axis=1)
                true_steps = np.linalg.norm(np.diff(truth, axis=0), axis=1)  # [i]: frame i to i + 1
                jump = strict = -np.inf
                for end in (a, b):  # the step from end - 1 to end crosses the fill's boundary
                    step = np.linalg.norm(x[end] - x[end - 1])
                    strict = max(strict, step - true_steps[end - 1])
                    jump = max(jump, step - np.nanmax(true_steps[max(0, end - 2):end + 1]))
                rows.append(dict(take=name, method=method, seconds=(b - a) / rate, used=used.get((m, a)), err=err,
                                 jump=jump, strict=strict, est=out.error[a:b, m], fill_s=seconds))
        print(f"  round {r + 1}/{rounds}: {len(gaps)} gaps", flush=True)


def han_sequences(layout, min_frames: int = 480) -> list[tuple[str, np.ndarray]]:
    out = []
    for path in sorted(glob.glob(os.path.join(HAN2018, "User*", "capture*", "*.trc"))):
        take = read_take(path)
        if take.n_frames >= min_frames:
            cols = layout_columns(take.names, layout)
            name = f"{path.split(os.sep)[-3]}/{os.path.basename(path).replace('_training_dense', '')[:-4]}"
            out.append((name, take.positions[:, cols].astype(np.float64)))
    return out


def band_table(rows: list, title: str) -> tuple[list[str], dict]:
    """Median / p95 error (mm) per method and band; also the pooled figures the bars use."""
    lines = [f"### {title}", "", "Median / 95th percentile error (mm) of the filled samples; `n` = gaps (of which "
             "filled by that method: a gap a method cannot fill counts as unfilled, not as an error).", "",
             "| method | " + " | ".join(f"{a:g}-{b:g} s" for a, b in BANDS) + " | jump mm: median / p95 / largest |",
             "|---|" + "---|" * (len(BANDS) + 1)]
    stats: dict = {}
    for method in ORDER:
        cells = []
        mine = [r for r in rows if r["method"] == method]
        for a, b in BANDS:
            band = [r for r in mine if a <= r["seconds"] < b or (b == LONGEST and r["seconds"] == b)]
            done = [r for r in band if r["err"] is not None]
            if done:
                e = np.concatenate([r["err"] for r in done]) * 1000
                stats[method, a] = (float(np.median(e)), float(np.percentile(e, 95)))
                cells.append(f"{np.median(e):.2f} / {np.percentile(e, 95):.1f} (n {len(band)}, {len(done)} filled)")
            else:
                cells.append(f"- (n {len(band)}, 0 filled)")
        jumps = np.array([r["jump"] for r in mine if r["jump"] is not None]) * 1000
        strict = np.array([r["strict"] for r in mine if r["jump"] is not None]) * 1000
        stats[method, "jump"] = float(jumps.max()) if len(jumps) else float("nan")
        stats[method, "jumps"] = (f"{np.median(jumps):.2f} / {np.percentile(jumps, 95):.2f} / {jumps.max():.2f}"
                                  if len(jumps) else "-")
        stats[method, "over"] = (int((jumps >= 0.5).sum()), len(jumps))
        stats[method, "strict"] = (int((strict >= 0.5).sum()), float(strict.max()) if len(strict) else float("nan"))
        for key, lo, hi in (("upto0.5", 0, 0.5), ("upto2", 0, 2.0001), ("from0.25", 0.25, 2.0001)):
            done = [r for r in mine if r["err"] is not None and lo <= r["seconds"] < hi]
            stats[method, key] = float(np.median(np.concatenate([r["err"] for r in done]) * 1000)) if done else np.nan
        lines.append(f"| {method} | " + " | ".join(cells) + f" | {stats[method, 'jumps']} |")
    picks = {}
    for r in rows:
        if r["method"] == "auto" and r["used"]:
            picks[r["used"]] = picks.get(r["used"], 0) + 1
    lines += ["", "auto chose: " + ", ".join(f"{k} {v}" for k, v in sorted(picks.items())), ""]
    est = [(np.mean(r["est"]), np.mean(r["err"])) for r in rows if r["method"] == "auto" and r["err"] is not None]
    if est:
        e = np.array(est)
        ratio = e[:, 1] / e[:, 0]
        lines += [f"Expected error of auto's fills against the error measured, per gap: median ratio measured / "
                  f"expected {np.median(ratio):.2f} (10th-90th percentile {np.percentile(ratio, 10):.2f}-"
                  f"{np.percentile(ratio, 90):.2f}); rank correlation {_spearman(e[:, 0], e[:, 1]):.2f}.", ""]
    return lines, stats


def _spearman(a: np.ndarray, b: np.ndarray) -> float:
    ra, rb = np.argsort(np.argsort(a)), np.argsort(np.argsort(b))
    return float(np.corrcoef(ra, rb)[0, 1])


def bars(stats: dict) -> list[str]:
    lines = ["Bars (real glove recording):", ""]
    for method in ("hand", "auto"):
        a, b = stats[method, "upto0.5"], stats[method, "upto2"]
        lines.append(f"- {method}: median {a:.2f} mm for gaps up to 0.5 s (bar <= 3: "
                     f"{'met' if a <= 3 else 'NOT met'}), {b:.2f} mm up to 2 s (bar <= 8: "
                     f"{'met' if b <= 8 else 'NOT met'})")
        for other in ("spline", "pca"):
            ratio = stats[other, "from0.25"] / stats[method, "from0.25"]
            lines.append(f"  - gaps >= 0.25 s: {stats[method, 'from0.25']:.2f} mm against {other} "
                         f"{stats[other, 'from0.25']:.2f} mm: {ratio:.1f}x lower (bar >= 2x: "
                         f"{'met' if ratio >= 2 else 'NOT met'})")
    for method in ("hand", "pose", "auto", "spline"):
        over, count = stats[method, "over"]
        strict, largest = stats[method, "strict"]
        lines.append(f"- {method}: largest step at a gap's end beyond the marker's own steps there "
                     f"{stats[method, 'jump']:.3f} mm; {over} of {count} gaps at 0.5 mm or more "
                     f"(bar < 0.5 for every fill: {'met' if over == 0 else 'NOT met'}); against its one true "
                     f"step at that frame alone: {strict} of {count} at 0.5 mm or more, largest {largest:.2f} mm")
    lines.append("")
    return lines


def _speed_take(layout, stress: bool) -> tuple[Take, HandSolve, int]:
    """A 10,000-frame labeled han19 take and its solve (the true hand), and its gaps inside the take.

    Realistic: a synthetic raw take (camera occlusion, random gaps) labeled by its truth.
    Stress: the average hand's synthetic motion with one gap of 0.05-2 s per marker every 500 frames.
    """
    if stress:
        hand = HandModel(side="right")
        _, x = marker_motion(layout, hand, 10_000, seed=7, noise=0.0005)
        rng = np.random.default_rng(7)
        valid = np.ones(x.shape[:2], dtype=bool)
        for chunk in range(0, 10_000, 500):
            for m, a, b in hide_gaps(valid[chunk:chunk + 500], 120.0, rng):
                x[chunk + a:chunk + b, m] = np.nan
    else:
        synth = synthesize(layout, 10_000, seed=3)
        hand, lab = synth.hand, synth.labels
        x = np.full((lab.shape[0], len(layout), 3), np.nan)
        f, p = np.nonzero(lab >= 0)
        x[f, lab[f, p]] = synth.take.positions[f, p]
    t = time.perf_counter()
    solver = HandSolver(hand, layout.place(hand)[0])
    fit = solver.solve(x, rate=120.0)
    seconds = {"solve": time.perf_counter() - t}
    gaps = sum(1 for _, a, b in find_gaps(np.isfinite(x[..., 0])) if a > 0 and b < len(x))
    solve = HandSolve(None, fit, layout, 120.0, 1, seconds, solver)
    return Take(x.astype(np.float32), list(layout.names), 120.0), solve, gaps


HARSHER = "beyond the bar: its take holds 3x the gaps of a realistic one"


def speed(lines: list[str]) -> None:
    layout = load_layout("han19")
    lines += ["## Speed", "", "`fill_gaps(take, layout, 'auto', solves=...)` on 10,000-frame labeled han19 takes "
              "(120 Hz), given the hand solve (the solve's own time beside it); best of 3.", "",
              "| take | gaps inside the take | filled | missing samples | solve s | fill s | bar < 1 s |",
              "|---|---|---|---|---|---|---|"]
    for stress, label in ((False, "synthetic raw take (occlusion, random gaps) labeled by its truth"),
                          (True, "stress: one 0.05-2 s gap per marker every 500 frames")):
        take, solve, count = _speed_take(layout, stress)
        times = []
        for _ in range(3):
            t = time.perf_counter()
            result = fill_gaps(take, layout, "auto", 2.0, solves=[("", solve)])
            times.append(time.perf_counter() - t)
        rep = result.report()
        lines.append(f"| {label} | {count} | {rep['filled']} | {100 * (1 - take.valid.mean()):.1f} % | "
                     f"{solve.seconds.get('solve', float('nan')):.1f} | {min(times):.2f} | "
                     f"{('met' if min(times) < 1 else 'NOT met') if not stress else HARSHER} |")
    lines.append("")
    print(*lines[-5:], sep="\n", flush=True)


def plot(all_stats: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(all_stats), figsize=(6 * len(all_stats), 4.2), sharey=True)
    mids = [np.sqrt(a * b) for a, b in BANDS]
    for ax, (title, stats) in zip(np.atleast_1d(axes), all_stats.items()):
        for method in ORDER:
            med = [stats.get((method, a), (np.nan, np.nan))[0] for a, _ in BANDS]
            p95 = [stats.get((method, a), (np.nan, np.nan))[1] for a, _ in BANDS]
            line, = ax.plot(mids, med, "o-", label=f"{method} median")
            ax.plot(mids, p95, ":", color=line.get_color(), alpha=0.7)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("gap length, s (band centre)")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("error, mm (solid: median, dotted: 95th percentile)")
    np.atleast_1d(axes)[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=12, help="rounds of hidden gaps on the glove take")
    parser.add_argument("--han-rounds", type=int, default=3, help="rounds per han2018 sequence")
    parser.add_argument("--han-limit", type=int, default=12, help="han2018 sequences used (of those >= 480 frames)")
    args = parser.parse_args()
    lines = ["# Gap filling benchmark", "",
             f"`python benchmarks/gap_fill.py --rounds {args.rounds} --han-rounds {args.han_rounds} --han-limit "
             f"{args.han_limit}` with OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}, "
             f"on a shared, loaded 2-core machine ({platform.machine()}). Methods: "
             f"{', '.join(METHODS)} (see `core/fill.py`).", "",
             __doc__.split("\n\n", 1)[1].split("Writes")[0].strip(), ""]
    all_stats = {}
    if os.path.isfile(GLOVE13):
        layout = load_layout("glove13")
        observed = layout_markers(read_take(GLOVE13), layout)
        rows: list = []
        evaluate("glove13", observed, 100.0, layout, args.rounds, 1, rows)
        table, stats = band_table(rows, f"Real glove recording (glove13, 100 Hz, {len(observed)} frames, "
                                        f"{args.rounds} rounds)")
        lines += ["## Real glove recording", ""] + table + bars(stats)
        all_stats["real glove (glove13, 100 Hz)"] = stats
    else:
        lines += ["## Real glove recording", "", f"skipped: {GLOVE13} not available", ""]
    if os.path.isdir(HAN2018):
        layout = load_layout("han19")
        seqs = han_sequences(layout)[:args.han_limit]
        rows = []
        for i, (name, observed) in enumerate(seqs):
            evaluate(name, observed, 120.0, layout, args.han_rounds, 100 + i, rows)
        table, stats = band_table(rows, f"han2018 (han19, 120 Hz): {len(seqs)} sequences of 480-500 frames, "
                                        f"{args.han_rounds} rounds each")
        lines += ["## han2018 sequences", ""] + table
        all_stats["han2018 (han19, 120 Hz)"] = stats
    else:
        lines += ["## han2018 sequences", "", f"skipped: {HAN2018} not available", ""]
    speed(lines)
    if all_stats:
        plot(all_stats, REPORTS / "gap_fill.png")
        lines += ["![error against gap length](gap_fill.png)", ""]
    write_report(str(REPORTS / "gap_fill.md"), lines)


if __name__ == "__main__":
    main()
