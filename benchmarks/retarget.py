"""Retargeting and engine exports benchmark: accuracy per rig convention, the speed of retargeting two hands
of 10,000 frames in the bpy module, FBX export of one solved hand of 10,000 frames, and FBX round trips.

    python benchmarks/retarget.py [--quick] [--frames N]

Writes benchmarks/reports/retarget.md. Needs the bpy module (``pip install -e ".[blender]"``); ufbx (in the
dev extra) adds a second reader's round trip.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "addon"))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests", "blender"))  # rigs.py: the test characters
sys.path.insert(0, os.path.dirname(__file__))

import bpy  # noqa: E402
import rigs  # noqa: E402
from datasets import write_report  # noqa: E402
from mocap_autolabel.blender import export  # noqa: E402
from mocap_autolabel.blender.armature import build_solved_hand  # noqa: E402
from mocap_autolabel.blender.retarget import retarget_character  # noqa: E402
from mocap_autolabel.core.hand.skeleton import BONE_NAMES  # noqa: E402
from mocap_autolabel.core.layout import load_layout  # noqa: E402
from mocap_autolabel.core.quiet import silenced_stdout  # noqa: E402
from mocap_autolabel.core.retarget.bone_maps import export_names  # noqa: E402
from mocap_autolabel.core.solve import solve_take  # noqa: E402
from mocap_autolabel.core.synth.generate import clean_config, synthesize  # noqa: E402
from mocap_autolabel.core.take import Take  # noqa: E402

REPORT = os.path.join(os.path.dirname(__file__), "reports", "retarget.md")
CONVENTIONS = ("mixamo", "ue5", "unity", "rigify")
PRESETS = ("ours", "ue5", "unity", "mixamo", "rigify")
#: Seeds of the synthetic generator that draw a left and a right hand.
SEEDS = {"left": 0, "right": 8}


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Degrees between rotations ``(..., 3, 3)`` (atan2: exact near 0, where arccos of float32 is not)."""
    rel = np.swapaxes(a, -1, -2) @ b
    cos = (np.trace(rel, axis1=-2, axis2=-1) - 1) / 2
    sin = np.linalg.norm(np.stack([rel[..., 2, 1] - rel[..., 1, 2], rel[..., 0, 2] - rel[..., 2, 0],
                                   rel[..., 1, 0] - rel[..., 0, 1]], axis=-1), axis=-1) / 2
    return np.degrees(np.arctan2(sin, cos))


def posed(objects: list[tuple[object, list[str]]], frames) -> list[np.ndarray]:
    """Blender's evaluated pose: per object ``(frames, bones, 3, 3)`` world rotations (scale taken off)."""
    scene = bpy.context.scene
    out = [np.empty((len(frames), len(names), 3, 3)) for _, names in objects]
    for i, f in enumerate(frames):
        scene.frame_set(int(f))
        for k, (obj, names) in enumerate(objects):
            world = np.array(obj.matrix_world)[:3, :3]
            world = world / np.linalg.norm(world, axis=0)
            out[k][i] = [world @ np.array(obj.pose.bones[n].matrix)[:3, :3] for n in names]
    return out


def solved_hands(frames: int) -> tuple[dict, dict]:
    """A clean synthetic labeled take per side (0.5 mm noise), solved (calibrated on its first 2 s)."""
    layout = load_layout("han19")
    solves, seconds = {}, {}
    for side, seed in SEEDS.items():
        synth = synthesize(layout, frames, seed=seed, config=clean_config())
        assert synth.hand.side == side, (side, synth.hand.side)
        markers = synth.markers + np.random.default_rng(seed).normal(0, 0.0005, synth.markers.shape)
        take = Take(positions=markers.astype(np.float32), names=layout.names, rate=120.0, first_frame=1,
                    source=f"{side}.c3d")
        t = time.perf_counter()
        solves[side] = solve_take(take, layout, calibrate_seconds=2.0)
        seconds[side] = time.perf_counter() - t
        print(f"solved the {side} hand: {frames} frames in {seconds[side]:.1f} s", flush=True)
    return solves, seconds


def scene_with_rigs(solves: dict) -> dict:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = 120, 1.0
    return {side: build_solved_hand(one, name=f"Hand_{side[0].upper()}") for side, one in solves.items()}


def character(convention: str, size: tuple[float, float]) -> rigs.Character:
    if convention == "rigify":
        return rigs.rigify_character(bpy)
    return rigs.build_character(bpy, convention, hand_size=size)


def joint_errors(ch: rigs.Character, rig, side: str, frames) -> np.ndarray:
    """Degrees per frame and mapped finger bone: the character's joint turn from its rest (Blender's
    evaluated pose) against our solved hand's matching joint turn, both in our hand frame's axes
    (characters whose hands are built from our hand model's rest: Mixamo, UE5, Unity)."""
    mapping = ch.bones[side]
    back = {t: o for o, t in mapping.items()}
    pairs = [(o, back[ch.obj.data.bones[t].parent.name], t, ch.obj.data.bones[t].parent.name)
             for o, t in mapping.items() if o != "palm"]
    theirs = [mapping["palm"]] + [t for _, _, t, _ in pairs]
    ours_posed, their_posed = posed([(rig, list(BONE_NAMES)), (ch.obj, theirs)], frames)
    ours_rest = np.array([np.array(rig.data.bones[n].matrix_local)[:3, :3] for n in BONE_NAMES])
    their_rest = np.array([np.array(ch.obj.data.bones[n].matrix_local)[:3, :3] for n in theirs])
    arm_ours = np.array(rig.matrix_world)[:3, :3] / np.linalg.norm(np.array(rig.matrix_world)[:3, :3], axis=0)
    arm_theirs = np.array(ch.obj.matrix_world)[:3, :3]
    arm_theirs = arm_theirs / np.linalg.norm(arm_theirs, axis=0)
    ours_posed = np.swapaxes(arm_ours, -1, -2) @ ours_posed  # back to armature space
    their_posed = np.swapaxes(arm_theirs, -1, -2) @ their_posed
    g = ch.hand_frame[side]

    def turn(p, rest, bone, parent):
        p0, b0 = rest[parent], rest[bone]
        now = np.swapaxes(p[:, parent], -1, -2) @ p[:, bone]
        return p0 @ now @ (p0.T @ b0).T @ p0.T

    out = [angle_deg(g.T @ turn(their_posed, their_rest, theirs.index(t), theirs.index(tp)) @ g,
                     turn(ours_posed, ours_rest, BONE_NAMES.index(o), BONE_NAMES.index(op)))
           for o, op, t, tp in pairs]
    return np.stack(out, axis=1)


def direction_errors(ch: rigs.Character, rig, side: str, frames) -> np.ndarray:
    """Degrees per frame and mapped finger bone between its direction in the character's hand bone frame
    and our bone's in our palm frame, after the one rotation that fits them best (a character whose rest
    is its own, as Rigify's meta-rig: its hand frame is not ours)."""
    mapping = {o: t for o, t in ch.bones[side].items() if o != "palm"}
    ours, theirs = posed([(rig, ["palm", *mapping]), (ch.obj, [ch.bones[side]["palm"], *mapping.values()])], frames)
    mine = (np.swapaxes(ours[:, :1], -1, -2) @ ours[:, 1:])[..., :, 1].reshape(-1, 3)
    got = (np.swapaxes(theirs[:, :1], -1, -2) @ theirs[:, 1:])[..., :, 1].reshape(-1, 3)
    u, _, vt = np.linalg.svd(got.T @ mine)
    k = u @ np.diag([1, 1, np.linalg.det(u @ vt)]) @ vt
    cos = np.sum((mine @ k.T) * got, axis=1) / np.linalg.norm(got, axis=1) / np.linalg.norm(mine, axis=1)
    return np.degrees(np.arccos(np.clip(cos, -1, 1))).reshape(len(frames), -1)


def stages(arm, sources: list) -> str:
    """Seconds of the retargeting's three stages, one by one: reading our keyed rigs, the core's transfer
    (both hands), keying the character."""
    from mocap_autolabel.blender.retarget import key_retargeted, source_hands, target_rig
    from mocap_autolabel.core.retarget.bone_maps import auto_map
    from mocap_autolabel.core.retarget.transfer import retarget

    t0 = time.perf_counter()
    hands = source_hands(sources)
    t1 = time.perf_counter()
    rig = target_rig(arm)
    bone_map = auto_map(list(rig.names), list(rig.parents))
    results = [(first, retarget(src, rig, bone_map.sides[side])) for side, src, first in hands]
    t2 = time.perf_counter()
    key_retargeted(arm, results)
    t3 = time.perf_counter()
    return f"{t1 - t0:.2f} / {t2 - t1:.2f} / {t3 - t2:.2f}"


def fbx_stacks(path: str) -> int:
    from io_scene_fbx import parse_fbx

    root, _ = parse_fbx.parse(path)
    objects = next(e for e in root.elems if e.id == b"Objects")
    return sum(e.id == b"AnimationStack" for e in objects.elems)


def read_back(path: str, bones: list[str], frames, reference: np.ndarray) -> float:
    """The worst rotation error (degrees) of ``bones`` over ``frames`` after Blender's importer reads the FBX
    into a fresh scene (the current file is saved and reopened around it)."""
    keep = os.path.join(tempfile.gettempdir(), f"retarget_bench_{os.getpid()}.blend")
    with silenced_stdout():
        bpy.ops.wm.save_as_mainfile(filepath=keep, copy=True)
        bpy.ops.wm.read_factory_settings(use_empty=True)
        bpy.context.scene.render.fps, bpy.context.scene.render.fps_base = 120, 1.0
        bpy.ops.import_scene.fbx(filepath=path, anim_offset=0.0)
    arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
    (back,) = posed([(arm, bones)], frames)
    with silenced_stdout():
        bpy.ops.wm.open_mainfile(filepath=keep)
    os.remove(keep)
    return float(angle_deg(reference, back).max())


UFBX = """
import json, os, sys
import ufbx
keep = []
def once(obj):
    keep.append(obj)
    return obj
scene = once(ufbx.load_file(sys.argv[1]))
order, frames = json.loads(sys.argv[2]), json.loads(sys.argv[3])
stacks = once(scene.anim_stacks)
anim = once(once(stacks[0]).anim)
out = []
for f in frames:
    nodes = once(once(scene.evaluate(anim, f / 120.0)).nodes)
    found = {}
    for i in range(len(nodes)):
        node = once(nodes[i])
        name = once(node.name)
        if name in order:
            m = once(node.node_to_world)
            found[name] = [[c.x, c.y, c.z] for c in (once(m.c0), once(m.c1), once(m.c2))]
    out.append([found[n] for n in order])
print(json.dumps({"stacks": len(stacks), "rotations": out}), flush=True)
os._exit(0)
"""
#: Blender's world from the FBX file's (ufbx applies no conversion): Y up files, and ue5's Z up.
TO_BLENDER = {"y_up": np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]), "z_up": np.eye(3)}


def ufbx_error(path: str, names: list[str], frames, reference: np.ndarray, up: str) -> float | None:
    """The worst rotation error (degrees) as ufbx reads the FBX; None where ufbx is not installed."""
    try:
        import ufbx  # noqa: F401
    except ImportError:
        return None
    done = subprocess.run([sys.executable, "-c", UFBX, path, json.dumps(names), json.dumps([int(f) for f in frames])],
                          capture_output=True, text=True, timeout=600)
    if done.returncode != 0:
        return float("nan")
    back = np.array(json.loads(done.stdout)["rotations"]).transpose(0, 1, 3, 2)
    back = TO_BLENDER[up] @ (back / np.linalg.norm(back, axis=-2, keepdims=True))
    return float(angle_deg(reference, back).max())


def real_takes() -> dict:
    """Labeled real takes, when ../shared/data has them, and the demo take: ``{name: (Take, layout)}``.
    The demo take is labeled by ``label_take``; the glove recording keeps its own labels."""
    from datasets import GLOVE13, glove13_take
    from mocap_autolabel.core.formats import reader_for
    from mocap_autolabel.core.labeling import labeled_take
    from mocap_autolabel.core.pipeline import label_take

    out = {}
    demo = os.path.join(os.path.dirname(__file__), "..", "samples", "demo_take.c3d")
    han19 = load_layout("han19")
    raw = reader_for(demo)(demo)
    out["demo take (1,200 frames, labeled by label_take)"] = (labeled_take(raw, label_take(raw, han19)), han19)
    if os.path.exists(GLOVE13):
        glove = load_layout("glove13")
        take, truth = glove13_take(glove)
        cols = [list(truth).index(j) for j in range(len(glove))]
        labeled = Take(positions=take.positions[:, cols], names=list(glove.names), rate=take.rate,
                       first_frame=take.first_frame, source=take.source)
        out[f"real glove recording ({take.n_frames:,} frames, its own labels)"] = (labeled, glove)
    return out


def tip_errors(ch: rigs.Character, rig, side: str, solved, frames) -> tuple[np.ndarray, int]:
    """Millimetres, per frame where our thumb touches a finger (the transfer's contact rule): the
    character's thumb-to-fingertip distance (Blender's evaluated pose) against our performer's."""
    from mocap_autolabel.core.retarget.source import SourceHand
    from mocap_autolabel.core.retarget.transfer import CONTACT_MARGIN

    source = SourceHand.from_poses(solved.calibration.hand(), solved.fit.poses)
    tips = source.tips()
    thumb = BONE_NAMES.index("thumb_dist")
    fingers = [BONE_NAMES.index(f"{f}_dist") for f in ("index", "middle", "ring", "little")]
    dist = np.stack([np.linalg.norm(tips[:, f] - tips[:, thumb], axis=1) for f in fingers], axis=1)
    reach = np.array([source.radii[thumb] + source.radii[f] + CONTACT_MARGIN for f in fingers])
    ratio = np.where(np.isfinite(dist), dist / reach, np.inf)
    which = np.argmin(ratio, axis=1)
    contact = np.flatnonzero(ratio[np.arange(len(ratio)), which] < 1.0)
    contact = contact[np.isin(contact + solved.first_frame, frames)] if len(contact) > len(frames) else contact
    names = ch.bones[side]
    world = np.array(ch.obj.matrix_world)
    errors = []
    scene = bpy.context.scene
    for i in contact:
        scene.frame_set(int(i + solved.first_frame))
        tail = {b: (world @ np.r_[np.array(ch.obj.pose.bones[names[b]].tail), 1.0])[:3]
                for b in ("thumb_dist", BONE_NAMES[fingers[which[i]]])}
        theirs = np.linalg.norm(tail["thumb_dist"] - tail[BONE_NAMES[fingers[which[i]]]])
        errors.append(abs(theirs - dist[i, which[i]]) * 1000)
    return np.array(errors), len(contact)


def real_section(quick: bool) -> list[str]:
    """Accuracy on the demo take and the real glove recording, per convention; the curled and rolled
    rests; pinches kept on a character with 20 % longer fingers."""
    rows, variants = [], []
    for name, (take, layout) in real_takes().items():
        with silenced_stdout():
            solved = solve_take(take, layout)
        side = solved.calibration.side
        frames = np.unique(np.linspace(solved.first_frame, solved.first_frame + take.n_frames - 1,
                                       60 if quick else 300).round().astype(int))
        size = (solved.calibration.length, solved.calibration.breadth)
        for convention in CONVENTIONS:
            rigs_ = scene_with_rigs({side: solved})
            ch = character(convention, size)
            retarget_character(bpy.context, armature=ch.obj, sources=[rigs_[side]])
            if ch.hand_frame is None:  # Rigify's meta-rig: a rest of its own
                err = direction_errors(ch, rigs_[side], side, frames).ravel()
                metric = "bone direction"
            else:
                err = joint_errors(ch, rigs_[side], side, frames).ravel()
                metric = "joint turn"
            rows.append(f"| {name} | {side} | {convention} | {metric} | {np.median(err):.3f} | "
                        f"{np.percentile(err, 99):.3f} | {err.max():.3f} |")
            print(rows[-1], flush=True)
        for label, options, pinch in (("fingers curled 35 degrees at rest", {"curl_deg": 35.0}, False),
                                      ("bones rolled 90 degrees at rest", {"roll_deg": 90.0}, False),
                                      ("20 % longer fingers", {"finger_scale": 1.2}, False),
                                      ("20 % longer fingers, Keep Pinches", {"finger_scale": 1.2}, True)):
            rigs_ = scene_with_rigs({side: solved})
            ch = rigs.build_character(bpy, "ue5", hand_size=size, **options)
            retarget_character(bpy.context, armature=ch.obj, sources=[rigs_[side]], pinch=pinch)
            err = direction_errors(ch, rigs_[side], side, frames).ravel()
            tips, contacts = tip_errors(ch, rigs_[side], side, solved, frames)
            tip = (f"{np.median(tips):.1f} / {tips.max():.1f}" if len(tips) else "no contact")
            variants.append(f"| {name} | {label} | {np.median(err):.3f} | {np.percentile(err, 99):.3f} | "
                            f"{contacts} | {tip} |")
            print(variants[-1], flush=True)
    return ["## The demo take and the real glove recording", "",
            "Each take solved (`solve_take`, its calibration), keyed as our rig and retargeted onto each "
            "convention's character (fingers only, the automatic map, rest reference), then checked on "
            "Blender's evaluated pose as above (Rigify's meta-rig, whose rest is its own, by bone directions).", "",
            "| take | side | convention | error | median | p99 | max |", "|---|---|---|---|---|---|---|", *rows, "",
            "Goal: median under 1 degree, 99th percentile under 3.", "",
            "## Rests that differ, and pinches", "",
            "UE5 characters whose hands differ from the performer's: rest fingers curled (35 degrees flexion at "
            "every joint), bones rolled (90 degrees about their own axes), 20 % longer phalanges. Errors: each "
            "finger bone's direction in the hand bone's frame against ours, after the one rotation that fits "
            "them best (degrees). Pinches: in the frames where our thumb touches a finger (the transfer's "
            "contact rule: the two distal bones' tips within their skin radii and 5 mm), the character's "
            "thumb-to-fingertip distance against the performer's, millimetres (median / max).", "",
            "| take | character | direction median | p99 | contact frames | tip distance error mm |",
            "|---|---|---|---|---|---|", *variants, "",
            "Goals: curled or rolled rests within 2 degrees; pinches within 5 mm of the performer's.", ""]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="one timing round, fewer frames checked")
    parser.add_argument("--frames", type=int, default=10_000, help="frames of each hand (default 10,000)")
    parser.add_argument("--real-only", action="store_true", help="only the demo take, the glove recording and "
                                                                 "the variants")
    args = parser.parse_args()
    if args.real_only:
        lines = ["# Retargeting onto characters and engine exports (real takes only)", ""]
        write_report(REPORT.replace(".md", "_real.md"), lines + real_section(args.quick))
        return
    rounds = 1 if args.quick else 3
    n = args.frames
    check = np.unique(np.linspace(1, n, 100 if args.quick else 400).round().astype(int))
    solves, solve_seconds = solved_hands(n)
    size = (solves["right"].calibration.length, solves["right"].calibration.breadth)
    lines = ["# Retargeting onto characters and engine exports", "",
             f"`python benchmarks/retarget.py{' --quick' if args.quick else ''}` on {platform.machine()} "
             f"({os.cpu_count()} cores, shared), bpy {bpy.app.version_string}. Two clean synthetic han19 takes of "
             f"{n:,} frames (a left and a right hand, 0.5 mm marker noise) solved with the calibration on their "
             f"first 2 s ({solve_seconds['left']:.1f} s and {solve_seconds['right']:.1f} s), keyed as our rigs; "
             f"characters from tests/blender/rigs.py (Mixamo, UE5 and Unity rigs carry hands built from our hand "
             f"model's rest in their conventions' arm poses, rolls and units; Rigify is its own human meta-rig).", ""]

    # --- retargeting: speed and accuracy per convention ---------------------------------------------
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for convention in CONVENTIONS:
            rigs_ = scene_with_rigs(solves)
            ch = character(convention, size)
            times = []
            for _ in range(rounds):  # each round replaces the last one's action and strip
                t = time.perf_counter()
                facts = retarget_character(bpy.context, armature=ch.obj, sources=list(rigs_.values()))
                times.append(time.perf_counter() - t)
            keyed = sum(len(f["bones"]) for f in facts["hands"].values())
            parts = stages(ch.obj, list(rigs_.values()))
            errs = []
            for side in ("left", "right"):
                if ch.hand_frame is not None:
                    errs.append(joint_errors(ch, rigs_[side], side, check).ravel())
                else:
                    errs.append(direction_errors(ch, rigs_[side], side, check).ravel())
            err = np.concatenate(errs)
            # the character's FBX (its own names), read back
            fbx = os.path.join(tmp, f"{convention}.fbx")
            t = time.perf_counter()
            with silenced_stdout():
                export.export_fbx(ch.obj, fbx, 1, n, preset=convention, rename=False)
            fbx_s = time.perf_counter() - t
            names = [b for f in facts["hands"].values() for b in f["bones"]]
            (reference,) = posed([(ch.obj, names)], check)
            trip = read_back(fbx, names, check, reference)
            metric = "joint turn" if ch.hand_frame is not None else "bone direction"
            rows.append(f"| {convention} | {keyed} | {min(times):.2f} | {parts} | {metric} | {np.median(err):.3f} | "
                        f"{np.percentile(err, 99):.3f} | {err.max():.3f} | {fbx_s:.1f} | {fbx_stacks(fbx)} | "
                        f"{trip:.4f} |")
            print(rows[-1], flush=True)
    lines += [f"## Retargeting two hands of {n:,} frames (`retarget_character`, in the bpy module)", "",
              "Seconds: the best of the rounds, reading our two keyed rigs, the core's transfer and keying the "
              "character (one action, an NLA strip); then the same three stages timed one by one "
              "(`source_hands`, the core's `retarget` per hand, `key_retargeted`). Errors in degrees against "
              "our solved hand over "
              f"{len(check)} frames of each hand and every keyed finger bone: *joint turn* compares each joint's "
              "turn from rest (the character's bone relative to its parent, Blender's evaluated pose) with our "
              "matching joint's, in our hand frame's axes; *bone direction* (Rigify, whose rest is its own) "
              "compares each finger bone's direction in the hand bone's frame with ours after the one rotation "
              "that fits them best. FBX: the character's armature exported with its own names (`export_fbx`, "
              "the convention's axes and units), seconds, its animation stacks, and the worst rotation error of "
              "the keyed bones read back by Blender's importer.", "",
              "| convention | bones keyed | retarget s | read / transfer / key s | error | median | p99 | max | "
              "FBX s | stacks | read back max |", "|---|---|---|---|---|---|---|---|---|---|---|", *rows, "",
              "Goal: retargeting under 2 s.", ""]

    # --- our rig's FBX per --bone-names preset ---------------------------------------------------------
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        rigs_ = scene_with_rigs({"right": solves["right"]})
        (reference,) = posed([(rigs_["right"], list(BONE_NAMES))], check)
        for preset in PRESETS:
            fbx = os.path.join(tmp, f"hand_{preset}.fbx")
            rig = bpy.data.objects["Hand_R"]  # read_back reopens the file: fetch the rig again
            times = []
            for _ in range(rounds):
                t = time.perf_counter()
                with silenced_stdout():
                    export.export_fbx(rig, fbx, 1, n, preset=preset, side="right")
                times.append(time.perf_counter() - t)
            names = [export_names(preset, "right")[b] for b in BONE_NAMES]
            trip = read_back(fbx, names, check, reference)
            second = ufbx_error(fbx, names, check, reference, "z_up" if preset == "ue5" else "y_up")
            rows.append(f"| {preset} | {min(times):.1f} | {os.path.getsize(fbx) / 1e6:.1f} | {fbx_stacks(fbx)} | "
                        f"{trip:.4f} | {'n/a' if second is None else f'{second:.4f}'} |")
            print(rows[-1], flush=True)
    lines += [f"## FBX of one solved hand of {n:,} frames (`solve --fbx --bone-names`)", "",
              "Seconds: the best of the rounds of `export_fbx` (a temporary copy of the rig renamed, every frame "
              "baked, Blender's exporter); the file's size, its animation stacks, and the worst rotation error "
              f"of the 20 bones over {len(check)} frames as Blender's importer and as ufbx (a second reader, "
              "`pip install ufbx`) read it back.", "",
              "| --bone-names | export s | MB | stacks | Blender read back max | ufbx read back max |",
              "|---|---|---|---|---|---|", *rows, "", "Goal: under 10 s, one stack.", ""]
    lines += real_section(args.quick)
    write_report(REPORT, lines)


if __name__ == "__main__":
    main()
