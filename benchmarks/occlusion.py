"""Heavy occlusion: han2018 hands with a quarter of their samples missing in long gaps, ghosts that
stay and noise; and the no-hand rule on them, on takes of two hands and on the body captures.

(a) Every han2018 TRC of Users 1 and 2 (both hands' files, every length: 336 takes of 26-500
    frames; the 10 per user that ``benchmarks/temporal.py`` fits gmm on are in too, since no gmm
    is fitted here) corrupted at :data:`HEAVY` (``corrupt_take``, seed 1000 * user + index of the
    file), labeled as the CLI labels (``process_take``: ``label_take``'s defaults, the layout
    check, the no-hand rule). Instances, frames all right, the kinds of errors and where they sit.
(b) Two hands: the left and right files of every han2018 sequence of Users 1-2 as one take (every
    length), corrupted at :data:`HEAVY` and at ``corrupt_take``'s default (as
    ``benchmarks/two_hands.py``), labeled with ``--hands auto`` and ``--hands 1``; synthetic
    interacting hands (``core.synth.two_hands``) the same.
(c) Every C3D file of ../shared/data/c3d with marker samples (body captures, a cube, probes: no
    hand), labeled with the layout ``choose_layout`` gives it, without the layout check: without a
    better layout named the no-hand rule also takes labels it does not believe where they are most
    of the frame (``checks.ALONE``), so a file refused here is refused with the check too.

(d) What each part of the heavy corruption costs, with the vote and per frame, and the vote's
    settings on the heavy takes (every 4th file of (a)).
(e) The real glove13 recording's labeled tracks at :data:`HEAVY` (4 seeds), with ``glove13``'s
    shipped settings and without the occlusion prior.

Writes ``benchmarks/reports/occlusion.md``.

    python benchmarks/occlusion.py [--limit N] [--pairs N] [--synthetic N] [--bodies N] [--ablation N]
"""

from __future__ import annotations

import argparse
import csv
import glob
import os
import platform
import sys
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from datasets import DATA, GLOVE13, HAN2018, glove13_take, layout_columns, write_report  # noqa: E402
from mocap_autolabel.core.cache import RunCache  # noqa: E402
from mocap_autolabel.core.checks import HAND_FRAMES, _believed, hand_checks, hand_share  # noqa: E402
from mocap_autolabel.core.errors import MocapInputError  # noqa: E402
from mocap_autolabel.core.labeling import labeled_take  # noqa: E402
from mocap_autolabel.core.layout import load_layout  # noqa: E402
from mocap_autolabel.core.metrics import score_labeling  # noqa: E402
from mocap_autolabel.core.pipeline import label_take  # noqa: E402
from mocap_autolabel.core.process import Outputs, choose_layout, process_take  # noqa: E402
from mocap_autolabel.core.settings import LabelSettings  # noqa: E402
from mocap_autolabel.core.synth.generate import TakeCorruption, corrupt_take  # noqa: E402
from mocap_autolabel.core.synth.two_hands import two_hand_take  # noqa: E402
from mocap_autolabel.core.take import Take, read_take  # noqa: E402

REPORTS = Path(__file__).parent / "reports"
C3D = os.path.join(DATA, "c3d")
#: A quarter of the samples missing in gaps of about 15 frames at 120 Hz, three ghost tracks that
#: stay 1-3 s, 1 mm noise (the rest as ``corrupt_take``'s default: flicker ghosts, broken
#: trajectories, a swap in some takes).
HEAVY = TakeCorruption(gaps_per_minute=138, mean_gap_s=15 / 120, persistent_ghosts=3, noise_sd=0.001)
RATE = 120.0
#: Take lengths (frames) the figures are split by.
LENGTHS = (0, 60, 120, 240, 10**9)
#: Segment lengths (frames) the errors are split by.
SEGMENTS = (1, 6, 16, 31, 61, 10**9)
#: A ghost trajectory at least this long is one of the ghosts that stay (flicker ghosts last ~4 frames).
LONG_GHOST = 30
KINDS = ("wrong label", "ghost labeled", "marker left null")


@dataclass
class Verdict:
    """What the CLI would say of a take: ``refused`` with the message, or labeled with ``warnings``;
    ``shares`` per hand and ``believed`` (the share of frames whose believed labels alone make a
    hand, the rule before heavy occlusion), from the labeling the rule judged."""

    refused: str | None
    warnings: list[str] = field(default_factory=list)
    shares: list[float] = field(default_factory=list)
    believed: list[float] = field(default_factory=list)
    labeling: object = None
    count: int = 1
    compact: list[float] = field(default_factory=list)


def believed_share(take: Take, layout, labeling, believed: bool = True) -> list[float]:
    """Per hand, the share of frames whose believed labels alone (``believed``; else all labels,
    however many other points the frame shows) hold half the layout within reach."""
    m = len(layout)
    hands = labeling.info["hands"]
    parts = [labeling] if hands.get("count", 1) < 2 else [labeling.label_range(h * m, (h + 1) * m) for h in range(2)]
    return [hand_share(labeled_take(take, part).positions[:, :m], _believed(part, m) if believed else None)
            for part in parts]


def verdict(take: Take, layout, settings: LabelSettings, cache: RunCache, check_layout: bool = True) -> Verdict:
    """The CLI's verdict on ``take``; where it refuses, the take labeled again without the rule for
    the shares."""
    outputs = Outputs(check_layout=check_layout)
    try:
        result = process_take(take, layout, settings, outputs, cache=cache)
    except MocapInputError as exc:
        result = process_take(take, layout, settings, Outputs(check_hand=False, check_layout=False), cache=cache)
        checks = hand_checks(take, layout, result.labeling)
        lab = result.labeling
        return Verdict(exc.problem, [], [c.share for _, c in checks], believed_share(take, layout, lab), lab,
                       lab.info["hands"]["count"], believed_share(take, layout, lab, believed=False))
    lab = result.labeling
    return Verdict(None, result.warnings, [c.share for _, c in result.checks], believed_share(take, layout, lab), lab,
                   lab.info["hands"]["count"], believed_share(take, layout, lab, believed=False))


def han_files(user: str) -> list[str]:
    return sorted(glob.glob(os.path.join(HAN2018, user, "capture*", "*.trc")))


def han_markers(path: str, layout) -> np.ndarray:
    take = read_take(path)
    return take.positions[:, layout_columns(take.names, layout)].astype(np.float64)


def sample_errors(take: Take, truth: np.ndarray, labeling) -> dict:
    """Every wrongly labeled sample of a one-hand take, by kind: the length of its segment, and for
    ghosts whether the ghost stays (:data:`LONG_GHOST`) and whether the marker whose label it took
    was seen in that frame; for markers left null, whether another sample took their label and how
    near the nearest ghost was."""
    per = labeling.per_sample()
    valid = take.valid
    seg = labeling.segment_ids()
    seglen = np.where(seg >= 0, labeling.length[np.maximum(seg, 0)], 0)
    kinds = {"wrong label": valid & (per >= 0) & (truth >= 0) & (per != truth),
             "ghost labeled": valid & (per >= 0) & (truth < 0),
             "marker left null": valid & (per < 0) & (truth >= 0)}
    out: dict = {k: {"segments": np.zeros(len(SEGMENTS) - 1, np.int64)} for k in KINDS}
    for k, mask in kinds.items():
        out[k]["segments"] += np.histogram(seglen[mask], bins=SEGMENTS)[0]
        out[k]["samples"] = int(mask.sum())
    # Ghosts labeled: a ghost that stays or a flicker; the marker whose label it took seen or not.
    ghost_run = np.zeros(per.shape, np.int64)
    for slot in range(per.shape[1]):  # the length of each run of ghost samples, per slot
        g = valid[:, slot] & (truth[:, slot] < 0)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], g.astype(np.int8), [0]])))
        for a, b in zip(edges[::2], edges[1::2]):
            ghost_run[a:b, slot] = b - a
    f, p = np.nonzero(kinds["ghost labeled"])
    seen = np.array([(truth[fi] == per[fi, pi]).any() for fi, pi in zip(f, p)], dtype=bool)
    stays = ghost_run[f, p] >= LONG_GHOST
    out["ghost labeled"]["stays"] = int(stays.sum())
    out["ghost labeled"]["label's marker seen"] = int(seen.sum())
    # Markers left null: their label given to another sample, or to none; the nearest ghost.
    f, p = np.nonzero(kinds["marker left null"])
    taken = np.array([(per[fi] == truth[fi, pi]).any() for fi, pi in zip(f, p)], dtype=bool)
    pos = take.positions.astype(np.float64)
    near = np.full(len(f), np.inf)
    for n, (fi, pi) in enumerate(zip(f, p)):
        ghosts = valid[fi] & (truth[fi] < 0)
        if ghosts.any():
            near[n] = np.linalg.norm(pos[fi, ghosts] - pos[fi, pi], axis=1).min()
    out["marker left null"]["label taken"] = int(taken.sum())
    out["marker left null"]["ghost within 2 cm"] = int((near < 0.02).sum())
    out["marker left null"]["ghost within 5 cm"] = int((near < 0.05).sum())
    # Frames not all right: what they hold.
    bad = np.zeros((len(per), len(KINDS)), dtype=bool)
    for j, k in enumerate(KINDS):
        bad[:, j] = kinds[k].any(axis=1)
    out["frames"] = {"any": int(bad.any(axis=1).sum()),
                     **{f"only {k}": int((bad[:, j] & (bad.sum(axis=1) == 1)).sum()) for j, k in enumerate(KINDS)}}
    return out


def add_errors(total: dict | None, one: dict) -> dict:
    if total is None:
        return {k: (dict(v) if isinstance(v, dict) else v) for k, v in one.items()}
    for k, v in one.items():
        for key, x in v.items():
            total[k][key] = total[k][key] + x
    return total


def run_heavy(layout, limit: int | None, cache: RunCache) -> list[dict]:
    m = len(layout)
    rows = []
    for u, user in enumerate(("User1", "User2")):
        for i, path in enumerate(han_files(user)[:limit]):
            take, truth, _ = corrupt_take(han_markers(path, layout), RATE, seed=1000 * u + i, cfg=HEAVY)
            t = time.perf_counter()
            v = verdict(take, layout, LabelSettings(), cache)
            seconds = time.perf_counter() - t
            # Scored on label_take's defaults (the labeling the rule judged, unless it went on to two hands).
            lab = v.labeling if v.count == 1 else label_take(take, layout, cache=cache)
            s = score_labeling(lab.per_sample(), truth, take.valid, m).as_dict()
            name = f"{user}/{os.path.relpath(path, os.path.join(HAN2018, user))}"
            rows.append({"name": name, "frames": take.n_frames,
                         "refused": v.refused, "share": min(v.shares), "believed": min(v.believed),
                         "count": v.count, "warnings": v.warnings, "score": s, "seconds": seconds,
                         "errors": sample_errors(take, truth, lab),
                         "seen": float(np.mean([(truth == j).any(axis=1).mean() for j in range(m)]))})
            print(f"  {rows[-1]['name']}: {take.n_frames} frames, {'REFUSED' if v.refused else 'hand'} "
                  f"({100 * rows[-1]['share']:.0f} %), {100 * s['correct'] / s['instances']:.2f} % right", flush=True)
    return rows


def truth_hand(truth: np.ndarray, labeling, m: int) -> tuple[int | None, float]:
    """The true hand (0 left file, 1 right file) most of a one-hand labeling's labels sit on, and the
    share of its labeled samples that carry their true label (within that hand)."""
    per = labeling.per_sample()
    ok = (per >= 0) & (truth >= 0)
    if not ok.any():
        return None, 0.0
    hand = int(np.bincount(truth[ok] // m, minlength=2).argmax())
    labeled = per >= 0
    return hand, float(((truth == per + hand * m) & labeled).sum() / max(labeled.sum(), 1))


def run_pairs(layout, limit: int | None, cache: RunCache) -> list[dict]:
    m = len(layout)
    rows = []
    for u, user in enumerate(("User1", "User2")):
        lefts = sorted(glob.glob(os.path.join(HAN2018, user, "capture*", "*_left.trc")))
        for i, left in enumerate(lefts[:limit]):
            right = left.replace("_left.trc", "_right.trc")
            if not os.path.isfile(right):
                continue
            a, b = han_markers(left, layout), han_markers(right, layout)
            n = min(len(a), len(b))
            for corruption, cfg in (("heavy", HEAVY), ("default", None)):
                take, truth, _ = corrupt_take(np.concatenate([a[:n], b[:n]], axis=1), RATE, seed=1000 * u + i,
                                              cfg=cfg)
                auto = verdict(take, layout, LabelSettings(), cache)
                one = verdict(take, layout, LabelSettings(hand_count=1), cache)
                s = score_labeling(auto.labeling.per_sample(), truth, take.valid, 2 * m).as_dict()
                hand, right_share = truth_hand(truth, one.labeling, m) if one.count == 1 else (None, 0.0)
                rows.append({"name": f"{user}/{os.path.relpath(left, os.path.join(HAN2018, user))}", "frames": n,
                             "corruption": corruption, "auto": auto, "one": one, "score": s, "one_hand": hand,
                             "one_right": right_share})
            print(f"  {rows[-1]['name']}: {n} frames, auto {[r['auto'].refused is None for r in rows[-2:]]}, "
                  f"--hands 1 {[r['one'].refused is None for r in rows[-2:]]}", flush=True)
    return rows


def run_synthetic(layout, takes: int, cache: RunCache, frames: int = 1200) -> list[dict]:
    m = len(layout)
    rows = []
    for seed in range(takes):
        two = two_hand_take(layout, frames, seed)
        auto = verdict(two.take, layout, LabelSettings(), cache)
        one = verdict(two.take, layout, LabelSettings(hand_count=1), cache)
        hand, right_share = truth_hand(two.labels, one.labeling, m) if one.count == 1 else (None, 0.0)
        rows.append({"name": f"synthetic seed {seed}", "frames": frames, "auto": auto, "one": one, "one_hand": hand,
                     "one_right": right_share})
        print(f"  synthetic {seed}: auto {auto.refused is None}, --hands 1 {one.refused is None}", flush=True)
    return rows


def median_frame(take: Take, labeling) -> tuple[int, int]:
    """The median frame's points and labels (over frames that show points)."""
    shown = take.valid.any(axis=1)
    if not shown.any():
        return 0, 0
    return (int(np.median(take.valid.sum(axis=1)[shown])),
            int(np.median((labeling.per_sample() >= 0).sum(axis=1)[shown])))


#: What each part of :data:`HEAVY` costs (the rest of it kept).
ABLATION = {"heavy": HEAVY,
            "no ghosts that stay": replace(HEAVY, persistent_ghosts=0),
            "no flicker ghosts": replace(HEAVY, flicker_ghosts_per_frame=0),
            "no ghosts at all": replace(HEAVY, persistent_ghosts=0, flicker_ghosts_per_frame=0),
            "no noise": replace(HEAVY, noise_sd=0.0),
            "no broken trajectories, no swap": replace(HEAVY, fragments_per_minute=0, swap_share=0),
            "the gaps alone": replace(HEAVY, persistent_ghosts=0, flicker_ghosts_per_frame=0, noise_sd=0,
                                      fragments_per_minute=0, swap_share=0),
            "corrupt_take's default (for comparison)": TakeCorruption()}
#: The vote's fitted settings against others (``LabelSettings`` fields; the shipped fit first).
VOTE_SETTINGS = {"shipped fit": {}, "stride 1 (every frame scored)": {"stride": 1},
                 "null prior (0, 0)": {"null_prior": (0.0, 0.0)}, "continuity (0, 1)": {"continuity": (0.0, 1.0)},
                 "partner (2, 4)": {"partner": (2.0, 4.0)},
                 "continuity (0, 1), partner (2, 4)": {"continuity": (0.0, 1.0), "partner": (2.0, 4.0)},
                 "no occlusion prior (0, 0)": {"occlusion_prior": (0.0, 0.0)}}
SCORED = ("instances", "correct", "frames", "frames_all_correct", "erroneous", "false_marker", "false_occlusion")


def run_ablation(layout, limit: int | None, every: int, cache: RunCache) -> dict:
    """Every ``every``-th han2018 file of each user under each corruption of :data:`ABLATION`, with
    the vote and per frame (``temporal none``: the labeler alone); the vote's settings on :data:`HEAVY`."""
    m = len(layout)
    tracks = [(1000 * u + i, han_markers(path, layout)) for u, user in enumerate(("User1", "User2"))
              for i, path in list(enumerate(han_files(user)[:limit]))[::every]]

    def score(cfg: TakeCorruption, settings: LabelSettings) -> np.ndarray:
        total = np.zeros(len(SCORED), np.int64)
        for seed, x in tracks:
            take, truth, _ = corrupt_take(x, RATE, seed=seed, cfg=cfg)
            s = score_labeling(label_take(take, layout, settings, cache=cache).per_sample(), truth, take.valid,
                               m).as_dict()
            total += [s[k] for k in SCORED]
        return total

    out = {"takes": len(tracks), "frames": sum(len(x) for _, x in tracks), "every": every, "corruption": {},
           "vote": {}}
    for name, cfg in ABLATION.items():
        out["corruption"][name] = [score(cfg, LabelSettings()), score(cfg, LabelSettings(temporal="none"))]
        print(f"  {name}: {pct(out['corruption'][name][0][1], out['corruption'][name][0][0])} %", flush=True)
    for name, fields in VOTE_SETTINGS.items():
        out["vote"][name] = out["corruption"]["heavy"][0] if not fields else score(HEAVY, LabelSettings(**fields))
        print(f"  {name}: {pct(out['vote'][name][1], out['vote'][name][0])} %", flush=True)
    return out


def ablation_lines(ab: dict) -> list[str]:
    lines = ["", f"### What costs what: every {ab['every']}th file of each user ({ab['takes']} takes, "
             f"{ab['frames']:,} frames)", "",
             "Each part of the heavy corruption left out in turn; `vote` is the default, `none` the per-frame "
             "labeler alone (its assignment per frame, no trajectories).", "",
             "| corruption | vote: instances right % | frames all right % | none: instances right % "
             "| frames all right % |", "|---|---|---|---|---|"]
    for name, (vote, alone) in ab["corruption"].items():
        lines.append(f"| {name} | {pct(vote[1], vote[0])} | {pct(vote[3], vote[2])} | {pct(alone[1], alone[0])} | "
                     f"{pct(alone[3], alone[2])} |")
    lines += ["", "The vote's settings (`LabelSettings` fields) on the heavy takes:", "",
              "| settings | instances right % | frames all right % | wrong / ghost labeled / left null (instances) |",
              "|---|---|---|---|"]
    for name, t in ab["vote"].items():
        lines.append(f"| {name} | {pct(t[1], t[0])} | {pct(t[3], t[2])} | {t[4]:,} / {t[5]:,} / {t[6]:,} |")
    return lines


#: Seeds of :func:`run_glove`'s heavy corruptions of the real glove13 recording.
GLOVE_SEEDS = range(4)


def run_glove(cache: RunCache) -> dict:
    """The real qualisys_glove13 recording's labeled tracks at :data:`HEAVY` (its other markers
    kept as distractors, at its own 100 Hz), labeled with ``glove13``'s shipped settings and
    without the occlusion prior: summed :data:`SCORED` counts of each, and the takes' break rates."""
    layout = load_layout("glove13")
    take, truth = glove13_take(layout)
    markers = np.full((take.n_frames, len(layout), 3), np.nan)
    markers[:, truth[truth >= 0]] = take.positions[:, truth >= 0]
    extra = take.positions[:, truth < 0]
    out = {"frames": take.n_frames, "takes": len(GLOVE_SEEDS), "rates": [], "shipped": np.zeros(len(SCORED), np.int64),
           "no occlusion prior": np.zeros(len(SCORED), np.int64)}
    for seed in GLOVE_SEEDS:
        heavy, labels, _ = corrupt_take(markers, take.rate, seed=seed, cfg=HEAVY, extra=extra)
        for key, settings in (("shipped", LabelSettings()), ("no occlusion prior",
                                                             LabelSettings(occlusion_prior=(0.0, 0.0)))):
            labeling = label_take(heavy, layout, settings, cache=cache)
            s = score_labeling(labeling.per_sample(), labels, heavy.valid, len(layout)).as_dict()
            out[key] += [s[k] for k in SCORED]
        out["rates"].append(labeling.info["break_rate"])
        print(f"  glove13 seed {seed}: break rate {out['rates'][-1]:.2f} a second", flush=True)
    return out


def glove_lines(glove: dict) -> list[str]:
    lines = ["", f"### The real glove13 recording under the same corruption ({glove['takes']} seeds of its "
             f"{glove['frames']:,} frames at 100 Hz)", "",
             f"Break rates {min(glove['rates']):.2f}-{max(glove['rates']):.2f} a second (the recording as captured: "
             "0.01).", "",
             "| settings | instances right % | frames all right % | wrong / ghost labeled / left null (instances) |",
             "|---|---|---|---|"]
    for name in ("shipped", "no occlusion prior"):
        t = glove[name]
        lines.append(f"| {name} | {pct(t[1], t[0])} | {pct(t[3], t[2])} | {t[4]:,} / {t[5]:,} / {t[6]:,} |")
    return lines


def run_bodies(limit: int | None, cache: RunCache) -> list[dict]:
    reference = os.path.join(C3D, "REFERENCE.tsv")
    files = [r["path"] for r in csv.DictReader(open(reference, encoding="utf-8"), delimiter="\t")
             if r["points"] not in ("", "0")]
    rows = []
    for path in files[:limit]:
        full = os.path.join(C3D, path)
        t = time.perf_counter()
        try:
            take = read_take(full)
            layout = load_layout(choose_layout(take, None))
            v = verdict(take, layout, LabelSettings(), cache, check_layout=False)
        except MocapInputError as exc:  # unreadable, or no marker samples: refused before the rule
            rows.append({"name": path, "points": None, "refused": exc.problem, "share": 0.0, "believed": 0.0,
                         "compact": 0.0, "before_rule": True, "seconds": time.perf_counter() - t})
            print(f"  {path}: {exc.problem}", flush=True)
            continue
        rows.append({"name": path, "points": take.n_points, "frames": take.n_frames, "layout": layout.name,
                     "refused": v.refused, "share": max(v.shares), "believed": max(v.believed),
                     "compact": max(v.compact), "before_rule": False, "seconds": time.perf_counter() - t,
                     "median": median_frame(take, v.labeling)})
        print(f"  {path}: {'refused' if v.refused else 'HAND FOUND'} ({100 * rows[-1]['share']:.1f} %) "
              f"{rows[-1]['seconds']:.1f} s", flush=True)
    return rows


def pct(a: float, b: float, digits: int = 2) -> str:
    return f"{100 * a / max(b, 1):.{digits}f}"


def heavy_lines(rows: list[dict]) -> list[str]:
    keys = ("instances", "correct", "frames", "frames_all_correct", "erroneous", "false_marker", "false_occlusion")
    total = {k: sum(r["score"][k] for r in rows) for k in keys}
    refused = [r for r in rows if r["refused"]]
    closest = min(rows, key=lambda r: r["share"])
    old = [r for r in rows if r["believed"] < HAND_FRAMES]
    lines = [f"## (a) Heavy occlusion: {len(rows)} han2018 takes of Users 1-2", "",
             f"{sum(r['frames'] for r in rows):,} frames; each marker seen in "
             f"{100 * np.mean([r['seen'] for r in rows]):.1f} % of frames on average.", "",
             "| | |", "|---|---|",
             f"| instances right | {pct(total['correct'], total['instances'])} % |",
             f"| frames with every label right | {pct(total['frames_all_correct'], total['frames'])} % |",
             f"| wrong label / ghost labeled / marker left null (instances) | {total['erroneous']:,} / "
             f"{total['false_marker']:,} / {total['false_occlusion']:,} |",
             f"| refused by the no-hand rule | {len(refused)} of {len(rows)} |",
             f"| refused by the rule before (believed labels only) | {len(old)} of {len(rows)} |",
             f"| closest to refusal | {closest['name']} ({closest['frames']} frames): a hand in "
             f"{100 * closest['share']:.1f} % of frames (refused under {100 * HAND_FRAMES:.0f} %) |",
             f"| two hands read where one was refused as one | {sum(r['count'] == 2 for r in rows)} |",
             f"| seconds per take (CLI path, shared cache) | {np.mean([r['seconds'] for r in rows]):.2f} |", ""]
    for r in refused:
        lines.append(f"- refused: {r['name']}: {r['refused']}")
    lines += ["", "By take length:", "", "| frames | takes | refused | instances right % | frames all right % "
              "| lowest hand share % |", "|---|---|---|---|---|---|"]
    for lo, hi in zip(LENGTHS[:-1], LENGTHS[1:]):
        part = [r for r in rows if lo <= r["frames"] < hi]
        if not part:
            continue
        inst = sum(r["score"]["instances"] for r in part)
        frames = sum(r["score"]["frames"] for r in part)
        span = f"{lo}-{hi - 1}" if hi < 10**9 else f">= {lo}"
        lines.append(f"| {span} | {len(part)} | {sum(bool(r['refused']) for r in part)} | "
                     f"{pct(sum(r['score']['correct'] for r in part), inst)} | "
                     f"{pct(sum(r['score']['frames_all_correct'] for r in part), frames)} | "
                     f"{100 * min(r['share'] for r in part):.1f} |")
    errors = None
    for r in rows:
        errors = add_errors(errors, r["errors"])
    n_err = sum(errors[k]["samples"] for k in KINDS)
    lines += ["", f"### The errors ({n_err:,} samples of markers and ghosts labeled wrong)", "",
              "Per sample (a labeled or unlabeled point of a frame), by the length of the segment it was decided "
              "in (a trajectory between gaps, or the part of it between the vote's cuts):", "",
              "| kind | samples | " + " | ".join(f"{a}-{b - 1}" if b < 10**9 else f">= {a}"
                                                 for a, b in zip(SEGMENTS[:-1], SEGMENTS[1:])) + " |",
              "|---|---|" + "---|" * (len(SEGMENTS) - 1)]
    for k in KINDS:
        bins = " | ".join(f"{x:,}" for x in errors[k]["segments"])
        lines.append(f"| {k} | {errors[k]['samples']:,} | {bins} |")
    g, o, f = errors["ghost labeled"], errors["marker left null"], errors["frames"]
    seen = g["label's marker seen"]
    several = f["any"] - f["only wrong label"] - f["only ghost labeled"] - f["only marker left null"]
    lines += ["", f"- ghosts labeled: {g['stays']:,} of {g['samples']:,} on ghosts that stay (trajectories of "
              f">= {LONG_GHOST} frames), the rest flickers; {seen:,} took the label of "
              "a marker seen in the same frame (a duplicate), the rest that of a marker missing there.",
              f"- markers left null: {o['label taken']:,} of {o['samples']:,} had their label given to another sample "
              f"of the frame; a ghost within 2 cm of {o['ghost within 2 cm']:,} and within 5 cm of "
              f"{o['ghost within 5 cm']:,}.",
              f"- frames not all right: {f['any']:,}; with wrong labels only {f['only wrong label']:,}, ghosts "
              f"labeled only {f['only ghost labeled']:,}, markers left null only {f['only marker left null']:,}, "
              f"several kinds {several:,}."]
    return lines


def two_hand_lines(pairs: list[dict], synthetic: list[dict]) -> list[str]:
    lines = ["", "## (b) Two hands in one take", "",
             "Refusals by the no-hand rule; with `--hands 1`, the hand labeled (the one found in more frames, "
             "labeled on its own with the other hand's samples kept out) and its labeled samples that carry "
             "their true label.", "",
             "| takes | `--hands auto` refused | two hands found | instances right % | `--hands 1` refused "
             "| `--hands 1` warned | its labels right % | closest to refusal (share %) |",
             "|---|---|---|---|---|---|---|---|"]
    groups = [(f"han2018 pairs, {c} corruption", [r for r in pairs if r["corruption"] == c])
              for c in ("heavy", "default")]
    groups.append(("synthetic interacting hands (1,200 frames)", synthetic))
    for name, part in groups:
        if not part:
            continue
        inst = sum(r["score"]["instances"] for r in part if "score" in r)
        right = sum(r["score"]["correct"] for r in part if "score" in r)
        lows = [min(r["auto"].shares + [1.0]) if r["auto"].count == 2 else max(r["auto"].shares) for r in part]
        lines.append(f"| {name}: {len(part)} | {sum(bool(r['auto'].refused) for r in part)} | "
                     f"{sum(r['auto'].count == 2 for r in part)} | {pct(right, inst) if inst else '-'} | "
                     f"{sum(bool(r['one'].refused) for r in part)} | "
                     f"{sum(any('two hands found' in w for w in r['one'].warnings) for r in part)} | "
                     f"{100 * np.mean([r['one_right'] for r in part]):.2f} | {100 * min(lows):.1f} |")
    said = [r for r in pairs + synthetic if r["auto"].refused or r["one"].refused]
    for r in said[:10]:
        which = "auto" if r["auto"].refused else "--hands 1"
        lines.append(f"- refused ({which}): {r['name']} {r.get('corruption', '')}: "
                     f"{(r['auto'].refused or r['one'].refused)}")
    example = next((w for r in pairs + synthetic for w in r["one"].warnings if "two hands found" in w), None)
    if example:
        lines += ["", f"`--hands 1` on a take of two hands warns: \"{example}\""]
    fallback = [r for r in pairs + synthetic if any("labeled as two hands" in w for w in r["auto"].warnings)]
    lines += ["", f"`--hands auto`: {len(fallback)} takes whose two hands were rejected for one hand (two hands "
              "labeled under half of their samples confidently), found no hand as one and were labeled as two."]
    return lines


def body_lines(bodies: list[dict]) -> list[str]:
    ruled = [r for r in bodies if not r["before_rule"]]
    found = [r for r in ruled if not r["refused"]]
    closest = sorted(ruled, key=lambda r: (-r["share"], -r["compact"]))[:5]
    lines = ["", f"## (c) The shared C3D corpus: {len(bodies)} files with marker samples", "",
             f"{len(bodies) - len(ruled)} refused before the rule (unreadable, or no marker samples); "
             f"{len(ruled)} labeled and judged: **{len(ruled) - len(found)} refused, {len(found)} found a hand**.", "",
             "Closest to a hand: the share of frames that hold one (the rule refuses under "
             f"{100 * HAND_FRAMES:.0f} %), with believed labels only, and with every label however many other "
             "points the frame shows (neither belief nor `ALONE`: what the labels' compactness alone would say):",
             "", "| file | points | frames | hand share % | believed only % | any label, compact % "
             "| median frame: points, labels |", "|---|---|---|---|---|---|---|"]
    for r in closest:
        lines.append(f"| {r['name']} | {r['points']} | {r['frames']} | {100 * r['share']:.1f} | "
                     f"{100 * r['believed']:.1f} | {100 * r['compact']:.1f} | {r['median'][0]}, {r['median'][1]} |")
    for r in found:
        lines.append(f"- HAND FOUND in {r['name']}: {100 * r['share']:.1f} % of frames")
    example = next((r for r in ruled if "Vicon.c3d" in r["name"]), ruled[0] if ruled else None)
    if example:
        lines += ["", f"The message, on {example['name']}: \"{example['refused']}\""]
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--limit", type=int, help="han2018 files per user at most (a)")
    parser.add_argument("--pairs", type=int, help="han2018 pairs per user at most (b)")
    parser.add_argument("--synthetic", type=int, default=8, help="synthetic two-hand takes (default 8)")
    parser.add_argument("--bodies", type=int, help="C3D files at most (c)")
    parser.add_argument("--ablation", type=int, default=4, help="every Nth file of (a) in the ablation (0: none)")
    args = parser.parse_args()
    if not os.path.isdir(HAN2018):
        print(f"{HAN2018}: not found (the shared data): nothing to measure", file=sys.stderr)
        return 1
    warnings.simplefilter("ignore", RuntimeWarning)
    layout = load_layout("han19")
    cache = RunCache()
    t = time.perf_counter()
    print("(a) heavy occlusion", flush=True)
    heavy = run_heavy(layout, args.limit, cache)
    ablation = run_ablation(layout, args.limit, args.ablation, cache) if args.ablation else None
    glove = run_glove(cache) if os.path.isfile(GLOVE13) else None
    print("(b) two hands", flush=True)
    pairs = run_pairs(layout, args.pairs, cache)
    synthetic = run_synthetic(layout, args.synthetic, cache)
    print("(c) body captures", flush=True)
    bodies = run_bodies(args.bodies, cache) if os.path.isdir(C3D) else []
    hands_low = min(r["share"] for r in heavy)
    ruled = [r for r in bodies if not r["before_rule"]]
    body_high = max((r["share"] for r in ruled), default=0.0)
    compact = max(ruled, key=lambda r: r["compact"], default=None)
    lines = ["# Heavy occlusion and the no-hand rule", "",
             f"`python benchmarks/occlusion.py` on {platform.machine()}, Python {platform.python_version()}, "
             f"{os.cpu_count()} cores, {(time.perf_counter() - t) / 60:.0f} min"
             + ("" if args.limit is None else f" (--limit {args.limit})") + ". Heavy occlusion: "
             f"`TakeCorruption(gaps_per_minute={HEAVY.gaps_per_minute:g}, mean_gap_s={HEAVY.mean_gap_s:.4f}, "
             f"persistent_ghosts={HEAVY.persistent_ghosts}, noise_sd={HEAVY.noise_sd:g})` at {RATE:g} Hz: a quarter "
             "of the samples missing in gaps of about 15 frames, three ghost tracks that stay 1-3 s, 1 mm noise.", "",
             "The no-hand rule (`core/checks.py`): a frame holds a hand where half of the layout's markers are "
             "labeled within 0.25 m of their median, and the labels are believed (segment mean probability >= 0.5) "
             "or at least half the points the frame offers the hand (`ALONE`; not where another layout fits clearly "
             f"better); a hand is found where {100 * HAND_FRAMES:.0f} % of the frames hold one.", "",
             f"**Margins**: the lowest hand share of a heavy-occlusion take is {100 * hands_low:.1f} %, the highest of "
             f"a file of the corpus {100 * body_high:.1f} % (threshold {100 * HAND_FRAMES:.0f} %)"
             + (f"; the corpus file whose labels come closest to a hand's shape is {compact['name']}: "
                f"{100 * compact['compact']:.1f} % of its frames hold half the layout within reach, believed in "
                f"{100 * compact['believed']:.1f} %, among {compact['median'][0]} points in its median frame "
                f"({compact['median'][1]} labeled), where `ALONE` needs half" if compact else "") + ".", ""]
    lines += heavy_lines(heavy) + (ablation_lines(ablation) if ablation else []) + (glove_lines(glove) if glove else [])
    lines += two_hand_lines(pairs, synthetic)
    lines += body_lines(bodies)
    write_report(str(REPORTS / "occlusion.md"), lines)
    return 0


if __name__ == "__main__":
    sys.exit(main())
