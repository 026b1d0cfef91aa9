"""Review inside Blender: label + colour a take, edit, re-solve, save and reopen (bpy module).

    python benchmarks/review.py [--frames 10000] [--runs 3] [--hands 1|2]

A synthetic raw han19 take (realistic corruption, 120 Hz; ``--hands 2``: two hands apart, as
han2018's) is imported, labeled with the defaults (set + vote) by the Label operator, corrected with
each relabel operator, and re-solved. Writes benchmarks/reports/review.md (two hands:
review_two_hands.md).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "addon"))

from datasets import write_report  # noqa: E402
from mocap_autolabel.core.formats.c3d import write_c3d  # noqa: E402
from mocap_autolabel.core.layout import load_layout  # noqa: E402
from mocap_autolabel.core.synth.generate import synthesize  # noqa: E402
from mocap_autolabel.core.synth.two_hands import TwoHandConfig, two_hand_take  # noqa: E402

REPORT = os.path.join(os.path.dirname(__file__), "reports", "review.md")


def timed(op, **kwargs) -> float:
    """Seconds one operator call takes (it must finish)."""
    start = time.perf_counter()
    result = op(**kwargs)
    assert result == {"FINISHED"}, result
    return time.perf_counter() - start


def solve_with_progress(bpy) -> dict:
    """Solve Hand's request on the scene's take, timed, with the gaps between its progress reports."""
    from mocap_autolabel.operators.solve_hand import MOCAPAL_OT_solve_hand, SolveRequest

    coll = bpy.context.scene.mocap_autolabel.take
    marker = next(iter(coll["mocap_labeled"].objects))
    bpy.context.view_layer.objects.active = marker
    props = type("Props", (), {"filepath": "", "layout_file": "", "layout": "han19"})()
    request = SolveRequest(*MOCAPAL_OT_solve_hand._labeled(props, bpy.context))
    stamps, shares = [], []

    def say(_message):
        stamps.append(time.perf_counter())
        shares.append(request.share)

    start = time.perf_counter()
    solved = request.run(say)
    end = time.perf_counter()
    times = [start] + stamps + [end]
    print(f"solve hand: {end - start:.1f} s, {len(stamps)} progress reports", flush=True)
    return {"seconds": end - start, "updates": len(stamps), "longest_gap": float(np.max(np.diff(times))),
            "first": shares[0], "last": shares[-1], "rms_mm": solved.fit.overall_rms() * 1000}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=10000)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--hands", type=int, choices=(1, 2), default=1)
    args = parser.parse_args()

    import bpy  # noqa: I001 (bpy first: it puts addon_utils on the path)
    import addon_utils

    addon_utils.enable("mocap_autolabel", default_set=True)
    from mocap_autolabel.blender.review import load_state
    from mocap_autolabel.blender.session import forget_all

    layout = load_layout("han19")
    rows: dict[str, list[float]] = {}
    progress: dict = {}

    def note(name: str, seconds: float) -> None:
        rows.setdefault(name, []).append(seconds)
        print(f"{name}: {seconds:.3f} s", flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "take.c3d")
        take = synthesize(layout, args.frames, seed=11).take if args.hands == 1 else \
            two_hand_take(layout, args.frames, seed=11, config=TwoHandConfig(close_share=0.0)).take
        write_c3d(take, path)
        for run in range(args.runs):
            bpy.ops.wm.read_homefile(use_empty=True)
            forget_all()
            note("import", timed(bpy.ops.mocap_autolabel.import_markers, filepath=path))
            scene = bpy.context.scene
            scene.mocap_autolabel.layout = "han19"
            note("label + colour (first in the process: model load)" if run == 0 else "label + colour",
                 timed(bpy.ops.mocap_autolabel.label))
            coll = scene.mocap_autolabel.take
            lab = load_state(coll).labeling
            labeled = {int(o["mocap_label"]): o for o in coll.all_objects if "mocap_label" in o}
            prefix = "" if args.hands == 1 else "L_"
            a, b = lab.names.index(prefix + "IndexTip"), lab.names.index(prefix + "MiddleTip")
            seg = np.flatnonzero(lab.label == a)
            seg = seg[np.argmax(lab.length[seg])]
            scene.frame_set(int(lab.start[seg] + lab.length[seg] // 2) + coll["mocap_first"])

            def select(*objs):
                for o in bpy.context.selected_objects:
                    o.select_set(False)
                for o in objs:
                    o.select_set(True)
                bpy.context.view_layer.objects.active = objs[0]

            select(labeled[a], labeled[b])
            note("swap (edit, no re-solve)", timed(bpy.ops.mocap_autolabel.swap_labels))
            select(labeled[b])
            note("lock", timed(bpy.ops.mocap_autolabel.lock))
            scene.frame_set(scene.frame_current + 5)
            note("split", timed(bpy.ops.mocap_autolabel.split))
            select(labeled[a])
            index = scene.frame_current - coll["mocap_first"]
            slot = int(np.flatnonzero(load_state(coll).labeling.per_sample()[index] == a)[0])
            note("unlabel", timed(bpy.ops.mocap_autolabel.unlabel))
            ghost = next(o for o in coll["mocap_unlabeled"].objects if o["mocap_null"] == slot)
            select(ghost)
            note("assign (a ghost gets a label)", timed(bpy.ops.mocap_autolabel.assign_label, label=str(a)))
            assigned_at = scene.frame_current
            note("re-solve (scores remembered)", timed(bpy.ops.mocap_autolabel.resolve))
            settings = scene.mocap_autolabel
            for sure in (0.9, 0.999, 0.95):  # the list, the counts and the key colours follow
                start = time.perf_counter()
                settings.sure = sure
                note(f"Confident at -> {sure} (list + key colours)", time.perf_counter() - start)
            scene.frame_set(coll["mocap_first"])
            note("next uncertain", timed(bpy.ops.mocap_autolabel.next_uncertain))
            scene.frame_set(assigned_at)
            select(ghost)
            note("unlock (deletes the assign, re-solves)", timed(bpy.ops.mocap_autolabel.unlock))
            note("delete correction (re-solves)", timed(bpy.ops.mocap_autolabel.delete_correction, index=0))
            blend = os.path.join(tmp, "review.blend")
            note("save .blend", timed(bpy.ops.wm.save_as_mainfile, filepath=blend))
            note("open .blend", timed(bpy.ops.wm.open_mainfile, filepath=blend))
            note("re-solve after reopening, nothing changed (the whole take)", timed(bpy.ops.mocap_autolabel.resolve))
            summary = load_state(bpy.context.scene.mocap_autolabel.take)
            constraints = len(summary.review.constraints)
            # Solve Hand as the panel runs it: on a job, reporting its stage and share done
            if run == 0 and args.hands == 1:
                progress.update(solve_with_progress(bpy))

    lines = ["# Review benchmark (Blender, bpy 5.0.1 module)", "",
             f"`python benchmarks/review.py --hands {args.hands}`: a synthetic raw han19 take of "
             f"{'one hand' if args.hands == 1 else 'two hands apart'}, {args.frames:,} frames (120 Hz, "
             f"realistic corruption), {args.runs} runs on this 2-core machine; operators called as a user "
             "would (background mode runs them synchronously). Median of the runs; the first labeling in a "
             "process also loads the ONNX model.", "",
             "| step | median s | runs |", "|---|---|---|"]
    for name, values in rows.items():
        lines.append(f"| {name} | {np.median(values):.3f} | {len(values)} |")
    lines += ["", f"After the edits the take holds {constraints} constraints and one split; every re-solve "
              "keeps them (tests/blender/test_blender_review.py checks it).", "",
              "Bars: label + colour of a 10,000-frame han19 take at most 5 s, re-solve under 1 s (issue 7, one "
              "hand); re-solve after a correction under 1.5 s (issue 32, two hands). A re-solve labels again "
              "only the frames within 5 s of the corrections changed since the last labeling "
              "(`core/windows.py: relabel_around`); a re-solve with nothing changed since (here the one "
              "after reopening) labels the whole take, its per-frame scores computed again."]
    if progress:
        lines += ["", "## Solve Hand's progress", "",
                  f"Solve Hand on the reopened take (first run), as the panel runs it (a job that reports its "
                  f"stage and share done; Esc is heard between reports): {progress['seconds']:.1f} s, "
                  f"{progress['updates']} progress reports, the longest {progress['longest_gap']:.1f} s apart "
                  f"(the most Esc can wait), shares rising from {progress['first']:.2f} to {progress['last']:.2f}; "
                  f"marker RMS {progress['rms_mm']:.2f} mm."]
    write_report(REPORT if args.hands == 1 else REPORT.replace("review.md", "review_two_hands.md"), lines)


if __name__ == "__main__":
    main()
