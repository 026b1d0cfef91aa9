"""Label digest: proves that a refactor of ``core.pipeline.label_take`` keeps every label and confidence.

``run`` labels a fixed suite of takes (one case = one ``label_take`` call) and writes one ``.npz``
per case: ``per_sample`` (int16 ``(F, P)``, ``Labeling.per_sample()``), ``confidence`` (float32,
``Labeling.per_sample_confidence()``), ``segments`` (int64 ``(n, 5)``: slot, start, stop, label,
locked), ``names``, ``hands`` and ``props`` (JSON of ``info["hands"]`` / ``info["props"]``, keys
sorted). ``compare`` reads two such folders and says, per case, IDENTICAL or what differs; it exits
with 1 if any case differs, failed or is missing on either side.

The cases: (a) the temporal benchmark's han2018 raw takes, default settings, and on the first 8
the rows set/vote/power, set/viterbi, set/none, perm/vote/power, cnn/vote/power, gmm/vote,
gmm/viterbi, nearest/none; (b) the real glove13 recording, default and gmm/vote; (c) two hands:
han2018 left + right pairs (hands auto, and each hand alone with ``hands=1``), synthetic
interacting takes (seeds 0-5, 1,200 frames), long ones (seeds 0-1, 3,000 frames), a held prop
(seeds 0-1, props off and on); (d) the demo take (default and ``validate=True``) and the take of
``synth --hands 2 --layout han19 --frames 1200 --seed 2``; (e) re-solves with ``previous=`` the
take's default labeling: a constraint moving a mid-take segment to another label, and a split of
it, on the demo take (labeled whole again: it is too short for a local re-solve) and on 3,000-frame
one-hand and two-hand synthetic takes (only the stretch around the change labeled again); (f) windows:
5,000-frame one-hand and two-hand synthetic takes with ``window=2000``. ``--quick`` keeps a handful
(3 han2018 takes and 2 rows, glove default, 2 synthetic two-hand takes, demo, 2 re-solves, one window).

The script speaks both APIs of ``label_take``: the keyword one (``score=``, ``hands=``,
``constraints=``...) and the refactored one (``LabelSettings`` + ``Corrections``), chosen at run
time by :func:`label`. Run it from the repository root, the code to test first on PYTHONPATH::

    export PY="nice -n 10 .venv/bin/python"
    PYTHONPATH=/tmp/base/addon:/tmp/base/benchmarks $PY tools/label_digest.py run /tmp/digest_base
    PYTHONPATH=addon:benchmarks $PY tools/label_digest.py run /tmp/digest_new
    .venv/bin/python tools/label_digest.py compare /tmp/digest_base /tmp/digest_new

Add ``--quick`` to ``run`` for the short suite (compare then only the cases both folders hold:
``compare`` also takes ``--common``). ``--only SUBSTRING`` runs the cases whose name contains it.
Real data comes from ``$MOCAP_DATA``, default ``../shared/data`` beside the repository.
"""

from __future__ import annotations

import argparse
import functools
import inspect
import json
import os
import sys
import time
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# benchmarks/datasets.py finds the data relative to its own folder, which is wrong for a worktree
# elsewhere (/tmp/base): point it at the data beside this repository unless told otherwise.
os.environ.setdefault("MOCAP_DATA", str(ROOT.parent / "shared" / "data"))

DEMO = ROOT / "samples" / "demo_take.c3d"
#: The rows run on the first han2018 takes: (method, temporal, vote score).
HAN_ROWS = [("set", "vote", "power"), ("set", "viterbi", "likelihood"), ("set", "none", "likelihood"),
            ("perm", "vote", "power"), ("cnn", "vote", "power"), ("gmm", "vote", "likelihood"),
            ("gmm", "viterbi", "likelihood"), ("nearest", "none", "likelihood")]
HAN_ROW_TAKES = 8
_UNSET = object()  # "the API's default", for window


# --- the API adapter -------------------------------------------------------------------------------

@functools.cache
def _new_api() -> bool:
    """True where ``label_take`` takes ``LabelSettings`` and ``Corrections`` (the refactored API)."""
    from mocap_autolabel.core.pipeline import label_take

    try:
        from mocap_autolabel.core import settings
    except ImportError:
        return False
    return hasattr(settings, "LabelSettings") and "corrections" in inspect.signature(label_take).parameters


def label(take, layout, *, method: str = "set", temporal: str = "vote", score: str = "likelihood",
          hands: str | int = "auto", props: bool = True, validate: bool = False, window=_UNSET,
          constraints=(), splits=(), previous=None, labeler=None, start=None):
    """One ``label_take`` call in whichever API the code on the path has; ``window`` is passed only
    where given."""
    from mocap_autolabel.core.pipeline import label_take

    if _new_api():
        from mocap_autolabel.core.settings import Corrections, LabelSettings

        fields = {"method": method, "temporal": temporal, "vote_score": score, "hand_count": hands,
                  "props": props, "validate": validate}
        if window is not _UNSET:
            fields["window"] = window
        return label_take(take, layout, LabelSettings(**fields),
                          corrections=Corrections(constraints=tuple(constraints), splits=tuple(splits)),
                          previous=previous, labeler=labeler, start=start)
    options = {} if window is _UNSET else {"window": window}
    return label_take(take, layout, method=method, temporal=temporal, score=score, labeler=labeler, start=start,
                      hands=hands, props=props, validate=validate, constraints=list(constraints),
                      splits=list(splits), previous=previous, **options)


# --- the cases -------------------------------------------------------------------------------------

Case = tuple[str, Callable[[], object]]  # name, a thunk returning the Labeling


@functools.cache
def _layout(name: str):
    from mocap_autolabel.core.layout import load_layout

    return load_layout(name)


@functools.cache
def _resolve_take(key: str):
    """The takes re-solved: the demo take (1,200 frames: a re-solve of it is labeled whole, the
    stretch around any change being most of the take) and 3,000-frame synthetic ones, one hand
    and two hands apart, where only the stretch around the change is labeled again (as in
    tests/test_windows.py)."""
    from mocap_autolabel.core.synth.generate import synthesize
    from mocap_autolabel.core.synth.two_hands import TwoHandConfig, two_hand_take
    from mocap_autolabel.core.take import read_take

    if key == "demo":
        return read_take(DEMO)
    if key == "long1":
        return synthesize(_layout("han19"), 3000, seed=11).take
    if key == "long2":
        return two_hand_take(_layout("han19"), 3000, seed=4, config=TwoHandConfig(close_share=0.0)).take
    raise KeyError(key)


@functools.cache
def _first(key: str):
    """A take's default labeling: a case itself, and the ``previous`` of its re-solves."""
    return label(_resolve_take(key), _layout("han19"))


def _mid_segment(lab) -> int:
    """A labeled segment of 50 frames to half the take that neither starts nor ends the take, its
    middle nearest the take's (the longest labeled segment where there is none)."""
    n = lab.n_frames
    pick = np.flatnonzero((lab.label >= 0) & (lab.start > 0) & (lab.stop < n) & (lab.length >= 50)
                          & (lab.length <= n // 2))
    if len(pick):
        return int(pick[np.argmin(np.abs(lab.start[pick] + lab.stop[pick] - n))])
    return int(np.argmax(np.where(lab.label >= 0, lab.length, -1)))


def _resolve_constraint(key: str):
    """Label again with ``previous`` and one constraint that moves a mid-take segment to the next
    label of its hand."""
    from mocap_autolabel.core.labeling import Constraint

    first, m = _first(key), len(_layout("han19"))
    seg = _mid_segment(first)
    hand, index = divmod(int(first.label[seg]), m)
    c = Constraint(int(first.slot[seg]), int(first.start[seg]), int(first.stop[seg]), hand * m + (index + 1) % m)
    return label(_resolve_take(key), _layout("han19"), constraints=[c], previous=first)


def _resolve_split(key: str):
    """Label again with ``previous`` and a split in the middle of the chosen segment."""
    first = _first(key)
    seg = _mid_segment(first)
    cut = (int(first.slot[seg]), int((first.start[seg] + first.stop[seg]) // 2))
    return label(_resolve_take(key), _layout("han19"), splits=[cut], previous=first)


def han_cases(quick: bool) -> Iterator[Case]:
    """(a) The temporal benchmark's han2018 raw takes."""
    from temporal import han_cases as build

    layout = _layout("han19")
    cases = build(layout, None)
    fitted: dict[int, object] = {}

    def gmm(case):
        # One fit per subject, as the benchmark does.
        from mocap_autolabel.core.labelers.gmm import GmmLabeler

        if id(case.fit) not in fitted:
            fitted[id(case.fit)] = GmmLabeler(layout).fit(case.fit)
        return fitted[id(case.fit)]

    picked = [0, 1, len(cases) - 1] if quick else range(len(cases))
    for i in picked:
        c = cases[i]
        yield f"han/{i:03d}/default", functools.partial(label, c.take, layout)
    for i in ([0] if quick else range(min(HAN_ROW_TAKES, len(cases)))):
        c = cases[i]
        for method, temporal, score in (HAN_ROWS[:1] + HAN_ROWS[5:6] if quick else HAN_ROWS):
            row = f"{method}-{temporal}" + ("-power" if score == "power" else "")
            yield f"han/{i:03d}/{row}", functools.partial(
                lambda c, method, temporal, score: label(
                    c.take, layout, method=method, temporal=temporal, score=score,
                    labeler=gmm(c) if method == "gmm" else None, start=c.start if method == "nearest" else None),
                c, method, temporal, score)


def glove_cases(quick: bool) -> Iterator[Case]:
    """(b) The real glove13 recording."""
    from mocap_autolabel.core.labelers.gmm import GmmLabeler
    from temporal import glove_case

    layout = _layout("glove13")
    case = glove_case(layout)
    yield "glove/default", functools.partial(label, case.take, layout)
    if not quick:
        yield "glove/gmm-vote", lambda: label(case.take, layout, method="gmm", labeler=GmmLabeler(layout).fit(case.fit))


def two_hand_cases(quick: bool) -> Iterator[Case]:
    """(c) Two hands: han2018 pairs, synthetic interacting takes, long ones, a held prop."""
    from mocap_autolabel.core.synth.generate import corrupt_take
    from mocap_autolabel.core.synth.two_hands import TwoHandConfig, two_hand_take

    layout = _layout("han19")
    if not quick:
        from two_hands import han_pairs

        for name, seed, a, b in han_pairs(layout):
            key = f"{seed:04d}-" + name.replace("/", "-")  # names repeat across capture folders: the seed does not
            take, _, _ = corrupt_take(np.concatenate([a, b], axis=1), 120.0, seed=seed)
            yield f"pairs/{key}/two", functools.partial(label, take, layout)
            for j, hand in enumerate((a, b)):
                alone, _, _ = corrupt_take(hand, 120.0, seed=100_000 * (j + 1) + seed)
                yield f"pairs/{key}/{('left', 'right')[j]}-alone", functools.partial(label, alone, layout, hands=1)
    for seed in ((0, 3) if quick else range(6)):
        yield f"synth2/seed{seed}", lambda seed=seed: label(two_hand_take(layout, 1200, seed).take, layout)
    if quick:
        return
    for seed in range(2):
        yield f"long/seed{seed}", lambda seed=seed: label(two_hand_take(layout, 3000, seed).take, layout)
    for seed in range(2):
        take = two_hand_take(layout, 1200, seed, TwoHandConfig(prop_markers=4)).take
        for check in (False, True):
            yield f"props/seed{seed}/{'on' if check else 'off'}", functools.partial(label, take, layout, props=check)


def demo_cases(quick: bool) -> Iterator[Case]:
    """(d) The demo take, and the take ``synth --hands 2 --layout han19 --frames 1200 --seed 2``
    writes (built directly, as the CLI's ``_synth_two`` does, without the C3D round trip); (e)
    re-solves: of the demo take, and of 3,000-frame takes where only a stretch is labeled again."""
    from mocap_autolabel.core.synth.two_hands import TwoHandConfig, two_hand_take

    layout = _layout("han19")
    yield "demo/default", functools.partial(_first, "demo")
    if not quick:
        yield "demo/validate", lambda: label(_resolve_take("demo"), layout, validate=True)
        yield "synth-cli/hands2-seed2", lambda: label(
            two_hand_take(layout, 1200, seed=2, config=TwoHandConfig(prop_markers=0), rate=120.0).take, layout)
    yield "resolve/demo-constraint", functools.partial(_resolve_constraint, "demo")
    if not quick:
        yield "resolve/demo-split", functools.partial(_resolve_split, "demo")
    for key in ("long1",) if quick else ("long1", "long2"):
        yield f"resolve/{key}-first", functools.partial(_first, key)
        yield f"resolve/{key}-constraint", functools.partial(_resolve_constraint, key)
        if not quick:
            yield f"resolve/{key}-split", functools.partial(_resolve_split, key)


def window_cases(quick: bool) -> Iterator[Case]:
    """(f) Takes longer than the window."""
    from mocap_autolabel.core.synth.generate import synthesize
    from mocap_autolabel.core.synth.two_hands import two_hand_take

    layout = _layout("han19")
    yield "window/one-hand", lambda: label(synthesize(layout, 5000, seed=5).take, layout, window=2000)
    if not quick:
        yield "window/two-hands", lambda: label(two_hand_take(layout, 5000, seed=3).take, layout, window=2000)


GROUPS = (han_cases, glove_cases, two_hand_cases, demo_cases, window_cases)


# --- run and compare -------------------------------------------------------------------------------

def _file(outdir: Path, name: str, suffix: str = ".npz") -> Path:
    return outdir / (name.replace("/", "__") + suffix)


def _digest(lab) -> dict:
    segments = np.stack([lab.slot, lab.start, lab.stop, lab.label.astype(np.int64),
                         lab.locked.astype(np.int64)], axis=1).astype(np.int64)
    return {"per_sample": lab.per_sample().astype(np.int16),
            "confidence": lab.per_sample_confidence().astype(np.float32),
            "segments": segments.reshape(-1, 5),
            "names": np.array(list(lab.names), dtype=str),
            "hands": np.array(json.dumps(lab.info.get("hands"), default=str, sort_keys=True)),
            "props": np.array(json.dumps(lab.info.get("props"), default=str, sort_keys=True))}


def run(outdir: Path, quick: bool, only: str | None) -> int:
    import mocap_autolabel

    outdir.mkdir(parents=True, exist_ok=True)
    if not only:  # a digest of another run would be compared as if it were this one's
        for stale in [*outdir.glob("*.npz"), *outdir.glob("*.error.txt")]:
            stale.unlink()
    print(f"mocap_autolabel from {Path(mocap_autolabel.__file__).parent}; "
          f"{'LabelSettings + Corrections' if _new_api() else 'keyword'} API; data {os.environ['MOCAP_DATA']}; "
          f"{'quick' if quick else 'full'} suite -> {outdir}", flush=True)
    t0 = time.perf_counter()
    done = failed = 0
    seen: set[str] = set()
    for group in GROUPS:
        for name, thunk in group(quick):
            if name in seen:
                raise RuntimeError(f"two cases named {name}")
            seen.add(name)
            if only and only not in name:
                continue
            t = time.perf_counter()
            try:
                lab = thunk()
            except Exception:
                failed += 1
                _file(outdir, name, ".error.txt").write_text(traceback.format_exc())
                print(f"{name}  FAILED after {time.perf_counter() - t:.2f} s", flush=True)
                traceback.print_exc()
                continue
            np.savez_compressed(_file(outdir, name), case=np.array(name), **_digest(lab))
            done += 1
            print(f"{name}  {time.perf_counter() - t:.2f} s", flush=True)
    print(f"{done} cases written, {failed} failed, {time.perf_counter() - t0:.1f} s", flush=True)
    return 1 if failed else 0


def _cases(folder: Path) -> dict[str, Path]:
    """Case name -> its .npz or .error.txt file."""
    out = {}
    for p in folder.iterdir():
        if p.name.endswith(".npz"):
            out[p.name[:-4].replace("__", "/")] = p
        elif p.name.endswith(".error.txt"):
            out[p.name[:-10].replace("__", "/")] = p
    return out


def _differences(a: Path, b: Path) -> str | None:
    """What differs between two digests of a case, in one line; None where they are identical."""
    if a.suffix != ".npz" or b.suffix != ".npz":
        return f"FAILED in {'A' if a.suffix != '.npz' else ''}{'B' if b.suffix != '.npz' else ''}"
    with np.load(a) as x, np.load(b) as y:
        pa, pb = x["per_sample"], y["per_sample"]
        if pa.shape != pb.shape:
            return f"DIFFERS: shape {pa.shape} vs {pb.shape}"
        n = int((pa != pb).sum())
        ca, cb = x["confidence"].astype(np.float64), y["confidence"].astype(np.float64)
        nan = int((np.isnan(ca) != np.isnan(cb)).sum())
        both = ~np.isnan(ca) & ~np.isnan(cb)
        worst = float(np.abs(ca[both] - cb[both]).max()) if both.any() else 0.0
        same = {}
        for key in ("names", "hands", "props", "segments"):
            same[key] = key in x and key in y and x[key].shape == y[key].shape and np.array_equal(x[key], y[key])
        if not n and not nan and worst == 0.0 and all(same.values()):
            return None
        parts = [f"{n} of {pa.size} labels differ", f"max |confidence diff| {worst:.3g}"]
        if nan:
            parts.append(f"{nan} samples NaN on one side only")
        parts += [f"{key} {'same' if ok else 'DIFFER'}" for key, ok in same.items()]
        return "DIFFERS: " + ", ".join(parts)


def compare(dir_a: Path, dir_b: Path, common: bool) -> int:
    a, b = _cases(dir_a), _cases(dir_b)
    names = sorted(set(a) & set(b)) if common else sorted(set(a) | set(b))
    if not names:
        print("no cases to compare")
        return 1
    width = max(len(n) for n in names)
    bad = 0
    for name in names:
        if name not in a or name not in b:
            print(f"{name:<{width}}  MISSING in {'A' if name not in a else 'B'}")
            bad += 1
            continue
        diff = _differences(a[name], b[name])
        bad += diff is not None
        print(f"{name:<{width}}  {diff or 'IDENTICAL'}", flush=True)
    print(f"{len(names) - bad} of {len(names)} cases identical" + (f", {bad} differ or missing" if bad else ""))
    return 1 if bad else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="label the suite and write one .npz per case into OUTDIR")
    r.add_argument("outdir", type=Path)
    r.add_argument("--quick", action="store_true", help="a representative handful of cases only")
    r.add_argument("--only", metavar="SUBSTRING", help="only the cases whose name contains SUBSTRING")
    c = sub.add_parser("compare", help="compare two digest folders; exit 1 if any case differs or is missing")
    c.add_argument("dir_a", type=Path)
    c.add_argument("dir_b", type=Path)
    c.add_argument("--common", action="store_true", help="only the cases both folders hold (e.g. full vs quick)")
    args = parser.parse_args()
    if args.command == "run":
        return run(args.outdir, args.quick, args.only)
    return compare(args.dir_a, args.dir_b, args.common)


if __name__ == "__main__":
    sys.exit(main())
