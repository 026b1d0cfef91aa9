"""Import speed: read a large C3D and build its Blender scene, keyed or as a point cloud; seconds,
samples/s, keys/s, peak memory; and our importer against io_anim_c3d on equal work, in one process.

    python benchmarks/import_speed.py [--sizes 100000x50,216000x38] [--vs 65535x50] [--pairs 5]
                                      [--report benchmarks/reports/import_speed.md]

Stages (each size, each stage in a fresh process): ``read`` (``read_take``), ``keyed`` (what the
import operator does: read, one keyed empty per point slot, the first depsgraph update, which
copies every key once more, then the undo step Blender pushes after an operator in the UI) and
``cloud`` (the same with the As Point Cloud option: one mesh + geometry nodes, no keys). Peak
memory is the growth of the process's peak resident size (VmHWM, reset through
/proc/self/clear_refs just before the stage) over its resident size before the stage, so it counts
numpy's and Blender's allocations alike; "peak RSS" is the process's whole peak (Blender included).

Against io_anim_c3d (MattiasFredriksson/io_anim_c3d, GPL-2.0; it reads at most 65,535 frames): when
``third_party/io_anim_c3d`` holds a checkout of it (git-ignored, never committed:
``git clone https://github.com/MattiasFredriksson/io_anim_c3d third_party/io_anim_c3d``), both
importers import the same synthetic C3D in one process, through their operators with default
options, each followed by the first depsgraph update (io_anim_c3d makes that update itself; ours
too), one warm-up round, then ``--pairs`` rounds in turn (io_anim_c3d, ours keyed, ours as a point
cloud), the scene emptied before each; quoted: medians, and the median of the per-round ratios.
Without the checkout it reports our keys/s alone.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "addon"))
THIRD_PARTY = os.path.join(ROOT, "third_party")
IO_ANIM_C3D = os.path.join(THIRD_PARTY, "io_anim_c3d")


def _status_mb(field: str) -> float:
    """A memory figure of this process from /proc/self/status (Linux), in MB."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024
    raise RuntimeError(f"no {field} in /proc/self/status: this benchmark needs Linux")


def _reset_peak() -> None:
    # Writing 5 resets VmHWM to the current RSS (ru_maxrss cannot be reset, and is even
    # inherited across exec from the parent that generated the file).
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")


def _write_take(path: str, frames: int, points: int) -> None:
    """A synthetic take: markers moving smoothly, 0.2 % of samples starting a 10-frame gap."""
    import numpy as np
    from mocap_autolabel.core.formats.c3d import write_c3d
    from mocap_autolabel.core.take import Take

    rng = np.random.default_rng(0)
    t = np.arange(frames, dtype=np.float32)[:, None, None] / 120.0
    pos = (rng.uniform(-1, 1, (1, points, 3)) + 0.05 * np.sin(t * rng.uniform(1, 5, (1, points, 3))))
    pos = pos.astype(np.float32)
    gaps = rng.random((frames, points)) < 0.002  # gap starts
    for f, p in zip(*np.nonzero(gaps), strict=True):
        pos[f:f + 10, p] = np.nan
    write_c3d(Take(pos, [f"*{i}" for i in range(points)], 120.0), path)


# --- one stage in a fresh process ---------------------------------------------------------------

def _stage(stage: str, path: str) -> dict:
    """Run one stage in this process and return its figures."""
    import gc

    import numpy as np  # noqa: F401  (imported before measuring)
    from mocap_autolabel.core.take import read_take

    if stage != "read":
        import bpy
        from mocap_autolabel.blender import animio
        from mocap_autolabel.blender.scene import ImportOptions, build_take, check_importable

        bpy.ops.wm.read_factory_settings(use_empty=True)
        wrapped = animio.write_points
        key_seconds = [0.0]

        def timed(*args, **kwargs):  # the bulk key writes alone (keyframe_points.add, co, interpolation)
            t = time.perf_counter()
            wrapped(*args, **kwargs)
            key_seconds[0] += time.perf_counter() - t

        animio.write_points = timed
    gc.collect()
    _reset_peak()
    rss0 = _status_mb("VmRSS")
    out = {"stage": stage}
    t0 = time.perf_counter()
    take = read_take(path)
    t1 = time.perf_counter()
    out["read_s"] = t1 - t0
    samples = take.n_frames * take.n_points
    out.update(samples=samples, frames=take.n_frames, points=take.n_points, raw_mb=samples * 12 / 2**20)
    if stage != "read":
        options = ImportOptions(as_point_cloud=stage == "cloud")
        check_importable(take, options)
        t1 = time.perf_counter()
        coll = build_take(take, bpy.context.scene, options)
        t2 = time.perf_counter()
        bpy.context.view_layer.update()  # the first depsgraph update: Blender's evaluated copy
        t3 = time.perf_counter()
        out.update(build_s=t2 - t1, keys_s=key_seconds[0], depsgraph_s=t3 - t2, import_s=t3 - t0,
                   peak_growth_mb=_status_mb("VmHWM") - rss0)
        keys = sum(len(fc.keyframe_points) for obj in coll.all_objects for fc in animio.fcurves_of(obj))
        loc_keys = sum(len(fc.keyframe_points) for obj in coll.all_objects for fc in animio.fcurves_of(obj)
                       if fc.data_path == "location")
        out.update(keys=keys, location_keys=loc_keys, valid_samples=int(take.valid.sum()))
        del take
        gc.collect()
        t4 = time.perf_counter()
        bpy.ops.ed.undo_push(message="Import")  # what Blender does after an operator with UNDO in the UI
        out.update(undo_s=time.perf_counter() - t4, peak_with_undo_mb=_status_mb("VmHWM") - rss0)
    else:
        out.update(import_s=t1 - t0, peak_growth_mb=_status_mb("VmHWM") - rss0)
    out.update(rss_after_mb=_status_mb("VmRSS"), peak_rss_mb=_status_mb("VmHWM"))
    if stage == "keyed":
        out["per_million_keys"] = _key_costs(animio)  # after the memory figures: it adds keys of its own
    return out


def _key_costs(animio, n: int = 1_000_000, reps: int = 3) -> dict:
    """Seconds per million keys of each bulk step on one new F-curve (best of ``reps``): what the
    keyed import pays per key, and what it avoids (int32 enum buffers, ``fcurve.update()``)."""
    import bpy
    import numpy as np

    obj = bpy.data.objects.new("bench_keys", None)
    bpy.context.scene.collection.objects.link(obj)
    animio.ensure_action(obj)
    co = np.empty((n, 2), dtype=np.float32)
    co[:, 0] = np.arange(n)
    co[:, 1] = np.sin(np.arange(n) / 100.0)
    steps = {
        "keyframe_points.add": lambda p, fc: p.add(n),
        "co (float32)": lambda p, fc: p.foreach_set("co", co.reshape(-1)),
        "co (float64)": lambda p, fc: p.foreach_set("co", co.reshape(-1).astype(np.float64)),
        "interpolation (uint8)": lambda p, fc: p.foreach_set("interpolation", np.ones(n, np.uint8)),
        "interpolation (int32)": lambda p, fc: p.foreach_set("interpolation", np.ones(n, np.int32)),
        "fcurve.update() (Bezier handles; we skip it)": lambda p, fc: (
            p.foreach_set("interpolation", np.full(n, 2, np.uint8)), fc.update()),
    }
    best = dict.fromkeys(steps, float("inf"))
    for _ in range(reps):
        fc = animio.new_fcurve(obj, "location", 0)
        points = fc.keyframe_points
        for name, step in steps.items():
            t = time.perf_counter()
            step(points, fc)
            best[name] = min(best[name], time.perf_counter() - t)
        animio.fcurves_of(obj).remove(fc)
    bpy.data.objects.remove(obj)
    return {k: v * 1e6 / n for k, v in best.items()}


# --- ours against io_anim_c3d in one process ----------------------------------------------------

def _versus(path: str, pairs: int) -> dict:
    """io_anim_c3d, ours keyed and ours as a point cloud on the same file, in turn, in this process."""
    import gc
    import importlib

    import bpy
    from mocap_autolabel.blender import animio

    addon_utils = importlib.import_module("addon_utils")  # on the path once bpy is imported

    addon_utils.enable("mocap_autolabel", default_set=True)
    have_io = os.path.isdir(IO_ANIM_C3D)
    if have_io:
        sys.path.insert(0, THIRD_PARTY)
        import io_anim_c3d

        io_anim_c3d.register()

    def fresh() -> None:
        bpy.ops.wm.read_homefile(use_empty=True)
        if "mocap_autolabel" not in bpy.context.preferences.addons:
            addon_utils.enable("mocap_autolabel", default_set=True)
        bpy.context.scene.render.fps = 120  # the file's rate: io_anim_c3d keys whole frames then
        gc.collect()

    def keys_of(action_objs) -> int:
        return sum(len(fc.keyframe_points) for obj in action_objs for fc in animio.fcurves_of(obj)
                   if "location" in fc.data_path)

    def run(which: str) -> tuple[float, int]:
        fresh()
        t = time.perf_counter()
        if which == "io_anim_c3d":
            bpy.ops.import_anim.c3d(filepath=path, perf_mon=False)
        else:
            bpy.ops.mocap_autolabel.import_markers(filepath=path, as_point_cloud=which == "cloud")
        bpy.context.view_layer.update()
        seconds = time.perf_counter() - t
        return seconds, keys_of(bpy.context.scene.objects)

    order = (["io_anim_c3d"] if have_io else []) + ["keyed", "cloud"]
    times: dict[str, list[float]] = {k: [] for k in order}
    keys: dict[str, int] = {}
    for round_ in range(pairs + 1):  # round 0 warms up
        for which in order:
            seconds, n = run(which)
            keys[which] = n
            if round_:
                times[which].append(seconds)
    fresh()
    out = {"pairs": pairs, "have_io": have_io, "keys": keys,
           "median_s": {k: statistics.median(v) for k, v in times.items()}, "times": times}
    if have_io:
        out["ratio_keyed"] = statistics.median(a / b for a, b in zip(times["io_anim_c3d"], times["keyed"], strict=True))
        out["ratio_cloud"] = statistics.median(a / b for a, b in zip(times["io_anim_c3d"], times["cloud"], strict=True))
        out["io_version"] = _io_version()
    return out


def _io_version() -> str:
    try:
        head = subprocess.run(["git", "-C", IO_ANIM_C3D, "log", "-1", "--format=%h %cs"], capture_output=True,
                              text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        head = "?"
    return head


def _child(args: list[str]) -> dict:
    out = subprocess.run([sys.executable, __file__, *args], capture_output=True, text=True)
    if out.returncode:
        raise RuntimeError(f"{args}: {out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _size(text: str) -> tuple[int, int]:
    frames, points = text.lower().split("x")
    return int(frames), int(points)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="100000x50,216000x38",
                        help="frames x points of the takes whose stages are measured, comma-separated")
    parser.add_argument("--vs", default="65535x50", help="frames x points of the take for the io_anim_c3d comparison")
    parser.add_argument("--pairs", type=int, default=5, help="counted rounds of the comparison")
    parser.add_argument("--report", default=os.path.join(ROOT, "benchmarks", "reports", "import_speed.md"))
    parser.add_argument("--stage", choices=["read", "keyed", "cloud", "versus"], help=argparse.SUPPRESS)
    parser.add_argument("--file", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.stage == "versus":
        print(json.dumps(_versus(args.file, args.pairs)))
        return 0
    if args.stage:
        print(json.dumps(_stage(args.stage, args.file)))
        return 0

    rows, versus = [], None
    with tempfile.TemporaryDirectory() as tmp:
        if args.vs:
            frames, points = _size(args.vs)
            path = os.path.join(tmp, f"vs_{frames}x{points}.c3d")
            _write_take(path, frames, points)
            versus = _child(["--stage", "versus", "--file", path, "--pairs", str(args.pairs)])
            versus.update(frames=frames, points=points)
            print(json.dumps(versus), flush=True)
            os.remove(path)
        for size in filter(None, args.sizes.split(",")):
            frames, points = _size(size)
            path = os.path.join(tmp, f"take_{frames}x{points}.c3d")
            _write_take(path, frames, points)
            for stage in ("read", "keyed", "cloud"):
                rows.append(_child(["--stage", stage, "--file", path]))
                print(json.dumps(rows[-1]), flush=True)
            os.remove(path)
    report = _report(rows, versus)
    print(report)
    os.makedirs(os.path.dirname(args.report), exist_ok=True)
    with open(args.report, "w") as fh:
        fh.write(report)
    return 0


def _report(rows: list[dict], versus: dict | None) -> str:
    import platform

    lines = [
        "# Import speed: reading a C3D and building its Blender scene",
        "",
        f"Machine: {os.cpu_count()} cores (shared: quote medians); Python {sys.version.split()[0]}; "
        f"{platform.machine()}; bpy {_bpy_version()}. Command: `python benchmarks/import_speed.py` "
        "(`make bench`). Synthetic takes: markers moving smoothly, 0.2 % of samples starting a 10-frame gap.",
        "",
    ]
    if versus is not None:
        fr, pts = versus["frames"], versus["points"]
        med = versus["median_s"]
        keys = versus["keys"]
        lines += [f"## Against io_anim_c3d: {fr:,} frames x {pts} markers, one process", ""]
        if versus["have_io"]:
            lines += [
                f"io_anim_c3d {versus['io_version']} from `third_party/io_anim_c3d` (git-ignored), its operator "
                "with default options (an armature, BEZIER keys, `fc.update()` per curve); ours, the "
                "import operator with default options (one empty per marker, LINEAR keys, keyed visibility), "
                "and with As Point Cloud. Each import followed by the first depsgraph update; the scene emptied "
                f"before each; one warm-up round, then {versus['pairs']} rounds in turn.",
                "",
                "| importer | median seconds | location keys | keys/s | io_anim_c3d / this (median of rounds) |",
                "|---|---|---|---|---|",
                f"| io_anim_c3d | {med['io_anim_c3d']:.2f} | {keys['io_anim_c3d']:,} | "
                f"{keys['io_anim_c3d'] / med['io_anim_c3d'] / 1e6:.1f} M | 1 |",
                f"| ours, keyed | {med['keyed']:.2f} | {keys['keyed']:,} | "
                f"{keys['keyed'] / med['keyed'] / 1e6:.1f} M | **{versus['ratio_keyed']:.2f}x** |",
                f"| ours, As Point Cloud | {med['cloud']:.2f} | 0 (no keys) | - | {versus['ratio_cloud']:.2f}x |",
                "",
                "Every round (seconds): " + "; ".join(
                    f"{k} " + ", ".join(f"{s:.2f}" for s in v) for k, v in versus["times"].items()) + ".",
                "",
            ]
        else:
            lines += [
                "io_anim_c3d is not in `third_party/io_anim_c3d` (clone it there to compare; it is git-ignored "
                "and never committed): our figures alone.",
                "",
                "| importer | median seconds | location keys | keys/s |",
                "|---|---|---|---|",
                f"| ours, keyed | {med['keyed']:.2f} | {keys['keyed']:,} | "
                f"{keys['keyed'] / med['keyed'] / 1e6:.1f} M |",
                f"| ours, As Point Cloud | {med['cloud']:.2f} | 0 (no keys) | - |",
                "",
            ]
    sizes = list(dict.fromkeys((r["frames"], r["points"]) for r in rows))
    for frames, points in sizes:
        mine = [r for r in rows if (r["frames"], r["points"]) == (frames, points)]
        samples = mine[0]["samples"]
        lines += [
            f"## Stages: {frames:,} frames x {points} markers ({samples / 1e6:.1f} M samples, "
            f"{mine[0]['raw_mb']:.0f} MB of float32 positions)",
            "",
            "Each stage in a fresh process. Import = read + build + first depsgraph update; peak growth over "
            "the process's RSS before the stage; bytes/sample = that growth / samples.",
            "",
            "| stage | read s | build s (key writes) | depsgraph s | import s | samples/s | peak growth MB "
            "| bytes/sample | undo step s | peak with undo MB | RSS after MB | peak RSS MB |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in mine:
            growth = r["peak_growth_mb"] * 2**20
            if r["stage"] == "read":
                lines.append(f"| read | {r['read_s']:.2f} | - | - | {r['import_s']:.2f} | "
                             f"{samples / r['import_s'] / 1e6:.1f} M | {r['peak_growth_mb']:.0f} | "
                             f"{growth / samples:.0f} | - | - | {r['rss_after_mb']:.0f} | {r['peak_rss_mb']:.0f} |")
                continue
            name = "keyed (3 location keys a sample)" if r["stage"] == "keyed" else "As Point Cloud"
            build = f"{r['build_s']:.2f} ({r['keys_s']:.2f})" if r["stage"] == "keyed" else f"{r['build_s']:.2f}"
            lines.append(f"| {name} | {r['read_s']:.2f} | {build} | {r['depsgraph_s']:.2f} | "
                         f"{r['import_s']:.2f} | {samples / r['import_s'] / 1e6:.1f} M | "
                         f"{r['peak_growth_mb']:.0f} | {growth / samples:.0f} | {r['undo_s']:.2f} | "
                         f"{r['peak_with_undo_mb']:.0f} | {r['rss_after_mb']:.0f} | {r['peak_rss_mb']:.0f} |")
        keyed = next((r for r in mine if r["stage"] == "keyed"), None)
        if keyed is not None:
            lines += ["", f"Keyed: {keyed['location_keys']:,} location keys for {keyed['valid_samples']:,} "
                          f"valid samples ({keyed['keys']:,} keys with visibility).", "",
                      "Where a key's time goes (one new F-curve of 1 M keys in the same process, best of 3; "
                      "seconds per million keys): "
                      + "; ".join(f"{k} {v:.3f}" for k, v in keyed["per_million_keys"].items()) + "."]
        lines.append("")
    return "\n".join(lines) + "\n"


def _bpy_version() -> str:
    try:
        import bpy

        return bpy.app.version_string
    except ImportError:
        return "absent"


if __name__ == "__main__":
    sys.exit(main())
