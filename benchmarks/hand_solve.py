"""Hand solve benchmark: IK speed, joint-angle error on synthetic takes, calibration recovery, real glove RMS,
and the `solve` command end to end on the real glove recording.

    python benchmarks/hand_solve.py [--quick] [--baseline OLD/addon]
    python benchmarks/hand_solve.py --solve-only [--baseline OLD/addon]   # just the end-to-end section

``--baseline`` names another checkout's ``addon`` folder (e.g. ``git worktree add /tmp/base <commit>``):
the end-to-end runs alternate between it and this one, for before/after figures measured alike.
Writes benchmarks/reports/hand_solve.md (``--solve-only`` replaces just its section there).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "addon"))
sys.path.insert(0, os.path.dirname(__file__))

from datasets import write_report  # noqa: E402
from mocap_autolabel.core.hand import HandModel  # noqa: E402
from mocap_autolabel.core.hand.calibrate import calibrate  # noqa: E402
from mocap_autolabel.core.hand.ik import HandSolver  # noqa: E402
from mocap_autolabel.core.layout import load_layout  # noqa: E402
from mocap_autolabel.core.synth.generate import marker_motion  # noqa: E402

REPORT = os.path.join(os.path.dirname(__file__), "reports", "hand_solve.md")
ADDON = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "addon")
END_TO_END = "## `solve` end to end on the real glove13 recording"


def joint_errors(args, lines):
    lines += ["## Joint angles on synthetic takes (1 mm noise per axis, known hand)", "",
              "Error of the 20 joint angles against the truth, every frame; `raw` is each frame's own fit, "
              "`smoothed` the default (10 Hz zero-phase low-pass of the pose track).", "",
              "| layout | frames | raw median | raw p95 | smoothed median | smoothed p95 | marker RMS mm | frames/s |",
              "|---|---|---|---|---|---|---|---|"]
    for name in ("han19", "glove13"):
        layout = load_layout(name)
        raw_err, smooth_err, rms, fps = [], [], [], []
        for seed in range(2 if args.quick else 4):
            hand = HandModel(side="left" if seed % 2 else "right")
            poses, observed = marker_motion(layout, hand, 3000, seed, 0.001)
            solver = HandSolver(hand, layout.place(hand)[0])
            raw = solver.solve(observed)
            t = time.perf_counter()
            smooth = solver.solve(observed, rate=120.0)
            fps.append(len(observed) / (time.perf_counter() - t))
            raw_err.append(np.degrees(np.abs(raw.poses[:, 6:] - poses[:, 6:])).ravel())
            smooth_err.append(np.degrees(np.abs(smooth.poses[:, 6:] - poses[:, 6:])).ravel())
            rms.append(smooth.overall_rms() * 1000)
        r, s = np.concatenate(raw_err), np.concatenate(smooth_err)
        lines.append(f"| {name} | {len(raw_err)} x 3000 | {np.median(r):.2f} | {np.percentile(r, 95):.2f} | "
                     f"{np.median(s):.2f} | {np.percentile(s, 95):.2f} | {np.mean(rms):.2f} | {np.median(fps):,.0f} |")
        print(lines[-1], flush=True)
    lines += ["", "Bar: median <= 2 degrees, 95th percentile <= 6 degrees (han19: the layout with a marker on every "
              "phalanx group; glove13 has one marker per finger besides the tip, so PIP and DIP share one "
              "constraint and the table shows it).", ""]


def speed(args, lines):
    layout = load_layout("han19")
    hand = HandModel(side="right")
    _, observed = marker_motion(layout, hand, 10_000, 42, 0.001)
    solver = HandSolver(hand, layout.place(hand)[0])
    rows = []
    for label, rate in (("per-frame fit", None), ("with smoothing (default)", 120.0)):
        best = np.inf
        for _ in range(1 if args.quick else 3):
            t = time.perf_counter()
            solver.solve(observed, rate=rate)
            best = min(best, time.perf_counter() - t)
        rows.append(f"| {label} | {len(observed)} | {best:.2f} | {len(observed) / best:,.0f} |")
        print(rows[-1], flush=True)
    lines += ["## Speed (one hand, han19, 10,000 frames, 2 cores)", "",
              "| solve | frames | seconds | frames/s |", "|---|---|---|---|", *rows, "",
              "Bar: at least 1,000 frames/s. Frames are solved in lock-stepped chunks (up to 256 side by side), "
              "each warm-started from its predecessor with 5 Levenberg-Marquardt steps on the analytic Jacobian.", ""]


def calibration(args, lines):
    layout = load_layout("han19")
    lines += ["## Calibration recovery (synthetic, han19, 2,400 frames, 0.5 mm noise)", "",
              "Offsets: every marker moved 10 mm in a random direction. Length: the hand 10 % longer than the "
              "starting hand. `flat` = the take starts with 0.5 s of flat hand given as reference frames; "
              "`pinch` = 32 frames where the thumb pad touches a finger pad, given as contacts.", "",
              "| perturbation | reference | seed | length error | max offset error mm | mean offset error mm | "
              "RMS before -> after mm | seconds |", "|---|---|---|---|---|---|---|---|"]
    for kind in ("offsets", "length", "both"):
        for reference in ("flat", "pinch", "none"):
            for seed in range(1 if args.quick else 2):
                rng = np.random.default_rng(100 + seed)
                side = "left" if seed else "right"
                base = HandModel(side=side)
                true = HandModel(base.length * (1.1 if kind != "offsets" else 1.0), base.breadth, side)
                offsets = rng.normal(size=(len(layout), 3))
                offsets *= 0.010 / np.linalg.norm(offsets, axis=1, keepdims=True)
                if kind == "length":
                    offsets[:] = 0
                fingers = ("index", "middle", "ring", "little")
                pinches = [(100 + 37 * i, fingers[i % 4]) for i in range(32)] if reference == "pinch" else []
                _, observed = marker_motion(layout, true, 2400, 100 + seed, 0.0005, offsets,
                                            flat_frames=60 if reference == "flat" else 0, pinches=pinches)
                t = time.perf_counter()
                cal = calibrate(observed, layout, hand=base, contacts=pinches,
                                reference=np.arange(60) if reference == "flat" else None)
                dt = time.perf_counter() - t
                err = np.linalg.norm(cal.offsets - offsets, axis=1) * 1000
                lines.append(f"| {kind} | {reference} | {seed} | "
                             f"{100 * (cal.length / true.length - 1):+.2f} % | {err.max():.2f} | {err.mean():.2f} | "
                             f"{cal.rms_before * 1000:.2f} -> {cal.rms_after * 1000:.2f} | {dt:.1f} |")
                print(lines[-1], flush=True)
    lines += ["", "Bars: offsets within 2 mm, length within 2 %. Without a reference pose, an offset of a lone "
              "marker on a phalanx along its arc is exactly a constant joint-angle bias, so the data cannot tell "
              "them apart and the prior decides; a reference pose (the flat hand most range-of-motion protocols "
              "start with) settles it.", ""]


def real_glove(args, lines):
    from datasets import GLOVE13

    if not os.path.isfile(GLOVE13):
        lines += ["## Real glove13 recording", "", f"skipped: {GLOVE13} not available", ""]
        return
    from mocap_autolabel.core.labeling import layout_markers
    from mocap_autolabel.core.take import read_take

    layout = load_layout("glove13")
    take = read_take(GLOVE13)
    observed = layout_markers(take, layout)
    half = len(observed) // 2
    t = time.perf_counter()
    cal = calibrate(observed[:half], layout)
    dt = time.perf_counter() - t
    default = HandModel(side=cal.side)
    before = HandSolver(default, layout.place(default)[0]).solve(observed, rate=take.rate)
    after = cal.solver(layout).solve(observed, rate=take.rate)
    held = np.sqrt(np.nanmean(after.residuals[half:] ** 2)) * 1000
    held_before = np.sqrt(np.nanmean(before.residuals[half:] ** 2)) * 1000
    lines += ["## Real glove13 recording (Qualisys, 13 markers, 3,000 frames at 100 Hz)", "",
              "Calibrated on the first half; the second half is held out.", "",
              "| | marker RMS, whole take mm | held-out half mm |", "|---|---|---|",
              f"| average hand, layout positions | {before.overall_rms() * 1000:.2f} | {held_before:.2f} |",
              f"| calibrated ({cal.side} hand {cal.length * 1000:.1f} x {cal.breadth * 1000:.1f} mm, {dt:.1f} s) | "
              f"{after.overall_rms() * 1000:.2f} | {held:.2f} |", "", "Bar: at most 3 mm after calibration.", ""]
    print(*lines[-6:], sep="\n", flush=True)


def _solve_once(addon: str, path: str) -> dict:
    """One ``python -m mocap_autolabel solve`` of ``path`` with the package from ``addon``: wall and CPU
    seconds of the whole process, and its report's calibration and fit figures."""
    with tempfile.TemporaryDirectory() as tmp:
        report = os.path.join(tmp, "report.json")
        env = dict(os.environ, PYTHONPATH=os.path.abspath(addon))
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "mocap_autolabel", "solve", path, "--layout", "glove13", "--quiet",
                        "--report", report], env=env, check=True, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        with open(report, encoding="utf-8") as f:
            data = json.load(f)
    cal = data["calibration"]
    return {"wall": wall, "cpu": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "calibrate": data["seconds"]["calibrate"], "ik": data["seconds"]["solve"], "frames": data["frames"],
            "cal_rms": cal["rms_before_mm"], "cal_rms_after": cal["rms_after_mm"], "rms": data["marker_rms_mm"],
            "over_gate": data["frames_over_gate"]}


def end_to_end(args, lines):
    """`solve` on the real glove recording, 5 runs (alternating with the baseline's when given): medians."""
    from datasets import GLOVE13

    if not os.path.isfile(GLOVE13):
        lines += [END_TO_END, "", f"skipped: {GLOVE13} not available", ""]
        return
    runs = 3 if args.quick else 5
    setups = [("this checkout", ADDON)] + ([("baseline", args.baseline)] if args.baseline else [])
    results = {name: [] for name, _ in setups}
    for _ in range(runs):
        for name, addon in setups:
            results[name].append(_solve_once(addon, GLOVE13))
    rows = []
    for name, _ in setups:
        r = results[name]

        def med(key, r=r):
            return float(np.median([x[key] for x in r]))

        rows.append(f"| {name} | {med('wall'):.2f} | {med('cpu'):.2f} | {med('calibrate'):.2f} | "
                    f"{r[0]['cal_rms']:.2f} -> {r[0]['cal_rms_after']:.4f} | {med('ik'):.2f} | "
                    f"{r[0]['frames'] / med('ik'):,.0f} | {r[0]['rms']:.4f} | {r[0]['over_gate']} |")
        print(rows[-1], flush=True)
    ratio = []
    if args.baseline:
        new, old = results["this checkout"], results["baseline"]
        wall = np.median([a["wall"] / b["wall"] for a, b in zip(new, old)])
        cpu = np.median([a["cpu"] / b["cpu"] for a, b in zip(new, old)])
        ratio = [f"Paired ratios, this checkout / baseline (median of {runs} pairs): wall {wall:.3f}, "
                 f"CPU {cpu:.3f}.", ""]
    lines += [END_TO_END, "",
              f"`python -m mocap_autolabel solve recording_part1.tsv --layout glove13` (3,000 frames at 100 Hz, "
              f"calibration included), {runs} runs each, medians; whole process (start-up and reading included). "
              f"Seconds per stage from the report; IK frames/s = frames / IK seconds. Machine: {os.cpu_count()} "
              f"cores, shared (other jobs running: the CPU column is the steadier one).", "",
              "| code | wall s | CPU s | calibration s | calibration RMS mm (before -> after) | IK s | IK frames/s | "
              "marker RMS mm | frames over gate |", "|---|---|---|---|---|---|---|---|---|", *rows, "", *ratio,
              "Bar (issue 48): under 4 s on a quiet machine (11.7 s before), the calibration's RMS no worse.", ""]


def _replace_section(path: str, heading: str, section: list[str]) -> None:
    """Put ``section`` (starting with ``heading``) in place of that section of the report at ``path``."""
    old = open(path, encoding="utf-8").read().split("\n") if os.path.isfile(path) else []
    start = next((i for i, line in enumerate(old) if line == heading), None)
    if start is None:
        old = old + [""] if old and old[-1] != "" else old
        new = old + section
    else:
        end = next((i for i in range(start + 1, len(old)) if old[i].startswith("## ")), len(old))
        new = old[:start] + section + old[end:]
    write_report(path, new if new[-1] != "" else new[:-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="fewer takes and repeats")
    parser.add_argument("--solve-only", action="store_true", help="only the `solve` end-to-end section")
    parser.add_argument("--baseline", metavar="ADDON", help="another checkout's addon folder to compare with")
    args = parser.parse_args()
    if args.solve_only:
        section = []
        end_to_end(args, section)
        _replace_section(REPORT, END_TO_END, section)
        return
    lines = ["# Hand solve benchmark", "",
             "`python benchmarks/hand_solve.py`; numbers from this machine (2 cores). On a shared machine the "
             "seconds follow its load; compare figures measured together (the end-to-end section alternates "
             "runs with `--baseline`).", ""]
    speed(args, lines)
    joint_errors(args, lines)
    calibration(args, lines)
    real_glove(args, lines)
    end_to_end(args, lines)
    write_report(REPORT, lines)


if __name__ == "__main__":
    main()
